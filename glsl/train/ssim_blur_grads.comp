#version 460
// SSIM backward, pass 1: the horizontal blur of the three moment gradients (the window's
// transpose is the window itself).

#include "ssim_window.glsl"

layout(local_size_x = SSIM_TILE, local_size_y = SSIM_TILE) in;

layout(push_constant) uniform BlurGradsParams {
    // Per pixel, by address (addressed_arrays.glsl): the moment gradients and their blur.
    uvec2 moment_grads_addr;
    uvec2 blurred_addr;
    uint width;
    uint height;
} pc;

#include "addressed_arrays.glsl"
#define moment_grads FloatArray(pc.moment_grads_addr) // [3][P][3]
#define blurred FloatArrayRW(pc.blurred_addr)         // [3][P][3]

void main() {
    uint px = gl_GlobalInvocationID.x;
    uint py = gl_GlobalInvocationID.y;
    if (px >= pc.width || py >= pc.height) {
        return;
    }
    uint plane = pc.width * pc.height * 3;
    uint row = py * pc.width;
    [[unroll]] for (uint c = 0; c < 3; c++) {
        float g[3] = float[3](0.0, 0.0, 0.0);
        [[unroll]] for (int k = 0; k < SSIM_TAPS; k++) {
            int qx = int(px) + k - SSIM_RADIUS;
            if (qx >= 0 && qx < int(pc.width)) {
                uint i = (row + uint(qx)) * 3 + c;
                float w = SSIM_WEIGHTS[k];
                [[unroll]] for (uint q = 0; q < 3; q++) {
                    g[q] += w * moment_grads.data[q * plane + i];
                }
            }
        }
        uint o = (row + px) * 3 + c;
        [[unroll]] for (uint q = 0; q < 3; q++) {
            blurred.data[q * plane + o] = g[q];
        }
    }
}
