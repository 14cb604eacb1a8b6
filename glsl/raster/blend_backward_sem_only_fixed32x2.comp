#version 460
// Semantic-only blend backward (geometry frozen), deterministic 64-bit fixed point (fixed32x2).
#define SEM_ONLY
#include "grad_add_fixed32x2.glsl"
#include "blend_backward_body.glsl"
