#version 460
// Entropy regularizer (Gaussian Semantics Eq. 4-6) on per-Gaussian semantic logits s_i:
// H_i = -sum_k p_k log p_k with p = softmax(s_i), dH/ds_k = -p_k (log p_k + H_i).
// ADDS weight * dH/ds into grad_logits (weight = lambda_H / N) and writes the partial
// sums of H_i / N. Grid-stride over Gaussians so the partials fit a fixed slot size.
//
// Both are formed from d_k = s_k - max s and its mean under p, d_bar = sum_k p_k d_k:
// H = log z - d_bar and log p_k + H = d_k - d_bar (log z cancels). Equal logits give
// d = 0 and a gradient of exactly 0, where log p_k + H summed rounding of log z and H: a
// few ulps that Adam, which scales each step to the gradient's own size, took as full
// steps (a uniform start moved by lr every iteration).

#include "loss_sums.glsl"

layout(local_size_x = LOSS_WG) in;

layout(push_constant) uniform EntropyParams {
    // [N][C] each, by address (addressed_arrays.glsl)
    uvec2 logits_addr;
    uvec2 grad_logits_addr;
    uint n;
    uint channels;
    uint stride;
    float weight;     // lambda_H / N
    float inv_n;      // 1 / N
} pc;

#include "addressed_arrays.glsl"
#define logits FloatArray(pc.logits_addr)
#define grad_logits FloatArrayRW(pc.grad_logits_addr)
layout(set = 0, binding = 2) writeonly buffer PartialsBuf { float data[]; } partials;

void main() {
    uint threads = gl_NumWorkGroups.x * LOSS_WG;
    float h_sum = 0.0;
    for (uint i = gl_GlobalInvocationID.x; i < pc.n; i += threads) {
        uint base = i * pc.channels;
        float m = -3.402823466e38;
        for (uint k = 0; k < pc.channels; k++) {
            m = max(m, logits.data[base + k]);
        }
        float z = 0.0;
        float d_bar = 0.0;
        for (uint k = 0; k < pc.channels; k++) {
            float d = logits.data[base + k] - m;
            z += exp(d);
            d_bar += exp(d) * d;
        }
        d_bar /= z;
        float h = log(z) - d_bar;
        for (uint k = 0; k < pc.channels; k++) {
            float d = logits.data[base + k] - m;
            grad_logits.data[base + k] -= pc.weight * (exp(d) / z) * (d - d_bar);
        }
        h_sum += h;
    }
    vec4 total = workgroup_sum4(vec4(h_sum * pc.inv_n, 0.0, 0.0, 0.0), gl_LocalInvocationIndex);
    if (gl_LocalInvocationIndex == 0) {
        partials.data[SLOT_ENTROPY * pc.stride + gl_WorkGroupID.x] = total.x;
    }
}
