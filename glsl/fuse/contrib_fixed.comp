#version 460
#include "contrib_fixed.glsl"
