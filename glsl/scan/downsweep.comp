#version 460
// Scan step of the reduce-then-scan: each workgroup computes the exclusive prefix sum of
// its block and adds the block's offset (the scanned sum of earlier blocks, from the next
// level up). src and dst may be the same buffer: the block is read whole before writing.
#extension GL_EXT_control_flow_attributes : require
#include "scan_layout.glsl"
#define WG_SIZE SCAN_WG_SIZE
#include "workgroup_scan.glsl"

layout(local_size_x = SCAN_WG_SIZE) in;

layout(push_constant) uniform ScanDownsweepParams {
    // This level's elements, their scan, and the next level's scanned sums, by address
    // (addressed_arrays.glsl; src and dst may be the same array).
    uvec2 src_addr;
    uvec2 dst_addr;
    uvec2 offsets_addr;
    uint level;
    uint has_offsets; // 0 at the top level: its single block starts at 0
} pc;

layout(set = 0, binding = 0) readonly buffer StateBuf { uint data[]; } state;
#include "addressed_arrays.glsl"
#define src UintArray(pc.src_addr)
#define dst UintArrayRW(pc.dst_addr)
#define offsets UintArray(pc.offsets_addr)

shared uint tile[SCAN_BLOCK];

void main() {
    uint n = state.data[pc.level];
    uint base = gl_WorkGroupID.x * SCAN_BLOCK;
    uint t = lane_order_index();
    // Coalesced load into shared memory, then each invocation scans SCAN_ITEMS
    // consecutive elements.
    [[unroll]] for (uint i = 0; i < SCAN_ITEMS; i++) {
        uint idx = i * SCAN_WG_SIZE + t;
        tile[idx] = base + idx < n ? src.data[base + idx] : 0;
    }
    barrier();
    uint local_prefix[SCAN_ITEMS];
    uint sum = 0;
    [[unroll]] for (uint i = 0; i < SCAN_ITEMS; i++) {
        local_prefix[i] = sum;
        sum += tile[t * SCAN_ITEMS + i];
    }
    uint total;
    uint prefix = workgroup_exclusive_add(sum, total);
    uint block_offset = pc.has_offsets != 0 ? offsets.data[gl_WorkGroupID.x] : 0;
    [[unroll]] for (uint i = 0; i < SCAN_ITEMS; i++) {
        tile[t * SCAN_ITEMS + i] = block_offset + prefix + local_prefix[i];
    }
    barrier();
    [[unroll]] for (uint i = 0; i < SCAN_ITEMS; i++) {
        uint idx = i * SCAN_WG_SIZE + t;
        if (base + idx < n) {
            dst.data[base + idx] = tile[idx];
        }
    }
}
