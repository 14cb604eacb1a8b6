#version 460
// Blend backward, float32 atomics.
#include "grad_add_float.glsl"
#include "blend_backward_body.glsl"
