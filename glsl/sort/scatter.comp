#version 460
// Downsweep of one radix pass: moves each (key, value) of the block to its place, keeping
// equal digits in input order (stable). The block is processed as SORT_ITEMS tiles of
// SORT_WG_SIZE elements in lane order; within a tile, each element's rank among equal
// digits of its subgroup comes from ballots (multi-split: one ballot per digit bit, so any
// subgroup size up to 128 works), and subgroups are ordered by a per-digit scan of their
// counts. No workgroup waits on another.
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#include "sort_layout.glsl"

layout(local_size_x = SORT_WG_SIZE) in;

layout(push_constant) uniform Params {
    uint shift;
    uint bits;
} pc;

layout(set = 0, binding = 0) readonly buffer StateBuf { uint data[]; } state;
layout(set = 0, binding = 1) readonly buffer KeysInBuf { uint data[]; } keys_in;
layout(set = 0, binding = 2) readonly buffer ValuesInBuf { uint data[]; } values_in;
layout(set = 0, binding = 3) writeonly buffer KeysOutBuf { uint data[]; } keys_out;
layout(set = 0, binding = 4) writeonly buffer ValuesOutBuf { uint data[]; } values_out;
layout(set = 0, binding = 5) readonly buffer OffsetsBuf { uint data[]; } offsets; // scanned counts

// Subgroups of at least 4 lanes.
#define MAX_SUBGROUPS (SORT_WG_SIZE / 4)

shared uint digit_base[RADIX];          // next output slot of each digit for this block
shared uint tile_total[RADIX];          // elements of each digit in the current tile
shared uint sg_hist[MAX_SUBGROUPS * RADIX]; // per-subgroup digit counts, then their prefixes

void main() {
    uint blocks = state.data[0];
    uint n = state.data[SORT_STATE_N];
    uint t = gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
    uint base = gl_WorkGroupID.x * SORT_BLOCK;
    if (t < RADIX) {
        digit_base[t] = offsets.data[t * blocks + gl_WorkGroupID.x];
    }
    uint hist_slots = gl_NumSubgroups * RADIX;
    for (uint i = 0; i < SORT_ITEMS; i++) {
        uint tile_start = base + i * SORT_WG_SIZE;
        if (tile_start >= n) {
            break; // uniform across the workgroup
        }
        for (uint s = t; s < hist_slots; s += SORT_WG_SIZE) {
            sg_hist[s] = 0;
        }
        barrier();

        uint g = tile_start + t;
        bool valid = g < n;
        uint key = valid ? keys_in.data[g] : 0;
        uint value = valid ? values_in.data[g] : 0;
        uint digit = bitfieldExtract(key, int(pc.shift), int(pc.bits));
        uvec4 peers = subgroupBallot(valid);
        [[unroll]] for (uint b = 0; b < RADIX_BITS; b++) {
            if (b < pc.bits) {
                bool bit = ((digit >> b) & 1u) != 0;
                uvec4 set_lanes = subgroupBallot(bit);
                peers &= bit ? set_lanes : ~set_lanes;
            }
        }
        uint rank = subgroupBallotExclusiveBitCount(peers);
        if (valid && rank == 0) {
            sg_hist[gl_SubgroupID * RADIX + digit] = subgroupBallotBitCount(peers);
        }
        barrier();
        if (t < RADIX) {
            uint acc = 0;
            for (uint s = 0; s < gl_NumSubgroups; s++) {
                uint c = sg_hist[s * RADIX + t];
                sg_hist[s * RADIX + t] = acc;
                acc += c;
            }
            tile_total[t] = acc;
        }
        barrier();
        if (valid) {
            uint dst = digit_base[digit] + sg_hist[gl_SubgroupID * RADIX + digit] + rank;
            keys_out.data[dst] = key;
            values_out.data[dst] = value;
        }
        barrier();
        if (t < RADIX) {
            digit_base[t] += tile_total[t];
        }
        // The next tile's first barrier orders this update before its use.
    }
}
