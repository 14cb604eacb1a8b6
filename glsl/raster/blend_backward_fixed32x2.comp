#version 460
// Blend backward, deterministic 64-bit fixed-point accumulation (fixed32x2).
#include "grad_add_fixed32x2.glsl"
#include "blend_backward_body.glsl"
