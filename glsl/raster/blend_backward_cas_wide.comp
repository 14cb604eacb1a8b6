#version 460
// blend_backward_cas.comp for CPU drivers: several pixels an invocation (blend_backward_body.glsl, WIDE).
#define WIDE
#include "grad_add_cas.glsl"
#include "blend_backward_body.glsl"
