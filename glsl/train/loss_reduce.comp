#version 460
// Second pass of every loss sum: workgroup k adds the `groups` partials of slot
// first_slot + k, always in the same order, into values[slot].

#include "loss_sums.glsl"

layout(local_size_x = LOSS_WG) in;

layout(push_constant) uniform LossReduceParams {
    uint first_slot;
    uint groups;
    uint stride;
} pc;

layout(set = 0, binding = 0) readonly buffer PartialsBuf { float data[]; } partials;
layout(set = 0, binding = 1) buffer ValuesBuf { float data[]; } values;

void main() {
    uint slot = pc.first_slot + gl_WorkGroupID.x;
    uint t = gl_LocalInvocationIndex;
    float acc = 0.0;
    // groups <= 65,535: at most 256 iterations per invocation.
    for (uint g = t; g < pc.groups; g += LOSS_WG) {
        acc += partials.data[slot * pc.stride + g];
    }
    vec4 total = workgroup_sum4(vec4(acc, 0.0, 0.0, 0.0), t);
    if (t == 0) {
        values.data[slot] = total.x;
    }
}
