// Push constants and the pixel under a Gaussian's projected center, shared by the vote
// (fuse/vote.comp) and the segment consensus's observations (fuse/center_pixel.comp). The
// includer declares `depth` (a float buffer) first, and with OPAQUE_DEPTH_TEST defined
// `opaque_depth` too; the means are reached by address.
#ifndef CENTER_PIXEL_GLSL
#define CENTER_PIXEL_GLSL

#include "shared_constants.glsl" // NO_LABEL

layout(push_constant) uniform CenterParams {
    vec4 world_to_camera[3]; // rows (R00 R01 R02 t0), ...
    uvec2 means_addr;        // the scene's means [n][3] (addressed_arrays.glsl)
    uvec2 out_addr;          // vote: the pass's vote rows [rows][n]; observations: each
                             // Gaussian's center pixel [n]
    uvec2 spatial_addr;      // observations: each Gaussian's number in space [n], where its
                             // pixel goes; 0: none, at its own index
    float fx;
    float fy;
    float cx;
    float cy;
    float near;
    float far;
    float depth_tolerance; // relative, of the occlusion test
    uint occlusion;        // 1: only where the center is within tolerance of the depth
    uint width;
    uint height;
    uint n;
    uint row_begin;        // vote: first class row of the votes this pass holds
    uint rows;             // vote: class rows this pass holds
    float behind_tolerance; // OPAQUE_DEPTH_TEST: relative, how far behind the opaque depth
} pc;

#include "addressed_arrays.glsl"
#define means FloatArray(pc.means_addr)

#if defined(OPAQUE_DEPTH_TEST)
// The farthest opaque depth of pixel (x, y) and its eight neighbours in the image, or 0 where
// one of them never turned opaque. The center lies somewhere inside its pixel, and a surface
// seen at a slant changes depth across a pixel by more than the tolerance (a few percent at
// 100 pixels across): the pixel's own depth alone would hide the surface's own Gaussians.
float farthest_opaque_depth(uint x, uint y) {
    float farthest = 0.0;
    for (uint ny = max(y, 1u) - 1u; ny <= min(y + 1u, pc.height - 1u); ny++) {
        for (uint nx = max(x, 1u) - 1u; nx <= min(x + 1u, pc.width - 1u); nx++) {
            float o = opaque_depth.data[ny * pc.width + nx];
            if (!(o > 0.0)) {
                return 0.0;
            }
            farthest = max(farthest, o);
        }
    }
    return farthest;
}
#endif

// The pixel under Gaussian i's center, or NO_LABEL where the center is outside the clip
// range or the image, or (with occlusion) not within the tolerance of the rendered depth
// (with OPAQUE_DEPTH_TEST: or behind the farthest opaque depth of its pixel and the pixel's
// eight neighbours by more than behind_tolerance).
uint center_pixel(uint i) {
    vec3 mean = vec3(means.data[3 * i], means.data[3 * i + 1], means.data[3 * i + 2]);
    vec3 p = vec3(dot(pc.world_to_camera[0].xyz, mean) + pc.world_to_camera[0].w,
                  dot(pc.world_to_camera[1].xyz, mean) + pc.world_to_camera[1].w,
                  dot(pc.world_to_camera[2].xyz, mean) + pc.world_to_camera[2].w);
    if (!(p.z > pc.near && p.z < pc.far)) {
        return NO_LABEL;
    }
    vec2 uv = vec2(pc.fx * p.x / p.z + pc.cx, pc.fy * p.y / p.z + pc.cy);
    if (!(uv.x >= 0.0 && uv.y >= 0.0 && uv.x < float(pc.width) && uv.y < float(pc.height))) {
        return NO_LABEL;
    }
    uint pix = uint(uv.y) * pc.width + uint(uv.x);
    if (pc.occlusion != 0) {
        float d = depth.data[pix];
        if (!(d > 0.0 && abs(p.z - d) <= pc.depth_tolerance * d)) {
            return NO_LABEL;
        }
#if defined(OPAQUE_DEPTH_TEST)
        // Hidden where the pixel turned opaque in front of it: within the tolerance of the
        // median depth, yet behind the surface the pixel shows (a wall a few centimetres
        // behind an object standing in front of it).
        float opaque = farthest_opaque_depth(uint(uv.x), uint(uv.y));
        if (opaque > 0.0 && p.z > opaque + pc.behind_tolerance * d) {
            return NO_LABEL;
        }
#endif
    }
    return pix;
}

#endif
