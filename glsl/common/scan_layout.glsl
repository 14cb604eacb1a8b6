// Shared between the prefix-scan kernels and src/gpu/scan.rs: block size and the layout of
// the scan's state buffer (element counts per level, then indirect dispatch arguments).
#ifndef SCAN_LAYOUT_GLSL
#define SCAN_LAYOUT_GLSL

// SCAN_WG_SIZE, SCAN_ITEMS, SCAN_BLOCK, SCAN_MAX_LEVELS, SCAN_ARGS_OFFSET.
#include "shared_constants.glsl"

// state[level]: element count at that level (level 0: the input).
// state[SCAN_ARGS_OFFSET + 3 * level ..]: (workgroups, 1, 1) for that level.

#endif
