#version 460
// Semantic-only blend backward (geometry frozen), float32 atomics.
#define SEM_ONLY
#include "grad_add_float.glsl"
#include "blend_backward_body.glsl"
