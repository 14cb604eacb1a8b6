#version 460
// Where each Gaussian is observed in one view, for the segment consensus (src/fuse/consensus.rs):
// the pixel under its projected center, or NO_LABEL where the center is behind the camera,
// outside the image or (with occlusion on) not within a tolerance of the rendered expected
// depth there. The host reads that pixel's label and connected label region. One invocation
// per Gaussian writes its own entry, so no atomics are needed.
#include "shared_constants.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform CenterPixelParams {
    vec4 world_to_camera[3]; // rows (R00 R01 R02 t0), ...
    float fx;
    float fy;
    float cx;
    float cy;
    float near;
    float far;
    float depth_tolerance; // relative, of the occlusion test
    uint occlusion;        // 1: observed only where the center is within tolerance of the depth
    uint width;
    uint height;
    uint n;
} pc;

layout(set = 0, binding = 0) readonly buffer MeansBuf { float data[]; } means;
layout(set = 0, binding = 1) readonly buffer DepthBuf { float data[]; } depth;
layout(set = 0, binding = 2) writeonly buffer PixelsBuf { uint data[]; } pixels; // [n]

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint pix = NO_LABEL;
    vec3 mean = vec3(means.data[3 * i], means.data[3 * i + 1], means.data[3 * i + 2]);
    vec3 p = vec3(dot(pc.world_to_camera[0].xyz, mean) + pc.world_to_camera[0].w,
                  dot(pc.world_to_camera[1].xyz, mean) + pc.world_to_camera[1].w,
                  dot(pc.world_to_camera[2].xyz, mean) + pc.world_to_camera[2].w);
    if (p.z > pc.near && p.z < pc.far) {
        vec2 uv = vec2(pc.fx * p.x / p.z + pc.cx, pc.fy * p.y / p.z + pc.cy);
        if (uv.x >= 0.0 && uv.y >= 0.0 && uv.x < float(pc.width) && uv.y < float(pc.height)) {
            uint candidate = uint(uv.y) * pc.width + uint(uv.x);
            bool visible = true;
            if (pc.occlusion != 0) {
                float d = depth.data[candidate];
                visible = d > 0.0 && abs(p.z - d) <= pc.depth_tolerance * d;
            }
            pix = visible ? candidate : NO_LABEL;
        }
    }
    pixels.data[i] = pix;
}
