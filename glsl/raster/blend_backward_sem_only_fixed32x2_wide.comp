#version 460
// blend_backward_sem_only_fixed32x2.comp for CPU drivers: several pixels an invocation (blend_backward_body.glsl, WIDE).
#define WIDE
#define SEM_ONLY
#include "grad_add_fixed32x2.glsl"
#include "blend_backward_body.glsl"
