#version 460
// Compacts the densification candidates in index order (positions from the scan of their
// flags) as sort keys that order by decreasing average gradient; a stable sort then breaks
// ties by index. Invocation n publishes the candidate count and how many fit the budget.
#include "densify_common.glsl"

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform DensifyCompactParams {
    uint n;
    uint max_gaussians;
} pc;

layout(set = 0, binding = 0) readonly buffer AccumBuf { float data[]; } grad_accum;
layout(set = 0, binding = 1) readonly buffer CountBuf { float data[]; } grad_count;
layout(set = 0, binding = 2) readonly buffer CandBuf { uint data[]; } candidate_flags;
layout(set = 0, binding = 3) readonly buffer CandOffsetsBuf { uint data[]; } candidate_offsets; // n + 1
layout(set = 0, binding = 4) writeonly buffer KeysBuf { uint data[]; } candidate_keys;
layout(set = 0, binding = 5) writeonly buffer IdsBuf { uint data[]; } candidate_ids;
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
