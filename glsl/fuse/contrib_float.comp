#version 460
#include "contrib_float.glsl"
