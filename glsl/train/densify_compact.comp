#version 460
// Compacts the densification candidates in index order (positions from the scan of their
// flags) as sort keys that order by decreasing average gradient; a stable sort then breaks
// ties by index. Invocation n publishes the candidate count and how many fit the budget.
#include "densify_common.glsl"

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform DensifyCompactParams {
    // Per Gaussian, by address (addressed_arrays.glsl): the accumulated gradient and its
    // count, the candidate flags and their scan ([n + 1]), and the candidates' sort keys
    // and ids written.
    uvec2 grad_accum_addr;
    uvec2 grad_count_addr;
    uvec2 candidate_flags_addr;
    uvec2 candidate_offsets_addr;
    uvec2 candidate_keys_addr;
    uvec2 candidate_ids_addr;
    uint n;
    uint max_gaussians;
} pc;

#include "addressed_arrays.glsl"
#define grad_accum FloatArray(pc.grad_accum_addr)
#define grad_count FloatArray(pc.grad_count_addr)
#define candidate_flags UintArray(pc.candidate_flags_addr)
#define candidate_offsets UintArray(pc.candidate_offsets_addr)
#define candidate_keys UintArrayRW(pc.candidate_keys_addr)
#define candidate_ids UintArrayRW(pc.candidate_ids_addr)
layout(set = 0, binding = 6) buffer StatusBuf { uint data[]; } status;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i > pc.n) {
        return;
    }
    if (i == pc.n) {
        uint candidates = candidate_offsets.data[pc.n];
        uint survivors = status.data[DS_SURVIVORS];
        // Each densified Gaussian adds exactly one (a clone adds a copy; a split turns one
        // into two), so the budget is what is left after the survivors.
        uint budget = pc.max_gaussians > survivors ? pc.max_gaussians - survivors : 0;
        status.data[DS_CANDIDATES] = candidates;
        status.data[DS_DENSIFIED] = min(candidates, budget);
        return;
    }
    if (candidate_flags.data[i] != 0) {
        uint j = candidate_offsets.data[i];
        candidate_keys.data[j] = descending_key(avg_grad(grad_accum.data[i], grad_count.data[i]));
        candidate_ids.data[j] = i;
    }
}
