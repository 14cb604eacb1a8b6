#version 460
// Projection with the camera-space and 2D means in float64 (devices with shaderFloat64).
#extension GL_EXT_shader_explicit_arithmetic_types_float64 : require
#define PROJECT_F64 1
#include "project_body.glsl"
