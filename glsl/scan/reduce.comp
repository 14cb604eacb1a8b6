#version 460
// Reduce step of the reduce-then-scan: each workgroup sums one block of SCAN_BLOCK
// elements of this level into one entry of the next level.
#extension GL_EXT_control_flow_attributes : require
#include "scan_layout.glsl"
#define WG_SIZE SCAN_WG_SIZE
#include "workgroup_scan.glsl"

layout(local_size_x = SCAN_WG_SIZE) in;

layout(push_constant) uniform ScanReduceParams {
    // This level's elements and the next level's, by address (addressed_arrays.glsl).
    uvec2 src_addr;
    uvec2 sums_addr;
    uint level;
} pc;

#include "addressed_arrays.glsl"
#define src UintArray(pc.src_addr)
#define sums UintArrayRW(pc.sums_addr)

layout(set = 0, binding = 0) readonly buffer StateBuf { uint data[]; } state;

void main() {
    uint n = state.data[pc.level];
    uint base = gl_WorkGroupID.x * SCAN_BLOCK;
    uint t = lane_order_index();
    uint acc = 0;
    [[unroll]] for (uint i = 0; i < SCAN_ITEMS; i++) {
        uint g = base + i * SCAN_WG_SIZE + t;
        acc += g < n ? src.data[g] : 0;
    }
    uint total = workgroup_add(acc);
    if (t == 0) {
        sums.data[gl_WorkGroupID.x] = total;
    }
}
