#version 460
// Majority vote (Semantic Fusion): each Gaussian's center is projected into the view and votes
// for the label under it. Behind the camera, outside the image and unlabeled pixels do not
// vote; with occlusion on, only a center whose depth is within a tolerance of the
// rendered expected depth at that pixel votes. One invocation per Gaussian owns its
// column of the vote matrix, so no atomics are needed.

layout(local_size_x = 256) in;

layout(push_constant) uniform Params {
    vec4 rot_t0;
    vec4 rot_t1;
    vec4 rot_t2;
    vec4 intrinsics;  // fx fy cx cy
    vec4 clip;        // near far depth_tolerance -
    uvec4 dims;       // width height n occlusion
    uvec4 rows;       // row_begin rows - -
} pc;

layout(set = 0, binding = 0) readonly buffer MeansBuf { float data[]; } means;
layout(set = 0, binding = 1) readonly buffer LabelsBuf { uint data[]; } labels;
layout(set = 0, binding = 2) readonly buffer DepthBuf { float data[]; } depth;
layout(set = 0, binding = 3) buffer VotesBuf { uint data[]; } votes; // [rows][n]

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint n = pc.dims.z;
    if (i >= n) {
        return;
    }
    vec3 mean = vec3(means.data[3 * i], means.data[3 * i + 1], means.data[3 * i + 2]);
    vec3 p = vec3(dot(pc.rot_t0.xyz, mean) + pc.rot_t0.w,
                  dot(pc.rot_t1.xyz, mean) + pc.rot_t1.w,
                  dot(pc.rot_t2.xyz, mean) + pc.rot_t2.w);
    if (!(p.z > pc.clip.x && p.z < pc.clip.y)) {
        return;
    }
    vec2 uv = vec2(pc.intrinsics.x * p.x / p.z + pc.intrinsics.z, pc.intrinsics.y * p.y / p.z + pc.intrinsics.w);
    if (!(uv.x >= 0.0 && uv.y >= 0.0 && uv.x < float(pc.dims.x) && uv.y < float(pc.dims.y))) {
        return;
    }
    uint pix = uint(uv.y) * pc.dims.x + uint(uv.x);
    uint row = labels.data[pix] - pc.rows.x; // unlabeled (0xFFFFFFFF) and other passes' rows fail below
    if (row >= pc.rows.y) {
        return;
    }
    if (pc.dims.w != 0) {
        float d = depth.data[pix];
        if (!(d > 0.0 && abs(p.z - d) <= pc.clip.z * d)) {
            return;
        }
    }
    votes.data[row * n + i] += 1;
}
