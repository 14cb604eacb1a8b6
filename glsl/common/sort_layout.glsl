// Shared between the radix-sort kernels and src/gpu/sort.rs.
#ifndef SORT_LAYOUT_GLSL
#define SORT_LAYOUT_GLSL

#define SORT_WG_SIZE 256
#define SORT_ITEMS 16
#define SORT_BLOCK (SORT_WG_SIZE * SORT_ITEMS) // 4096 elements per workgroup
#define RADIX_BITS 4
#define RADIX (1 << RADIX_BITS)

// Sort state buffer: [0..3) indirect dispatch arguments (blocks, 1, 1); [3] n, the
// element count clamped to the sorter's capacity.
#define SORT_STATE_N 3

#endif
