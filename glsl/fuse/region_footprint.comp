#version 460
#include "region_footprint.glsl"
