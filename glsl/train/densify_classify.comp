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
    // Per Gaussian, by address (addressed_arrays.glsl): log-scales [n][3], opacity logits,
    // the accumulated screen-space gradient and its count, and the flags and output
    // counts written ([n + 1] each).
    uvec2 log_scales_addr;
    uvec2 opacity_logits_addr;
    uvec2 grad_accum_addr;
    uvec2 grad_count_addr;
    uvec2 candidate_flags_addr;
    uvec2 out_count_addr;
    uint n;
    float grad_threshold;
    // Thresholds on the largest log-scale (ln of the host's scale thresholds, so the test
    // needs no exp) and on the opacity logit (logit of min_opacity).
    float opacity_logit_min;
    float ln_prune_scale; // +inf when large Gaussians are not pruned
} pc;

#include "addressed_arrays.glsl"
#define log_scales FloatArray(pc.log_scales_addr)
#define opacity_logits FloatArray(pc.opacity_logits_addr)
#define grad_accum FloatArray(pc.grad_accum_addr)
#define grad_count FloatArray(pc.grad_count_addr)
#define candidate_flags UintArrayRW(pc.candidate_flags_addr)
#define out_count UintArrayRW(pc.out_count_addr)
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
