#version 460
// Counts the labeled pixels (label < channels; NO_LABEL marks ignored ones), so the
// cross-entropy kernel can take its mean without a host round trip.

#include "loss_sums.glsl"

layout(local_size_x = LOSS_WG) in;

layout(push_constant) uniform CountLabelsParams {
    uvec2 labels_addr; // [P], by address (addressed_arrays.glsl)
    uint pixels;
    uint channels;
    uint stride;
} pc;

#include "addressed_arrays.glsl"
#define labels UintArray(pc.labels_addr)
layout(set = 0, binding = 1) writeonly buffer PartialsBuf { float data[]; } partials;

void main() {
    uint p = gl_GlobalInvocationID.x;
    bool labeled = p < pc.pixels && labels.data[p] < pc.channels;
    // At most 256 per workgroup: exact in float.
    vec4 total = workgroup_sum4(vec4(labeled ? 1.0 : 0.0, 0.0, 0.0, 0.0), gl_LocalInvocationIndex);
    if (gl_LocalInvocationIndex == 0) {
        partials.data[SLOT_LABELED * pc.stride + gl_WorkGroupID.x] = total.x;
    }
}
