#version 460
// Upsweep of one radix pass: the digit histogram of each block, stored digit-major
// (counts[digit * blocks + block]) so that one exclusive scan of the whole array yields
// every block's output offset for every digit.
#extension GL_EXT_control_flow_attributes : require
#include "sort_layout.glsl"

layout(local_size_x = SORT_WG_SIZE) in;

#include "pass_params.glsl"

layout(set = 0, binding = 0) readonly buffer StateBuf { uint data[]; } state;
layout(set = 0, binding = 2) writeonly buffer CountsBuf { uint data[]; } counts;

shared uint hist[RADIX];

void main() {
    uint blocks = state.data[0];
    uint n = state.data[SORT_STATE_N];
    uint t = gl_LocalInvocationIndex;
    if (t < RADIX) {
        hist[t] = 0;
    }
    barrier();
    uint base = gl_WorkGroupID.x * SORT_BLOCK;
    [[unroll]] for (uint i = 0; i < SORT_ITEMS; i++) {
        uint g = base + i * SORT_WG_SIZE + t;
        if (g < n) {
            atomicAdd(hist[bitfieldExtract(keys_in.data[g], int(pc.shift), int(pc.bits))], 1);
        }
    }
    barrier();
    if (t < RADIX) {
        counts.data[t * blocks + gl_WorkGroupID.x] = hist[t];
    }
}
