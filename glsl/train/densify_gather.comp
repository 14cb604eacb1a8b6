#version 460
// Builds one parameter tensor of the new set: element c of slot j comes from element c of
// the slot's source Gaussian, changed by the tensor's role: split children move their mean
// and shrink their scale; Adam moments of every new Gaussian (clone copy, split children)
// start at zero. One invocation per element, over a 2D grid of workgroups (the element
// count can pass 65,535 workgroups in one dimension). A tensor past one binding is gathered
// in parts: `dst` is bound from slot `first_slot`, `src` from Gaussian `src_first`, and a
// slot whose source lies in another part of `src` is left to that part's dispatch.
#include "densify_common.glsl"

// ROLE_* (what a gathered tensor is) come from shared_constants.glsl.

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform GatherParams {
    // Per slot, by address (addressed_arrays.glsl): its source, kind and mean offset.
    uvec2 slot_source_addr;
    uvec2 slot_kind_addr;
    uvec2 slot_mean_delta_addr; // [slots][3]
    uint elements; // slots of this part * width
    uint width;
    uint role;
    float ln_split_shrink; // ln(1.6)
    uint first_slot;       // the part's first slot (dst is bound from it)
    uint src_first;        // the first source Gaussian src is bound from
    uint src_count;        // source Gaussians bound
} pc;

#include "addressed_arrays.glsl"
#define slot_source UintArray(pc.slot_source_addr)
#define slot_kind UintArray(pc.slot_kind_addr)
#define slot_mean_delta FloatArray(pc.slot_mean_delta_addr)

layout(set = 0, binding = 3) readonly buffer SrcBuf { float data[]; } src;
layout(set = 0, binding = 4) writeonly buffer DstBuf { float data[]; } dst;

void main() {
    uint e = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * DENSIFY_WG_SIZE
           + gl_LocalInvocationID.x;
    if (e >= pc.elements) {
        return;
    }
    uint local_slot = e / pc.width;
    uint c = e - local_slot * pc.width;
    uint j = pc.first_slot + local_slot;
    uint source = slot_source.data[j] - pc.src_first; // wraps below src_first: skipped too
    if (source >= pc.src_count) {
        return;
    }
    uint kind = slot_kind.data[j];
    float v = src.data[source * pc.width + c];
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
