#version 460
// Majority vote (Semantic Fusion): each Gaussian's center is projected into the view and votes
// for the label under it. Behind the camera, outside the image and unlabeled pixels do not
// vote; with occlusion on, only a center whose depth is within a tolerance of the
// rendered expected depth at that pixel votes. One invocation per Gaussian owns its
// column of the vote matrix, so no atomics are needed.

layout(local_size_x = 256) in;

layout(set = 0, binding = 1) readonly buffer LabelsBuf { uint data[]; } labels;
layout(set = 0, binding = 2) readonly buffer DepthBuf { float data[]; } depth;

#include "center_pixel.glsl"
#define votes UintArrayRW(pc.out_addr) // [rows][n]

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) {
        return;
    }
    uint pix = center_pixel(i);
    if (pix == NO_LABEL) {
        return;
    }
    uint row = labels.data[pix] - pc.row_begin; // unlabeled (NO_LABEL) and other passes' rows fail below
    if (row < pc.rows) {
        votes.data[row * pc.n + i] += 1;
    }
}
