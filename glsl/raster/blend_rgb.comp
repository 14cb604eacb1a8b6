#version 460
// RGB, alpha, depth only: no semantic channels to pay for.
#define CHUNK_CHANNELS 0
#include "blend_body.glsl"
