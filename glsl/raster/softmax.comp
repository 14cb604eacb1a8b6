#version 460
// Per-Gaussian softmax of the semantic logits, for the mode that blends probabilities
// (Gaussian Semantics' ablation) instead of raw logits.

layout(local_size_x = 256) in;

layout(push_constant) uniform SoftmaxParams {
    uint n;
    uint channels;
    // [n][channels] each, by address (addressed_arrays.glsl)
    uvec2 logits_addr;
    uvec2 probs_addr;
} pc;

#include "addressed_arrays.glsl"
#define logits FloatArray(pc.logits_addr)
#define probs FloatArrayRW(pc.probs_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint base = i * pc.channels;
    float m = -3.402823466e38;
    for (uint c = 0; c < pc.channels; c++) {
        m = max(m, logits.data[base + c]);
    }
    float sum = 0.0;
    for (uint c = 0; c < pc.channels; c++) {
        sum += exp(logits.data[base + c] - m);
    }
    for (uint c = 0; c < pc.channels; c++) {
        probs.data[base + c] = exp(logits.data[base + c] - m) / sum;
    }
}
