#version 460
// Blend backward, deterministic 64-bit fixed-point accumulation (fixed64).
#include "grad_add_fixed64.glsl"
#include "blend_backward_body.glsl"
