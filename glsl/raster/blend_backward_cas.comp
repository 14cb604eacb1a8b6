#version 460
// Blend backward, compare-and-swap accumulation.
#include "grad_add_cas.glsl"
#include "blend_backward_body.glsl"
