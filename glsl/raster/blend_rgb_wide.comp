#version 460
// blend_rgb.comp for CPU drivers: 16 pixels an invocation (tile_window.glsl, PIXELS).
#define PIXELS 16
#define CHUNK_CHANNELS 0
#include "blend_body.glsl"
