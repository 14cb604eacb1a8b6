#version 460
// blend_backward_sem_only.comp for CPU drivers: several pixels an invocation (blend_backward_body.glsl, WIDE).
#define WIDE
#define SEM_ONLY
#include "grad_add_float.glsl"
#include "blend_backward_body.glsl"
