#version 460
// 3DGS opacity reset: caps every opacity at a small value (min in logit space equals min
// in opacity space, sigmoid being increasing). The host zeroes the Adam moments.
#include "densify_common.glsl"

layout(local_size_x = DENSIFY_WG_SIZE) in;

layout(push_constant) uniform ResetOpacityParams {
    uvec2 opacity_logits_addr; // [n], by address (addressed_arrays.glsl)
    uint n;
    float max_logit;
} pc;

#include "addressed_arrays.glsl"
#define opacity_logits FloatArrayRW(pc.opacity_logits_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < pc.n) {
        opacity_logits.data[i] = min(opacity_logits.data[i], pc.max_logit);
    }
}
