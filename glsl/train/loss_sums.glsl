// Where the loss kernels leave their sums: each workgroup writes one partial per slot
// into partials[slot * stride + group], and loss_reduce.comp adds a slot's partials in a
// fixed order into values[slot]. No float atomics, and the same sums every run.
#ifndef LOSS_SUMS_GLSL
#define LOSS_SUMS_GLSL

// The slots SLOT_* and LOSS_WG, the invocations per workgroup of every kernel that reduces.
#include "shared_constants.glsl"

shared vec4 loss_sum_scratch[LOSS_WG];

// Sum of v over the workgroup (t = gl_LocalInvocationIndex), valid in every invocation.
// A shared-memory tree, not subgroup ops: the same order, so the same rounding, on any
// subgroup size. Call from uniform control flow (it contains barriers).
vec4 workgroup_sum4(vec4 v, uint t) {
    loss_sum_scratch[t] = v;
    barrier();
    for (uint s = LOSS_WG / 2; s > 0; s /= 2) {
        if (t < s) {
            loss_sum_scratch[t] += loss_sum_scratch[t + s];
        }
        barrier();
    }
    vec4 total = loss_sum_scratch[0];
    barrier(); // the scratch may be reused right after
    return total;
}

#endif
