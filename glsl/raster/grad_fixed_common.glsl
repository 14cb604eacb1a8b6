// Fixed-point conversion shared by grad_add_fixed64.glsl and grad_add_fixed32x2.glsl: a
// step's float value v becomes the 64-bit integer round(v * scale[group]), added with
// integer atomics. Integer sums do not depend on the order of the adds, so the gradients
// are bit-identical run to run (docs/joint-training.md, "Deterministic training").
//
// Range: the host sets the step bound 2^b so that every add of a view (at most one per
// padded pixel and semantic chunk) keeps the 64-bit total below 2^62: a step whose
// |v * scale| reaches 2^b is not added but flagged (FS_OVERFLOW) with its magnitude, and
// the host redoes the view with a smaller scale. A NaN or infinite value is flagged too
// (FS_NONFINITE). Nothing wraps.

#include "shared_constants.glsl"

layout(set = 0, binding = 17) readonly buffer FixedParamsBuf { float data[]; } fixed_params;
layout(set = 0, binding = 18) buffer FixedStatusBuf { uint data[]; } fixed_status;

// The fixed-point group of screen-space value k (GRAD2D_STRIDE layout).
uint screen_group(uint k) {
    return k < 2 ? 0u : (k < 5 ? 1u : (k < 6 ? 2u : 3u));
}

// round(v * scale) as two's complement (lo, hi); false when it is not to be added.
bool to_fixed(float v, uint group, out uvec2 q) {
    q = uvec2(0u);
    float x = v * fixed_params.data[group];
    if (isnan(x) || isinf(x)) {
        atomicOr(fixed_status.data[FS_NONFINITE], 1u);
        return false;
    }
    float m = roundEven(abs(x));
    if (m >= fixed_params.data[FIXED_PARAM_LIMIT]) {
        atomicOr(fixed_status.data[FS_OVERFLOW], 1u);
        atomicMax(fixed_status.data[FS_STEP_MAX + group], floatBitsToUint(abs(v)));
        return false;
    }
    // m is an integer below 2^62 with 24 significant bits: both halves are exact.
    float hi_f = floor(m * (1.0 / 4294967296.0));
    uint lo = uint(m - hi_f * 4294967296.0);
    uint hi = uint(hi_f);
    if (x < 0.0) { // negate: two's complement of (hi, lo)
        lo = ~lo + 1u;
        hi = ~hi + (lo == 0u ? 1u : 0u);
    }
    q = uvec2(lo, hi);
    return true;
}
