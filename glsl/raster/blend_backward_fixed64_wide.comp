#version 460
// blend_backward_fixed64.comp for CPU drivers: several pixels an invocation (blend_backward_body.glsl, WIDE).
#define WIDE
#include "grad_add_fixed64.glsl"
#include "blend_backward_body.glsl"
