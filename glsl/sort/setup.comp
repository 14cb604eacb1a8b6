#version 460
// Reads the element count from a GPU buffer (no CPU readback), clamps it to the sorter's
// capacity, and writes the per-pass dispatch size.
#include "sort_layout.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform SortSetupParams {
    uint count_index;
    uint capacity;
} pc;

layout(set = 0, binding = 0) readonly buffer CountBuf { uint data[]; } count_src;
layout(set = 0, binding = 1) writeonly buffer StateBuf { uint data[]; } state;

void main() {
    uint n = min(count_src.data[pc.count_index], pc.capacity);
    state.data[0] = (n + SORT_BLOCK - 1) / SORT_BLOCK;
    state.data[1] = 1;
    state.data[2] = 1;
    state.data[SORT_STATE_N] = n;
}
