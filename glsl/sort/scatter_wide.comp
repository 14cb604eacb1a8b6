#version 460
// scatter.comp for CPU drivers (wide_runs.glsl): each lane counts its run's digits, the
// block's scanned offset of each digit is split over the lanes in run order, and each lane
// then moves its run's keys and values one after another to the next slot of their digit:
// equal digits keep their input order (stable).
#extension GL_EXT_control_flow_attributes : require
#include "sort_layout.glsl"
#include "pass_params.glsl"
#include "wide_runs.glsl"

layout(set = 0, binding = 0) readonly buffer StateBuf { uint data[]; } state;
layout(set = 0, binding = 5) readonly buffer OffsetsBuf { uint data[]; } offsets; // scanned counts

void main() {
    uint blocks = state.data[0];
    uvec2 run = run_range(state.data[SORT_STATE_N]);
    uint next[RADIX_WIDE];
    count_run(run, next);
    barrier();
    // Each digit's slots: the block's offset, then each lane's run after the runs before it.
    for (uint d = gl_LocalInvocationIndex; d < RADIX_WIDE; d += SORT_WIDE_LANES) {
        uint slot = offsets.data[d * blocks + gl_WorkGroupID.x];
        for (uint lane = 0; lane < SORT_WIDE_LANES; lane++) {
            uint keys = run_digits[d * SORT_WIDE_LANES + lane];
            run_digits[d * SORT_WIDE_LANES + lane] = slot;
            slot += keys;
        }
    }
    barrier();
    uint lane = gl_LocalInvocationIndex;
    for (uint d = 0; d < RADIX_WIDE; d++) {
        next[d] = run_digits[d * SORT_WIDE_LANES + lane];
    }
    for (uint i = run.x; i < run.y; i++) {
        uint key = keys_in.data[i];
        uint dst = next[key_digit(key)]++;
        keys_out.data[dst] = key;
        values_out.data[dst] = values_in.data[i];
    }
}
