#version 460
// RGB plus SEM_CHUNK semantic channels per dispatch (chunk_base selects which).
#define SEM_CHUNK 16
#include "blend_body.glsl"
