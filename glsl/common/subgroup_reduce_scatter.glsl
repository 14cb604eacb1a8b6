// Sums 16 per-lane values over the subgroup and leaves each sum in one lane:
// a reduce-scatter by recursive halving. Each round exchanges half of a lane's remaining
// values with the lane `o` apart (o = 1, 2, 4, 8) and keeps the half its bit of `o` picks,
// so 16 values cost 8 + 4 + 2 + 1 shuffles (plus one per doubling past 16 lanes) instead of
// 16 full reductions of log2(size) shuffles each. Works for any subgroup size from 4: with
// fewer than 16 lanes a lane ends with 16 / size sums.
//
// After reduce_scatter16(v): v[i] of lane l totals value reduce_scatter_index(l, i) for
// i < 4 (REDUCE_SCATTER_NONE where that lane holds no such sum of its own). All lanes of the subgroup must call it (uniform control flow). The
// blend backward uses it for a step's screen-space values and for its chunk of channels.
#ifndef SUBGROUP_REDUCE_SCATTER_GLSL
#define SUBGROUP_REDUCE_SCATTER_GLSL

#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_shuffle : require

// One halving round over the first 2 * HALF values at lane distance O.
#define REDUCE_SCATTER_ROUND(v, HALF, O)                                          \
    {                                                                             \
        bool upper = (gl_SubgroupInvocationID & (O)) != 0u;                       \
        [[unroll]] for (uint i = 0; i < (HALF); i++) {                            \
            float send = upper ? v[i] : v[i + (HALF)];                            \
            float keep = upper ? v[i + (HALF)] : v[i];                            \
            v[i] = keep + subgroupShuffleXor(send, (O));                          \
        }                                                                         \
    }

void reduce_scatter16(inout float v[16]) {
    uint size = gl_SubgroupSize;
    REDUCE_SCATTER_ROUND(v, 8u, 1u)
    REDUCE_SCATTER_ROUND(v, 4u, 2u)
    if (size > 4u) {
        REDUCE_SCATTER_ROUND(v, 2u, 4u)
    }
    if (size > 8u) {
        REDUCE_SCATTER_ROUND(v, 1u, 8u)
    }
    for (uint o = 16u; o < size; o *= 2u) {
        v[0] += subgroupShuffleXor(v[0], o);
    }
}

// Which of the 16 values lane `lane`'s sum v[i] (i < 4) totals, or REDUCE_SCATTER_NONE
// where the lane holds fewer sums or only a copy (lanes past the 16th). A lane keeps
// 16 / min(size, 16) sums, from the value its bits of 1, 2, 4, 8 picked the halves of.
#define REDUCE_SCATTER_NONE 0xFFFFFFFFu
uint reduce_scatter_index(uint lane, uint i) {
    uint held = 16u / min(gl_SubgroupSize, 16u);
    if (lane >= 16u || i >= held) {
        return REDUCE_SCATTER_NONE;
    }
    uint first = 0u;
    uint half_len = 8u;
    for (uint o = 1u; o < min(gl_SubgroupSize, 16u); o *= 2u) {
        if ((lane & o) != 0u) {
            first += half_len;
        }
        half_len /= 2u;
    }
    return first + i;
}

#endif
