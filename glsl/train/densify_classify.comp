#version 460
// First step of a densification plan: per Gaussian, prune or keep; a kept Gaussian whose
// average gradient passes the threshold becomes a densification candidate. Writes the
// candidate flags (scanned for compaction), each Gaussian's output count before the budget
// (1 if kept, 0 if pruned) and counts the survivors. Invocation n writes the trailing zero
// of both flag arrays, so their exclusive scans end with the totals.
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#include "densify_common.glsl"

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform DensifyClassifyParams {
    uvec2 log_scales_addr; // [n][3], by address (gaussian_arrays.glsl)
    uint n;
    float grad_threshold;
    // Thresholds on the largest log-scale (ln of the host's scale thresholds, so the test
    // needs no exp) and on the opacity logit (logit of min_opacity).
    float opacity_logit_min;
    float ln_prune_scale; // +inf when large Gaussians are not pruned
} pc;

#include "gaussian_arrays.glsl"
#define log_scales FloatArray(pc.log_scales_addr)
layout(set = 0, binding = 1) readonly buffer OpacityBuf { float data[]; } opacity_logits;
layout(set = 0, binding = 2) readonly buffer AccumBuf { float data[]; } grad_accum;
layout(set = 0, binding = 3) readonly buffer CountBuf { float data[]; } grad_count;
layout(set = 0, binding = 4) writeonly buffer CandBuf { uint data[]; } candidate_flags; // n + 1
layout(set = 0, binding = 5) writeonly buffer OutCountBuf { uint data[]; } out_count;   // n + 1
layout(set = 0, binding = 6) buffer StatusBuf { uint data[]; } status;

void main() {
    uint i = gl_GlobalInvocationID.x;
    bool survives = false;
    if (i < pc.n) {
        vec3 ls = vec3(log_scales.data[3 * i], log_scales.data[3 * i + 1],
                       log_scales.data[3 * i + 2]);
        bool pruned = opacity_logits.data[i] < pc.opacity_logit_min
                   || max3(ls) > pc.ln_prune_scale;
        survives = !pruned;
        float g = avg_grad(grad_accum.data[i], grad_count.data[i]);
        candidate_flags.data[i] = survives && g >= pc.grad_threshold ? 1 : 0;
        out_count.data[i] = survives ? 1 : 0;
    } else if (i == pc.n) {
        candidate_flags.data[i] = 0;
        out_count.data[i] = 0;
    }
    // One atomic per subgroup (every invocation reaches this: no early return above).
    uint kept = subgroupAdd(survives ? 1u : 0u);
    if (subgroupElect() && kept > 0) {
        atomicAdd(status.data[DS_SURVIVORS], kept);
    }
}
