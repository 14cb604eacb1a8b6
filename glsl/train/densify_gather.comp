#version 460
// Builds one parameter tensor of the new set: element c of slot j comes from element c of
// the slot's source Gaussian, changed by the tensor's role: split children move their mean
// and shrink their scale; Adam moments of every new Gaussian (clone copy, split children)
// start at zero. One invocation per element, over a 2D grid of workgroups (the element
// count can pass 65,535 workgroups in one dimension).
#include "densify_common.glsl"

// ROLE_* (what a gathered tensor is) come from shared_constants.glsl.

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform GatherParams {
    uint elements; // new_n * width
    uint width;
    uint role;
    float ln_split_shrink; // ln(1.6)
} pc;

layout(set = 0, binding = 0) readonly buffer SourceBuf { uint data[]; } slot_source;
layout(set = 0, binding = 1) readonly buffer KindBuf { uint data[]; } slot_kind;
layout(set = 0, binding = 2) readonly buffer DeltaBuf { float data[]; } slot_mean_delta;
layout(set = 0, binding = 3) readonly buffer SrcBuf { float data[]; } src;
layout(set = 0, binding = 4) writeonly buffer DstBuf { float data[]; } dst;

void main() {
    uint e = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * DENSIFY_WG_SIZE
           + gl_LocalInvocationID.x;
    if (e >= pc.elements) {
        return;
    }
    uint j = e / pc.width;
    uint c = e - j * pc.width;
    uint kind = slot_kind.data[j];
    float v = src.data[slot_source.data[j] * pc.width + c];
    bool child = kind >= SLOT_SPLIT0;
    if (pc.role == ROLE_MOMENT && kind != SLOT_KEEP) {
        v = 0.0;
    } else if (pc.role == ROLE_MEANS && child) {
        v += slot_mean_delta.data[3 * j + c];
    } else if (pc.role == ROLE_LOG_SCALES && child) {
        v -= pc.ln_split_shrink;
    }
    dst.data[e] = v;
}
