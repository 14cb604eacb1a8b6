// Shared between the radix-sort kernels and src/gpu/sort.rs.
#ifndef SORT_LAYOUT_GLSL
#define SORT_LAYOUT_GLSL

// SORT_WG_SIZE, SORT_ITEMS, SORT_BLOCK, RADIX_BITS, RADIX_BITS_WIDE, SORT_STATE_N.
#include "shared_constants.glsl"
#define RADIX (1 << RADIX_BITS)
#define RADIX_WIDE (1 << RADIX_BITS_WIDE)

// Sort state buffer: [0..3) indirect dispatch arguments (blocks, 1, 1); [SORT_STATE_N] n,
// the element count clamped to the sorter's capacity.

#endif
