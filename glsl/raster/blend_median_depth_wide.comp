#version 460
// blend_median_depth.comp for CPU drivers: 16 pixels an invocation (tile_window.glsl,
// PIXELS).
#define PIXELS 16
#define CHUNK_CHANNELS 0
#define MEDIAN_DEPTH
#include "blend_body.glsl"
