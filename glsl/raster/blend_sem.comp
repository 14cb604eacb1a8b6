#version 460
// RGB plus SEM_CHUNK semantic channels per dispatch (chunk_base selects which).
#include "shared_constants.glsl"
#define CHUNK_CHANNELS SEM_CHUNK
#include "blend_body.glsl"
