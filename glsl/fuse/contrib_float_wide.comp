#version 460
// contrib_float.comp for CPU drivers: 16 pixels an invocation (tile_window.glsl, PIXELS).
#define PIXELS 16
#include "contrib_float.glsl"
