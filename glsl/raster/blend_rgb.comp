#version 460
// RGB, alpha, depth only: no semantic channels to pay for.
#define SEM_CHUNK 0
#include "blend_body.glsl"
