// Projects every Gaussian into the camera (EWA splatting): 2D mean, dilated 2D covariance
// and its inverse (conic), opacity, view-dependent color from SH, and the tiles its
// opacity-aware screen extent covers. Writes a visibility flag per Gaussian (and a zero at
// index n) for the compaction scan. Included by project.comp (float32) and
// project_f64.comp (PROJECT_F64: the camera-space and 2D means in float64).
//
// The 2D mean is stored as its integer part (exact in float32) and its fraction, so that
// pixel offsets d = (int - px) + (frac - 0.5) keep full precision at any image size.
#extension GL_EXT_control_flow_attributes : require
#include "raster_common.glsl"
#include "projection.glsl"

layout(local_size_x = 256) in;

#include "project_params.glsl"

layout(set = 0, binding = 0) readonly buffer MeansBuf { float data[]; } means;
layout(set = 0, binding = 1) readonly buffer LogScalesBuf { float data[]; } log_scales;
layout(set = 0, binding = 2) readonly buffer QuatsBuf { float data[]; } quats;
layout(set = 0, binding = 3) readonly buffer OpacityBuf { float data[]; } opacity_logits;
layout(set = 0, binding = 4) readonly buffer ShBuf { float data[]; } sh;
layout(set = 0, binding = 5) writeonly buffer XyBuf { vec4 data[]; } xy_depth_opacity; // floor(mean2d) depth opacity
layout(set = 0, binding = 6) writeonly buffer ConicBuf { vec4 data[]; } conics;  // A B C -
layout(set = 0, binding = 7) writeonly buffer ColorBuf { vec4 data[]; } colors;  // r g b -
layout(set = 0, binding = 8) writeonly buffer RectBuf { uvec4 data[]; } tile_rects; // x0 y0 x1 y1 (end-exclusive)
layout(set = 0, binding = 9) writeonly buffer FlagsBuf { uint data[]; } visible;    // n + 1 entries
layout(set = 0, binding = 11) writeonly buffer FracBuf { vec2 data[]; } xy_frac;
#ifdef PROJECT_F64
// World-to-camera rows (R00 R01 R02 t0, ...), then fx fy cx cy, in float64.
layout(set = 0, binding = 12) readonly buffer Camera64Buf { double data[]; } camera64;
#endif

#define SH_COEFF(k) vec3(sh.data[base + 3 * (k)], sh.data[base + 3 * (k) + 1], sh.data[base + 3 * (k) + 2])

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint n = pc.n;
    if (i > n) {
        return;
    }
    if (i == n) {
        visible.data[n] = 0;
        return;
    }
    visible.data[i] = 0;

    vec3 mean = vec3(means.data[3 * i], means.data[3 * i + 1], means.data[3 * i + 2]);
#ifdef PROJECT_F64
    dvec3 md = dvec3(mean);
    dvec3 pd = dvec3(camera64.data[0] * md.x + camera64.data[1] * md.y + camera64.data[2] * md.z + camera64.data[3],
                     camera64.data[4] * md.x + camera64.data[5] * md.y + camera64.data[6] * md.z + camera64.data[7],
                     camera64.data[8] * md.x + camera64.data[9] * md.y + camera64.data[10] * md.z + camera64.data[11]);
    vec3 p = vec3(pd);
#else
    vec3 p = vec3(dot(pc.world_to_camera[0].xyz, mean) + pc.world_to_camera[0].w,
                  dot(pc.world_to_camera[1].xyz, mean) + pc.world_to_camera[1].w,
                  dot(pc.world_to_camera[2].xyz, mean) + pc.world_to_camera[2].w);
#endif
    if (!(p.z > pc.near && p.z < pc.far)) {
        return;
    }
    vec4 q_raw = vec4(quats.data[4 * i], quats.data[4 * i + 1], quats.data[4 * i + 2], quats.data[4 * i + 3]);
    float qn;
    vec4 q = quat_normalized(q_raw, qn);
    if (!(qn > 0.0)) {
        return;
    }
    float opacity = sigmoid(opacity_logits.data[i]);
    if (!(opacity >= ALPHA_MIN)) {
        return;
    }

    // 3D covariance R S S^T R^T, into camera space, then onto the image.
    mat3 rq = quat_to_mat(q);
    vec3 s = exp(vec3(log_scales.data[3 * i], log_scales.data[3 * i + 1], log_scales.data[3 * i + 2]));
    mat3 w = transpose(mat3(pc.world_to_camera[0].xyz, pc.world_to_camera[1].xyz, pc.world_to_camera[2].xyz)); // rows -> matrix
    float width = float(pc.width), height = float(pc.height);
    vec4 cov_det = persp_proj_cov_det(p, w * rot_scale(rq, s), pc.intrinsics, vec2(width, height));
    vec3 cov2 = dilate_cov2(cov_det.xyz);
    vec3 conic = dilated_conic(cov_det);
    // A covariance float32 cannot hold (scales of e^40) has no footprint to draw: culled,
    // as the CPU reference culls it, rather than blended with a NaN exponent.
    if (!(all_finite(cov2) && all_finite(conic))) {
        return;
    }

#ifdef PROJECT_F64
    dvec2 m2 = dvec2(camera64.data[12] * pd.x / pd.z + camera64.data[14], camera64.data[13] * pd.y / pd.z + camera64.data[15]);
    dvec2 m2_floor = floor(m2);
    vec2 mean_int = vec2(m2_floor);
    vec2 mean_frac = vec2(m2 - m2_floor);
#else
    vec2 mean2d = persp_proj_mean(p, pc.intrinsics);
    vec2 mean_int = floor(mean2d);
    vec2 mean_frac = mean2d - mean_int;
#endif
    // Opacity-aware extent: alpha >= 1/255 needs d^T cov^-1 d <= 2 ln(255 opacity).
    float r = sqrt(2.0 * log(255.0 * opacity));
    vec2 extent = r * sqrt(cov2.xz);
    vec2 lo = max(mean_int + ceil(mean_frac - extent - 0.5), vec2(0.0));
    vec2 hi = min(mean_int + floor(mean_frac + extent - 0.5), vec2(width - 1.0, height - 1.0));
    if (!(lo.x <= hi.x && lo.y <= hi.y)) {
        return;
    }
    uvec2 tlo = uvec2(lo) / TILE_SIZE;
    uvec2 thi = uvec2(hi) / TILE_SIZE + 1;

    // A scene uploaded without colour (the fusion methods never read it) has no SH.
    vec3 color = vec3(0.0);
    if (pc.sh_coeffs > 0) {
        vec3 dir = normalize(mean - pc.camera_center);
        uint base = i * pc.sh_coeffs * 3;
        SH_EVAL(color, pc.sh_degree, dir, SH_COEFF);
        color = max(color + 0.5, vec3(0.0));
    }

    xy_depth_opacity.data[i] = vec4(mean_int, p.z, opacity);
    xy_frac.data[i] = mean_frac;
    conics.data[i] = vec4(conic, 0.0);
    colors.data[i] = vec4(color, 0.0);
    tile_rects.data[i] = uvec4(tlo, thi);
    visible.data[i] = 1;
}
