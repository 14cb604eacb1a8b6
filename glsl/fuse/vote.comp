#version 460
// Majority vote (Semantic Fusion): each Gaussian's center is projected into the view and votes
// for the label under it. Behind the camera, outside the image and unlabeled pixels do not
// vote; with occlusion on, only a center whose depth is within a tolerance of the
// rendered expected depth at that pixel votes. One invocation per Gaussian owns its
// column of the vote matrix, so no atomics are needed.

layout(local_size_x = 256) in;

layout(push_constant) uniform VoteParams {
    vec4 world_to_camera[3]; // rows (R00 R01 R02 t0), ...
    float fx;
    float fy;
    float cx;
    float cy;
    float near;
    float far;
    float depth_tolerance; // relative, of the occlusion test
    uint occlusion;        // 1: vote only where the center is within tolerance of the depth
    uint width;
    uint height;
    uint n;
    uint row_begin;        // first class row of the votes this pass holds
    uint rows;             // class rows this pass holds
} pc;

layout(set = 0, binding = 0) readonly buffer MeansBuf { float data[]; } means;
layout(set = 0, binding = 1) readonly buffer LabelsBuf { uint data[]; } labels;
layout(set = 0, binding = 2) readonly buffer DepthBuf { float data[]; } depth;
layout(set = 0, binding = 3) buffer VotesBuf { uint data[]; } votes; // [rows][n]

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint n = pc.n;
    if (i >= n) {
        return;
    }
    vec3 mean = vec3(means.data[3 * i], means.data[3 * i + 1], means.data[3 * i + 2]);
    vec3 p = vec3(dot(pc.world_to_camera[0].xyz, mean) + pc.world_to_camera[0].w,
                  dot(pc.world_to_camera[1].xyz, mean) + pc.world_to_camera[1].w,
                  dot(pc.world_to_camera[2].xyz, mean) + pc.world_to_camera[2].w);
    if (!(p.z > pc.near && p.z < pc.far)) {
        return;
    }
    vec2 uv = vec2(pc.fx * p.x / p.z + pc.cx, pc.fy * p.y / p.z + pc.cy);
    if (!(uv.x >= 0.0 && uv.y >= 0.0 && uv.x < float(pc.width) && uv.y < float(pc.height))) {
        return;
    }
    uint pix = uint(uv.y) * pc.width + uint(uv.x);
    uint row = labels.data[pix] - pc.row_begin; // unlabeled (NO_LABEL) and other passes' rows fail below
    if (row >= pc.rows) {
        return;
    }
    if (pc.occlusion != 0) {
        float d = depth.data[pix];
        if (!(d > 0.0 && abs(p.z - d) <= pc.depth_tolerance * d)) {
            return;
        }
    }
    votes.data[row * n + i] += 1;
}
