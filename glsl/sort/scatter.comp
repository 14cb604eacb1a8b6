#version 460
// Downsweep of one radix pass: moves each (key, value) of the block to its place, keeping
// equal digits in input order (stable). The block is processed in rounds of SUBTILES tiles
// of SORT_WG_SIZE elements in lane order; each element's rank among equal digits of its
// subgroup comes from ballots (multi-split: one ballot per digit bit, so any subgroup size
// up to 128 works), and (subtile, subgroup) pairs are ordered by a per-digit scan of their
// counts. The round is sorted by digit in shared memory first and then written out in
// order, so neighbouring lanes write neighbouring addresses (a digit's run) instead of up
// to RADIX runs per store. No workgroup waits on another.
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#include "sort_layout.glsl"

layout(local_size_x = SORT_WG_SIZE) in;

#include "pass_params.glsl"

layout(set = 0, binding = 0) readonly buffer StateBuf { uint data[]; } state;
layout(set = 0, binding = 5) readonly buffer OffsetsBuf { uint data[]; } offsets; // scanned counts

// Subgroups of at least 4 lanes.
#define MAX_SUBGROUPS (SORT_WG_SIZE / 4)
// A round ranks SUBTILES tiles of SORT_WG_SIZE elements with one histogram, one prefix
// pass and one scatter: a quarter of the barriers of one tile per round.
#define SUBTILES 4
#define ROUND (SORT_WG_SIZE * SUBTILES)

shared uint digit_base[RADIX];                         // next output slot of each digit
shared uint round_total[RADIX];                        // elements of each digit this round
shared uint sg_hist[SUBTILES * MAX_SUBGROUPS * RADIX]; // counts per (subtile, subgroup, digit), then prefixes
shared uint digit_local[RADIX];                        // first slot of each digit in the round
shared uint s_keys[ROUND];                             // the round, sorted by digit
shared uint s_values[ROUND];

void main() {
    uint blocks = state.data[0];
    uint n = state.data[SORT_STATE_N];
    uint t = gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID;
    uint base = gl_WorkGroupID.x * SORT_BLOCK;
    if (t < RADIX) {
        digit_base[t] = offsets.data[t * blocks + gl_WorkGroupID.x];
    }
    uint sg_slots = gl_NumSubgroups * RADIX;
    for (uint r = 0; r < SORT_BLOCK / ROUND; r++) {
        uint round_start = base + r * ROUND;
        if (round_start >= n) {
            break; // uniform across the workgroup
        }
        for (uint s = t; s < SUBTILES * sg_slots; s += SORT_WG_SIZE) {
            sg_hist[s] = 0;
        }
        barrier();

        // Element order within the round: subtile, then subgroup, then lane.
        uint keys[SUBTILES];
        uint values[SUBTILES];
        uint digits[SUBTILES];
        uint ranks[SUBTILES];
        bool valid[SUBTILES];
        [[unroll]] for (uint k = 0; k < SUBTILES; k++) {
            uint g = round_start + k * SORT_WG_SIZE + t;
            valid[k] = g < n;
            keys[k] = valid[k] ? keys_in.data[g] : 0;
            values[k] = valid[k] ? values_in.data[g] : 0;
            digits[k] = bitfieldExtract(keys[k], int(pc.shift), int(pc.bits));
            uvec4 peers = subgroupBallot(valid[k]);
            [[unroll]] for (uint b = 0; b < RADIX_BITS; b++) {
                if (b < pc.bits) {
                    bool bit = ((digits[k] >> b) & 1u) != 0;
                    uvec4 set_lanes = subgroupBallot(bit);
                    peers &= bit ? set_lanes : ~set_lanes;
                }
            }
            ranks[k] = subgroupBallotExclusiveBitCount(peers);
            if (valid[k] && ranks[k] == 0) {
                sg_hist[k * sg_slots + gl_SubgroupID * RADIX + digits[k]] = subgroupBallotBitCount(peers);
            }
        }
        barrier();
        if (t < RADIX) {
            uint acc = 0;
            for (uint s = 0; s < SUBTILES * gl_NumSubgroups; s++) {
                uint c = sg_hist[s * RADIX + t];
                sg_hist[s * RADIX + t] = acc;
                acc += c;
            }
            round_total[t] = acc;
        }
        barrier();
        if (t < RADIX) {
            uint before = 0;
            for (uint d = 0; d < t; d++) {
                before += round_total[d];
            }
            digit_local[t] = before;
        }
        barrier();
        [[unroll]] for (uint k = 0; k < SUBTILES; k++) {
            if (valid[k]) {
                uint local = digit_local[digits[k]] + sg_hist[k * sg_slots + gl_SubgroupID * RADIX + digits[k]] + ranks[k];
                s_keys[local] = keys[k];
                s_values[local] = values[k];
            }
        }
        barrier();
        uint round_len = min(ROUND, n - round_start);
        for (uint i = t; i < round_len; i += SORT_WG_SIZE) {
            uint key = s_keys[i];
            uint digit = bitfieldExtract(key, int(pc.shift), int(pc.bits));
            uint dst = digit_base[digit] + (i - digit_local[digit]);
            keys_out.data[dst] = key;
            values_out.data[dst] = s_values[i];
        }
        barrier();
        if (t < RADIX) {
            digit_base[t] += round_total[t];
        }
        // The next round's first barrier orders this update before its use.
    }
}
