#version 460
// Turns one view's fixed-point gradient sums (blend_backward_fixed*.comp) back into
// floats: out[i] (+)= total_i / scale[group]. One invocation per row of `stride` values
// (a Gaussian). Also records, per group, the largest |total| (FS_TOTAL_MAX; max is
// order-independent), from which the host picks the next view's scales.
//
// Decoding uses 32-bit words only (no int64 needed): the magnitude of the two's
// complement (lo, hi) is hi * 2^32 + lo, rounded once per half.
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#include "shared_constants.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform FixedResolveParams {
    uint rows;
    uint stride;     // values per row
    uint semantic;   // 1: every value is in FIXED_GROUP_SEM; 0: screen-space layout
    uint accumulate; // 1: add into out; 0: overwrite
    // [rows][stride] each, by address (addressed_arrays.glsl)
    uvec2 fixed_sums_addr;
    uvec2 out_grad_addr;
} pc;

#include "addressed_arrays.glsl"
#define fixed_sums UVec2Array(pc.fixed_sums_addr)
#define out_grad FloatArrayRW(pc.out_grad_addr)
layout(set = 0, binding = 2) readonly buffer FixedParamsBuf { float data[]; } fixed_params;
layout(set = 0, binding = 3) buffer FixedStatusBuf { uint data[]; } fixed_status;

uint screen_group(uint k) {
    return k < 2 ? 0u : (k < 5 ? 1u : (k < 6 ? 2u : 3u));
}

float decode(uvec2 q) {
    bool negative = (q.y & 0x80000000u) != 0u;
    uint lo = q.x, hi = q.y;
    if (negative) {
        lo = ~lo + 1u;
        hi = ~hi + (lo == 0u ? 1u : 0u);
    }
    float m = float(hi) * 4294967296.0 + float(lo);
    return negative ? -m : m;
}

void main() {
    uint row = gl_GlobalInvocationID.x;
    float group_max[FIXED_GROUPS];
    for (uint g = 0; g < FIXED_GROUPS; g++) {
        group_max[g] = 0.0;
    }
    if (row < pc.rows) {
        for (uint k = 0; k < pc.stride; k++) {
            uint i = row * pc.stride + k;
            uint group = pc.semantic == 1 ? FIXED_GROUP_SEM : screen_group(k);
            float v = decode(fixed_sums.data[i]) / fixed_params.data[group];
            group_max[group] = max(group_max[group], abs(v));
            out_grad.data[i] = pc.accumulate == 1 ? out_grad.data[i] + v : v;
        }
    }
    for (uint g = 0; g < FIXED_GROUPS; g++) {
        float m = subgroupMax(group_max[g]);
        if (m > 0.0 && subgroupElect()) {
            atomicMax(fixed_status.data[FS_TOTAL_MAX + g], floatBitsToUint(m));
        }
    }
}
