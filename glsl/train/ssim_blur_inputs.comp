#version 460
// SSIM forward, pass 1: the horizontal blur of the five local moments of the rendered
// image x and the target y: x, y, x^2, y^2, x*y, per pixel and channel.

#include "ssim_window.glsl"

layout(local_size_x = SSIM_TILE, local_size_y = SSIM_TILE) in;

layout(push_constant) uniform BlurInputsParams {
    // Per pixel, by address (addressed_arrays.glsl: a training image's moments pass one
    // binding at 2.2 MP on lavapipe): the rendered and target RGB, and the moments written.
    uvec2 rgb_addr;
    uvec2 target_addr;
    uvec2 moments_addr;
    uint width;
    uint height;
} pc;

#include "addressed_arrays.glsl"
#define rgb FloatArray(pc.rgb_addr)       // [P][3]
#define target FloatArray(pc.target_addr) // [P][3]
#define moments FloatArrayRW(pc.moments_addr)

// [5][P][3]: blurred x, y, x^2, y^2, xy.

void main() {
    uint px = gl_GlobalInvocationID.x;
    uint py = gl_GlobalInvocationID.y;
    if (px >= pc.width || py >= pc.height) {
        return;
    }
    uint plane = pc.width * pc.height * 3;
    uint row = py * pc.width;
    [[unroll]] for (uint c = 0; c < 3; c++) {
        float mx = 0.0, my = 0.0, xx = 0.0, yy = 0.0, xy = 0.0;
        [[unroll]] for (int k = 0; k < SSIM_TAPS; k++) {
            int qx = int(px) + k - SSIM_RADIUS;
            if (qx >= 0 && qx < int(pc.width)) {
                uint i = (row + uint(qx)) * 3 + c;
                float x = rgb.data[i];
                float y = target.data[i];
                float w = SSIM_WEIGHTS[k];
                mx += w * x;
                my += w * y;
                xx += w * x * x;
                yy += w * y * y;
                xy += w * x * y;
            }
        }
        uint o = (row + px) * 3 + c;
        moments.data[o] = mx;
        moments.data[plane + o] = my;
        moments.data[2 * plane + o] = xx;
        moments.data[3 * plane + o] = yy;
        moments.data[4 * plane + o] = xy;
    }
}
