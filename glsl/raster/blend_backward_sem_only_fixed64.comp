#version 460
// Semantic-only blend backward (geometry frozen), deterministic 64-bit fixed point (fixed64).
#define SEM_ONLY
#include "grad_add_fixed64.glsl"
#include "blend_backward_body.glsl"
