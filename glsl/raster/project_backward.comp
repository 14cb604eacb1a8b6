#version 460
// Backward of projection (project_body.glsl) for one view: from each visible Gaussian's
// screen-space gradient (grad2d: mean2d, conic, opacity, color) to its stored parameters
// (means, log-scales, quaternion, opacity logit, SH), added into the gradient buffers,
// which hold one value per parameter and sum over the views of an iteration. Also adds
// the densification statistic: the norm of the 2D-mean gradient in NDC units (3DGS), and
// counts the view. Recomputes the forward's intermediates in float32.
#extension GL_EXT_control_flow_attributes : require
#include "raster_common.glsl"
#include "projection.glsl"

#define GRAD2D_STRIDE 10

layout(local_size_x = 256) in;

#include "project_params.glsl"

layout(set = 0, binding = 0) readonly buffer MeansBuf { float data[]; } means;
layout(set = 0, binding = 1) readonly buffer LogScalesBuf { float data[]; } log_scales;
layout(set = 0, binding = 2) readonly buffer QuatsBuf { float data[]; } quats;
layout(set = 0, binding = 3) readonly buffer OpacityBuf { float data[]; } opacity_logits;
layout(set = 0, binding = 4) readonly buffer ShBuf { float data[]; } sh;
layout(set = 0, binding = 5) readonly buffer FlagsBuf { uint data[]; } visible;
layout(set = 0, binding = 6) readonly buffer Grad2dBuf { float data[]; } grad2d;
layout(set = 0, binding = 7) buffer GMeansBuf { float data[]; } grad_means;
layout(set = 0, binding = 8) buffer GLogScalesBuf { float data[]; } grad_log_scales;
layout(set = 0, binding = 9) buffer GQuatsBuf { float data[]; } grad_quats;
layout(set = 0, binding = 10) buffer GOpacityBuf { float data[]; } grad_opacity_logits;
layout(set = 0, binding = 11) buffer GShBuf { float data[]; } grad_sh;
layout(set = 0, binding = 12) buffer DensifyGradBuf { float data[]; } densify_grad;
layout(set = 0, binding = 13) buffer DensifyCountBuf { float data[]; } densify_count;
// Fixed-point status of this view's blend backward (grad_fixed_common.glsl; zeros with
// float atomics): after an overflow the view is redone, so it must add nothing here (the
// densification statistics are not cleared between iterations).
layout(set = 0, binding = 14) readonly buffer FixedStatusBuf { uint data[]; } fixed_status;
// Status words of this view's binning (ST_*): lists that overflowed are grown and the view
// recorded again, so this attempt must add nothing either.
layout(set = 0, binding = 15) readonly buffer RasterStatusBuf { uint data[]; } raster_status;

#define SH_COEFF(k) vec3(sh.data[base + 3 * (k)], sh.data[base + 3 * (k) + 1], sh.data[base + 3 * (k) + 2])

// Gradient of sum_k basis_k(dir) * g_k with respect to dir (the SH basis of SH_EVAL).
vec3 sh_basis_grad(uint degree, vec3 dir, float g[16]) {
    vec3 r = vec3(0.0);
    if (degree < 1) {
        return r;
    }
    float x = dir.x, y = dir.y, z = dir.z;
    r += SH_C1 * vec3(-g[3], -g[1], g[2]);
    if (degree < 2) {
        return r;
    }
    const float k4 = 1.0925484305920792, k6 = 0.31539156525252005, k8 = 0.5462742152960396;
    r += k4 * g[4] * vec3(y, x, 0.0);
    r -= k4 * g[5] * vec3(0.0, z, y);
    r += k6 * g[6] * vec3(-2.0 * x, -2.0 * y, 4.0 * z);
    r -= k4 * g[7] * vec3(z, 0.0, x);
    r += k8 * g[8] * vec3(2.0 * x, -2.0 * y, 0.0);
    if (degree < 3) {
        return r;
    }
    float xx = x * x, yy = y * y, zz = z * z;
    const float k9 = -0.5900435899266435, k10 = 2.890611442640554, k11 = -0.4570457994644658;
    const float k12 = 0.3731763325901154, k14 = 1.445305721320277;
    r += k9 * g[9] * vec3(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
    r += k10 * g[10] * vec3(y * z, x * z, x * y);
    r += k11 * g[11] * vec3(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
    r += k12 * g[12] * vec3(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
    r += k11 * g[13] * vec3(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
    r += k14 * g[14] * vec3(2.0 * x * z, -2.0 * y * z, xx - yy);
    r += k9 * g[15] * vec3(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
    return r;
}

// The SH basis values of SH_EVAL, read back by evaluating it with unit coefficients.
#define UNIT_COEFF(k) vec3((k) == unit_k ? 1.0 : 0.0)

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint n = pc.n;
    bool redone = fixed_status.data[FS_OVERFLOW] != 0 || raster_status.data[ST_OVERFLOW] != 0
        || raster_status.data[ST_ISECT_WRAPPED] != 0;
    if (i >= n || visible.data[i] == 0 || redone) {
        return;
    }
    uint g0 = i * GRAD2D_STRIDE;
    vec2 v_mean2d = vec2(grad2d.data[g0], grad2d.data[g0 + 1]);
    vec3 v_conic = vec3(grad2d.data[g0 + 2], grad2d.data[g0 + 3], grad2d.data[g0 + 4]);
    float v_opacity = grad2d.data[g0 + 5];
    vec3 v_color = vec3(grad2d.data[g0 + 6], grad2d.data[g0 + 7], grad2d.data[g0 + 8]);

    // Forward intermediates.
    vec3 mean = vec3(means.data[3 * i], means.data[3 * i + 1], means.data[3 * i + 2]);
    mat3 w = transpose(mat3(pc.world_to_camera[0].xyz, pc.world_to_camera[1].xyz, pc.world_to_camera[2].xyz)); // world -> camera
    vec3 p = w * mean + vec3(pc.world_to_camera[0].w, pc.world_to_camera[1].w, pc.world_to_camera[2].w);
    vec4 q_raw = vec4(quats.data[4 * i], quats.data[4 * i + 1], quats.data[4 * i + 2], quats.data[4 * i + 3]);
    float qn;
    vec4 q = quat_normalized(q_raw, qn);
    mat3 rq = quat_to_mat(q);
    vec3 s = exp(vec3(log_scales.data[3 * i], log_scales.data[3 * i + 1], log_scales.data[3 * i + 2]));
    mat3 covc = covar_world_to_cam(w, rot_scale_to_covar(rq, s));
    float width = float(pc.width), height = float(pc.height);
    vec3 conic = dilated_conic(persp_proj_cov_det(p, w * rot_scale(rq, s), pc.intrinsics, vec2(width, height)));

    // Back along the chain; the dilation passes the gradient through unchanged.
    mat2 v_cov2 = cov2_to_conic_vjp(conic, v_conic);
    mat3 v_covc;
    vec3 v_p = persp_proj_vjp(p, covc, pc.intrinsics, vec2(width, height), v_mean2d, v_cov2, v_covc);
    vec3 v_mean = transpose(w) * v_p;
    mat3 v_r;
    vec3 v_s;
    rot_scale_to_covar_vjp(rq, s, covar_world_to_cam_vjp(w, v_covc), v_r, v_s);
    vec3 v_log_scale = v_s * s;
    vec4 v_q_raw = quat_normalize_vjp(q, qn, quat_to_mat_vjp(q, v_r));

    // Color = max(SH(dir) + 0.5, 0), dir = normalize(mean - camera center).
    uint degree = pc.sh_degree, coeffs = pc.sh_coeffs;
    uint base = i * coeffs * 3;
    vec3 to_mean = mean - pc.camera_center;
    vec3 dir = normalize(to_mean);
    vec3 color;
    SH_EVAL(color, degree, dir, SH_COEFF);
    v_color *= vec3(greaterThan(color + 0.5, vec3(0.0)));
    float g_basis[16];
    for (uint k = 0; k < 16; k++) {
        g_basis[k] = 0.0;
    }
    for (uint k = 0; k < coeffs; k++) {
        uint unit_k = k;
        vec3 basis;
        SH_EVAL(basis, degree, dir, UNIT_COEFF);
        vec3 v_coeff = basis * v_color;
        grad_sh.data[base + 3 * k] += v_coeff.x;
        grad_sh.data[base + 3 * k + 1] += v_coeff.y;
        grad_sh.data[base + 3 * k + 2] += v_coeff.z;
        g_basis[k] = dot(SH_COEFF(k), v_color);
    }
    vec3 v_dir = sh_basis_grad(degree, dir, g_basis);
    v_mean += (v_dir - dir * dot(dir, v_dir)) / length(to_mean);

    float opacity = sigmoid(opacity_logits.data[i]);
    grad_opacity_logits.data[i] += v_opacity * opacity * (1.0 - opacity);
    [[unroll]] for (uint k = 0; k < 3; k++) {
        grad_means.data[3 * i + k] += v_mean[k];
        grad_log_scales.data[3 * i + k] += v_log_scale[k];
    }
    [[unroll]] for (uint k = 0; k < 4; k++) {
        grad_quats.data[4 * i + k] += v_q_raw[k];
    }
    densify_grad.data[i] += length(v_mean2d * vec2(0.5 * width, 0.5 * height));
    densify_count.data[i] += 1.0;
}
