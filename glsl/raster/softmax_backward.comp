#version 460
// Backward of softmax.comp: adds the logits' gradient p * (g - <g, p>) given the gradient
// g of the blended probabilities p (the softmax-before-blending mode).

layout(local_size_x = 256) in;

layout(push_constant) uniform SoftmaxBackwardParams {
    uint n;
    uint channels;
    // [n][channels] each, by address (addressed_arrays.glsl)
    uvec2 probs_addr;
    uvec2 grad_probs_addr;
    uvec2 grad_logits_addr;
} pc;

#include "addressed_arrays.glsl"
#define probs FloatArray(pc.probs_addr)
#define grad_probs FloatArray(pc.grad_probs_addr)
#define grad_logits FloatArrayRW(pc.grad_logits_addr)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint base = i * pc.channels;
    float gp = 0.0;
    for (uint c = 0; c < pc.channels; c++) {
        gp += grad_probs.data[base + c] * probs.data[base + c];
    }
    for (uint c = 0; c < pc.channels; c++) {
        float p = probs.data[base + c];
        grad_logits.data[base + c] += p * (grad_probs.data[base + c] - gp);
    }
}
