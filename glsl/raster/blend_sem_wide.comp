#version 460
// blend_sem.comp for CPU drivers: 8 pixels an invocation (tile_window.glsl, PIXELS).
#include "shared_constants.glsl"
#define PIXELS 8
#define CHUNK_CHANNELS SEM_CHUNK
#include "blend_body.glsl"
