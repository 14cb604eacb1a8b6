#version 460
// count.comp for CPU drivers (wide_runs.glsl): each block's digit histogram, summed over
// the runs of its lanes, stored digit-major as count.comp stores it.
#extension GL_EXT_control_flow_attributes : require
#include "sort_layout.glsl"
#include "pass_params.glsl"
#include "wide_runs.glsl"

layout(set = 0, binding = 0) readonly buffer StateBuf { uint data[]; } state;
layout(set = 0, binding = 2) writeonly buffer CountsBuf { uint data[]; } counts;

void main() {
    uint blocks = state.data[0];
    uint hist[RADIX_WIDE];
    count_run(run_range(state.data[SORT_STATE_N]), hist);
    barrier();
    for (uint d = gl_LocalInvocationIndex; d < RADIX_WIDE; d += SORT_WIDE_LANES) {
        uint total = 0;
        for (uint lane = 0; lane < SORT_WIDE_LANES; lane++) {
            total += run_digits[d * SORT_WIDE_LANES + lane];
        }
        counts.data[d * blocks + gl_WorkGroupID.x] = total;
    }
}
