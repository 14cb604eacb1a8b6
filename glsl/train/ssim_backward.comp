#version 460
// SSIM backward, pass 2, and the L1 gradient: the vertical blur of the moment gradients,
// then the chain rule through the moments (blur(x), blur(x^2), blur(xy)) gives
// dL/dx = G*g_mx + 2x G*g_xx + y G*g_xy, plus 0.8 sign(x - y) / (3 * pixels).
// Overwrites v_rgb.

#include "ssim_window.glsl"

layout(local_size_x = SSIM_TILE, local_size_y = SSIM_TILE) in;

layout(push_constant) uniform SsimBackwardParams {
    // Per pixel, by address (addressed_arrays.glsl): the rendered and target RGB, the
    // blurred moment gradients, and dL/d rgb written.
    uvec2 rgb_addr;
    uvec2 target_addr;
    uvec2 blurred_addr;
    uvec2 v_rgb_addr;
    uint width;
    uint height;
    float l1_weight; // 0.8 / (3 * pixels)
} pc;

#include "addressed_arrays.glsl"
#define rgb FloatArray(pc.rgb_addr)
#define target FloatArray(pc.target_addr)
#define blurred FloatArray(pc.blurred_addr) // [3][P][3]
#define v_rgb FloatArrayRW(pc.v_rgb_addr)   // [P][3]

void main() {
    uint px = gl_GlobalInvocationID.x;
    uint py = gl_GlobalInvocationID.y;
    if (px >= pc.width || py >= pc.height) {
        return;
    }
    uint plane = pc.width * pc.height * 3;
    [[unroll]] for (uint c = 0; c < 3; c++) {
        float g[3] = float[3](0.0, 0.0, 0.0);
        [[unroll]] for (int k = 0; k < SSIM_TAPS; k++) {
            int qy = int(py) + k - SSIM_RADIUS;
            if (qy >= 0 && qy < int(pc.height)) {
                uint i = (uint(qy) * pc.width + px) * 3 + c;
                float w = SSIM_WEIGHTS[k];
                [[unroll]] for (uint q = 0; q < 3; q++) {
                    g[q] += w * blurred.data[q * plane + i];
                }
            }
        }
        uint o = (py * pc.width + px) * 3 + c;
        float x = rgb.data[o];
        float y = target.data[o];
        // sign(0) = 0, as torch's abs backward.
        v_rgb.data[o] = g[0] + 2.0 * x * g[1] + y * g[2] + pc.l1_weight * sign(x - y);
    }
}
