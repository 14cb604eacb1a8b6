#version 460
// Computes the element count of every scan level, and each level's workgroup count as
// indirect dispatch arguments, from a count that lives on the GPU:
// n = ceil(source[index] / div) * mul.
#include "scan_layout.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform ScanSetupParams {
    uint count_index;
    uint div;
    uint mul;
    uint levels;   // scan levels the host planned (1..=SCAN_MAX_LEVELS)
    uint capacity; // the plan's element capacity: larger counts are clamped to it
} pc;

layout(set = 0, binding = 0) readonly buffer CountBuf { uint data[]; } count_src;
layout(set = 0, binding = 1) writeonly buffer StateBuf { uint data[]; } state;

void main() {
    uint raw = count_src.data[pc.count_index];
    // Clamp before multiplying so that a huge bogus count cannot wrap around.
    uint blocks = raw / pc.div + (raw % pc.div != 0 ? 1 : 0);
    uint n = min(blocks, pc.capacity / pc.mul) * pc.mul;
    for (uint l = 0; l < SCAN_MAX_LEVELS; l++) {
        uint groups = (n + SCAN_BLOCK - 1) / SCAN_BLOCK;
        bool used = l < pc.levels;
        state.data[l] = used ? n : 0;
        state.data[SCAN_ARGS_OFFSET + 3 * l + 0] = used ? groups : 0;
        state.data[SCAN_ARGS_OFFSET + 3 * l + 1] = 1;
        state.data[SCAN_ARGS_OFFSET + 3 * l + 2] = 1;
        n = groups;
    }
}
