#version 460
// region_footprint.comp for CPU drivers: 16 pixels an invocation (tile_window.glsl, PIXELS).
#define PIXELS 16
#include "region_footprint.glsl"
