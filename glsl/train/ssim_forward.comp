#version 460
// SSIM forward, pass 2: the vertical blur finishes the local moments; then per pixel and
// channel the SSIM, its partial derivatives with respect to the three blurred moments it
// depends on through x (times dL/dSSIM, ready for the backward blur), and the partial sums
// of |x - y|, SSIM and (x - y)^2 for the logged values.

#include "ssim_window.glsl"
#include "loss_sums.glsl"

layout(local_size_x = SSIM_TILE, local_size_y = SSIM_TILE) in;

layout(push_constant) uniform SsimForwardParams {
    // Per pixel, by address (addressed_arrays.glsl): the rendered and target RGB, the
    // blurred moments, and their gradient written.
    uvec2 rgb_addr;
    uvec2 target_addr;
    uvec2 moments_addr;
    uvec2 moment_grads_addr;
    uint width;
    uint height;
    uint stride;        // partials per slot
    float inv_count;    // 1 / (3 * pixels): each element's share of a mean
    float ssim_weight;  // dL/dSSIM(p, c) = -0.2 / (3 * pixels)
} pc;

#include "addressed_arrays.glsl"
#define rgb FloatArray(pc.rgb_addr)
#define target FloatArray(pc.target_addr)
#define moments FloatArray(pc.moments_addr) // [5][P][3]
// [3][P][3]: dL/d(blurred x), dL/d(blurred x^2), dL/d(blurred xy).
#define moment_grads FloatArrayRW(pc.moment_grads_addr)
layout(set = 0, binding = 4) writeonly buffer PartialsBuf { float data[]; } partials;

void main() {
    uint px = gl_GlobalInvocationID.x;
    uint py = gl_GlobalInvocationID.y;
    bool inside = px < pc.width && py < pc.height;
    uint plane = pc.width * pc.height * 3;
    vec4 sums = vec4(0.0); // |x - y|, SSIM, (x - y)^2
    if (inside) {
        [[unroll]] for (uint c = 0; c < 3; c++) {
            float m[5] = float[5](0.0, 0.0, 0.0, 0.0, 0.0);
            [[unroll]] for (int k = 0; k < SSIM_TAPS; k++) {
                int qy = int(py) + k - SSIM_RADIUS;
                if (qy >= 0 && qy < int(pc.height)) {
                    uint i = (uint(qy) * pc.width + px) * 3 + c;
                    float w = SSIM_WEIGHTS[k];
                    [[unroll]] for (uint q = 0; q < 5; q++) {
                        m[q] += w * moments.data[q * plane + i];
                    }
                }
            }
            float mx = m[0], my = m[1];
            float sxx = m[2] - mx * mx;
            float syy = m[3] - my * my;
            float sxy = m[4] - mx * my;
            float a1 = 2.0 * mx * my + SSIM_C1;
            float a2 = 2.0 * sxy + SSIM_C2;
            float b1 = mx * mx + my * my + SSIM_C1;
            float b2 = sxx + syy + SSIM_C2;
            float den = b1 * b2;
            float ssim = a1 * a2 / den;
            // S = a1 a2 / (b1 b2); mx enters a1, a2 (via sxy), b1, b2 (via sxx).
            float d_mx = (2.0 * my * (a2 - a1) - 2.0 * mx * ssim * (b2 - b1)) / den;
            float d_xx = -ssim / b2;
            float d_xy = 2.0 * a1 / den;

            uint o = (py * pc.width + px) * 3 + c;
            moment_grads.data[o] = pc.ssim_weight * d_mx;
            moment_grads.data[plane + o] = pc.ssim_weight * d_xx;
            moment_grads.data[2 * plane + o] = pc.ssim_weight * d_xy;

            float d = rgb.data[o] - target.data[o];
            sums += vec4(abs(d), ssim, d * d, 0.0) * pc.inv_count;
        }
    }
    vec4 total = workgroup_sum4(sums, gl_LocalInvocationIndex);
    if (gl_LocalInvocationIndex == 0) {
        uint group = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
        partials.data[SLOT_L1 * pc.stride + group] = total.x;
        partials.data[SLOT_SSIM * pc.stride + group] = total.y;
        partials.data[SLOT_SE * pc.stride + group] = total.z;
    }
}
