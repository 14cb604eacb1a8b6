#version 460
// Backward of softmax.comp: adds the logits' gradient p * (g - <g, p>) given the gradient
// g of the blended probabilities p (the softmax-before-blending mode).

layout(local_size_x = 256) in;

layout(push_constant) uniform SoftmaxParams {
    uint n;
    uint channels;
} pc;

layout(set = 0, binding = 0) readonly buffer ProbsBuf { float data[]; } probs;
layout(set = 0, binding = 1) readonly buffer GradProbsBuf { float data[]; } grad_probs;
layout(set = 0, binding = 2) buffer GradLogitsBuf { float data[]; } grad_logits;

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
