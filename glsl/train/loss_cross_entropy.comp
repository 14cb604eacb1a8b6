#version 460
// Semantic cross-entropy per labeled pixel, its gradient, and the partial sums of its
// mean. Mode 0 (raw logits): CE = logsumexp(s) - s[label], gradient softmax(s) - onehot.
// Mode 1 (softmax): s is already a distribution, CE = -log(max(s[label], 1e-6)), gradient
// -1/s[label] at the label unless clamped. Both are scaled by lambda / labeled pixels (the
// count comes from loss_count_labels + loss_reduce). Overwrites v_sem_norm; ignored pixels
// (label NO_LABEL, or any label >= channels) get zeros.

#include "loss_sums.glsl"

layout(local_size_x = LOSS_WG) in;

layout(push_constant) uniform CrossEntropyParams {
    // Per pixel, by address (addressed_arrays.glsl): the normalized semantic channels, the
    // labels, and the channels' gradient written.
    uvec2 sem_norm_addr;
    uvec2 labels_addr;
    uvec2 v_sem_norm_addr;
    uint pixels;
    uint channels;
    uint stride;
    uint mode;     // 0: raw logits, 1: softmax
    float lambda;  // lambda_sem
} pc;

const float PROB_FLOOR = 1e-6;

#include "addressed_arrays.glsl"
#define sem_norm FloatArray(pc.sem_norm_addr) // [P][C]
#define labels UintArray(pc.labels_addr)       // [P]
layout(set = 0, binding = 2) readonly buffer ValuesBuf { float data[]; } values;
#define v_sem_norm FloatArrayRW(pc.v_sem_norm_addr)
layout(set = 0, binding = 4) writeonly buffer PartialsBuf { float data[]; } partials;

void main() {
    uint p = gl_GlobalInvocationID.x;
    float labeled = values.data[SLOT_LABELED];
    float inv_labeled = labeled > 0.0 ? 1.0 / labeled : 0.0;
    float ce = 0.0;
    if (p < pc.pixels) {
        uint base = p * pc.channels;
        uint label = labels.data[p];
        if (label >= pc.channels) {
            for (uint k = 0; k < pc.channels; k++) {
                v_sem_norm.data[base + k] = 0.0;
            }
        } else if (pc.mode == 0) {
            float m = -3.402823466e38;
            for (uint k = 0; k < pc.channels; k++) {
                m = max(m, sem_norm.data[base + k]);
            }
            float z = 0.0;
            for (uint k = 0; k < pc.channels; k++) {
                z += exp(sem_norm.data[base + k] - m);
            }
            ce = m + log(z) - sem_norm.data[base + label];
            float scale = pc.lambda * inv_labeled;
            for (uint k = 0; k < pc.channels; k++) {
                float prob = exp(sem_norm.data[base + k] - m) / z;
                v_sem_norm.data[base + k] = scale * (prob - (k == label ? 1.0 : 0.0));
            }
        } else {
            float prob = sem_norm.data[base + label];
            ce = -log(max(prob, PROB_FLOOR));
            float grad = prob > PROB_FLOOR ? -pc.lambda * inv_labeled / prob : 0.0;
            for (uint k = 0; k < pc.channels; k++) {
                v_sem_norm.data[base + k] = k == label ? grad : 0.0;
            }
        }
    }
    vec4 total = workgroup_sum4(vec4(ce * inv_labeled, 0.0, 0.0, 0.0), gl_LocalInvocationIndex);
    if (gl_LocalInvocationIndex == 0) {
        partials.data[SLOT_CE * pc.stride + gl_WorkGroupID.x] = total.x;
    }
}
