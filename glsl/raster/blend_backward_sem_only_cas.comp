#version 460
// Semantic-only blend backward (geometry frozen), compare-and-swap accumulation.
#define SEM_ONLY
#include "grad_add_cas.glsl"
#include "blend_backward_body.glsl"
