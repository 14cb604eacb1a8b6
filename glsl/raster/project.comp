#version 460
// Projection in float32 (devices without shaderFloat64).
#include "project_body.glsl"
