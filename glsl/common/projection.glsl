// One Gaussian's 3D -> 2D projection (EWA splatting, classic 3DGS as gsplat does it), each
// forward step next to its vector-Jacobian product, so that project_body.glsl and
// project_backward.comp differentiate exactly the math the forward runs. The constants
// match src/render/reference/project.rs.
//
// Chain: q -> R (unit quaternion); M = R diag(s), cov3 = M M^T; covc = W cov3 W^T (world
// to camera); cov2 = J covc J^T with the clamped perspective Jacobian J(p); dilation;
// conic = cov2^-1. The forward computes cov2 as (J W M)(J W M)^T and its determinant from
// J W M's minors (persp_proj_cov_det); the backward differentiates the same function of
// covc. The 2D mean is (fx x/z + cx, fy y/z + cy).
//
// A symmetric 2x2 matrix travels as vec3 (xx, xy, yy), the layout of the conic buffer; its
// gradient as the full mat2 (see conic_vjp).
#ifndef PROJECTION_GLSL
#define PROJECTION_GLSL

// Added to both diagonal entries of every 2D covariance (a variance in px^2): no Gaussian
// is thinner than about a pixel, which keeps the conic bounded.
#define COV2D_DILATION 0.3
// Lower clamp of the dilated 2D covariance's determinant, so the conic stays finite.
#define DET_MIN 1e-10
// Inside the Jacobian only, x/z and y/z are clamped to the view frustum widened on each
// side by this fraction of tan(fov/2): Gaussians far outside the image would otherwise
// get a huge, meaningless footprint.
#define FRUSTUM_MARGIN 0.3

// Rotation matrix of a unit quaternion (w, x, y, z); GLSL matrices are column-major.
mat3 quat_to_mat(vec4 q) {
    float w = q.x, x = q.y, y = q.z, z = q.w;
    return mat3(
        1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y),
        2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x),
        2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y));
}

// dL/dq of quat_to_mat for the unit quaternion q, from v_r = dL/dR.
vec4 quat_to_mat_vjp(vec4 q, mat3 v_r) {
    float qw = q.x, qx = q.y, qy = q.z, qz = q.w;
    // r(row, col) = v_r[col][row].
#define R(row, col) v_r[col][row]
    vec4 v_q = 2.0 * vec4(
        qz * (R(1, 0) - R(0, 1)) + qy * (R(0, 2) - R(2, 0)) + qx * (R(2, 1) - R(1, 2)),
        qy * (R(1, 0) + R(0, 1)) + qz * (R(2, 0) + R(0, 2)) + qw * (R(2, 1) - R(1, 2)) - 2.0 * qx * (R(1, 1) + R(2, 2)),
        qx * (R(1, 0) + R(0, 1)) + qw * (R(0, 2) - R(2, 0)) + qz * (R(2, 1) + R(1, 2)) - 2.0 * qy * (R(0, 0) + R(2, 2)),
        qw * (R(1, 0) - R(0, 1)) + qx * (R(2, 0) + R(0, 2)) + qy * (R(2, 1) + R(1, 2)) - 2.0 * qz * (R(0, 0) + R(1, 1)));
#undef R
    return v_q;
}

// The unit quaternion of q_raw, and qn = |q_raw| (0: no rotation, the Gaussian is culled).
// Scaled by its largest component first: length() of components of 1e20 overflows float32
// and of 1e-30 underflows, which turned the first into the identity and culled the second.
vec4 quat_normalized(vec4 q_raw, out float qn) {
    vec4 mag = abs(q_raw);
    float largest = max(max(mag.x, mag.y), max(mag.z, mag.w));
    if (!(largest > 0.0)) {
        qn = 0.0;
        return vec4(1.0, 0.0, 0.0, 0.0);
    }
    vec4 q = q_raw / largest;
    float scaled = length(q);
    qn = largest * scaled;
    return q / scaled;
}

// dL/dq_raw of q = q_raw / qn (qn = |q_raw|), from v_q = dL/dq.
vec4 quat_normalize_vjp(vec4 q, float qn, vec4 v_q) {
    return (v_q - q * dot(q, v_q)) / qn;
}

// M = R diag(s): the 3D covariance is M M^T.
mat3 rot_scale(mat3 r, vec3 s) {
    return r * mat3(s.x, 0, 0, 0, s.y, 0, 0, 0, s.z);
}

// 3D covariance R diag(s)^2 R^T of rotation r and scales s.
mat3 rot_scale_to_covar(mat3 r, vec3 s) {
    mat3 m = rot_scale(r, s);
    return m * transpose(m);
}

// From v_cov3 = dL/dcov3 to v_r = dL/dR and v_s = dL/ds.
void rot_scale_to_covar_vjp(mat3 r, vec3 s, mat3 v_cov3, out mat3 v_r, out vec3 v_s) {
    mat3 v_m = 2.0 * (v_cov3 * rot_scale(r, s));
    v_s = vec3(dot(v_m[0], r[0]), dot(v_m[1], r[1]), dot(v_m[2], r[2]));
    v_r = mat3(v_m[0] * s.x, v_m[1] * s.y, v_m[2] * s.z);
}

// Covariance in camera space, w the world-to-camera rotation.
mat3 covar_world_to_cam(mat3 w, mat3 cov3) {
    return w * cov3 * transpose(w);
}

mat3 covar_world_to_cam_vjp(mat3 w, mat3 v_covc) {
    return transpose(w) * v_covc * w;
}

// Camera-space point p = (x, y, z) to pixel coordinates (fx x/z + cx, fy y/z + cy);
// intrinsics = (fx, fy, cx, cy).
vec2 persp_proj_mean(vec3 p, vec4 intrinsics) {
    float rz = 1.0 / p.z;
    return vec2(intrinsics.x * p.x * rz + intrinsics.z, intrinsics.y * p.y * rz + intrinsics.w);
}

// z * (x/z, y/z) with x/z, y/z clamped to the widened frustum (FRUSTUM_MARGIN) of an image
// of `size` pixels; `clamped` says which of the two the clamp moved.
vec2 frustum_clamped_xy(vec3 p, vec4 intrinsics, vec2 size, out bvec2 clamped) {
    float fx = intrinsics.x, fy = intrinsics.y, cx = intrinsics.z, cy = intrinsics.w;
    float tan_x = 0.5 * size.x / fx, tan_y = 0.5 * size.y / fy;
    float lim_xp = (size.x - cx) / fx + FRUSTUM_MARGIN * tan_x, lim_xn = cx / fx + FRUSTUM_MARGIN * tan_x;
    float lim_yp = (size.y - cy) / fy + FRUSTUM_MARGIN * tan_y, lim_yn = cy / fy + FRUSTUM_MARGIN * tan_y;
    float rz = 1.0 / p.z;
    float ux = p.x * rz, uy = p.y * rz;
    clamped = bvec2(ux > lim_xp || ux < -lim_xn, uy > lim_yp || uy < -lim_yn);
    return vec2(p.z * min(lim_xp, max(-lim_xn, ux)), p.z * min(lim_yp, max(-lim_yn, uy)));
}

// The perspective Jacobian J (2x3) at p with the clamped txy = frustum_clamped_xy(p),
// as mat3x2: column k holds d(u, v)/d p_k.
mat3x2 persp_jacobian(vec3 p, vec4 intrinsics, vec2 txy) {
    float fx = intrinsics.x, fy = intrinsics.y;
    float rz = 1.0 / p.z;
    return mat3x2(fx * rz, 0.0, 0.0, fy * rz, -fx * txy.x * rz * rz, -fy * txy.y * rz * rz);
}

// 2D covariance J covc J^T of a Gaussian at camera-space p in an image of `size` pixels,
// before dilation, as (xx, xy, yy), and its determinant (w). The camera-space covariance
// comes as its factor wm = W R diag(s) (covc = wm wm^T), so that cov2 = T T^T with the 2x3
// T = J wm, and the determinant is the sum of T's squared 2x2 minors (Cauchy-Binet):
// xx yy - xy^2 cancels to nothing in float32 for a needle (50 m by 1 cm: a determinant 2
// ulp of xx yy), whose conic then blew up and whose pixels vanished. Never forming covc
// also keeps cov2 finite wherever T is.
vec4 persp_proj_cov_det(vec3 p, mat3 wm, vec4 intrinsics, vec2 size) {
    bvec2 clamped;
    mat3x2 t = persp_jacobian(p, intrinsics, frustum_clamped_xy(p, intrinsics, size, clamped)) * wm;
    // The rows of T.
    vec3 t0 = vec3(t[0][0], t[1][0], t[2][0]);
    vec3 t1 = vec3(t[0][1], t[1][1], t[2][1]);
    vec3 minors = cross(t0, t1);
    return vec4(dot(t0, t0), dot(t0, t1), dot(t1, t1), dot(minors, minors));
}

// From dL/dmean2d and v_cov2 = dL/dcov2 to dL/dp, through the 2D mean and through J, and to
// v_covc = dL/dcovc. Where x/z is clamped, J's tx = z * limit passes gradient to z only,
// none to x (the same for y).
vec3 persp_proj_vjp(vec3 p, mat3 covc, vec4 intrinsics, vec2 size, vec2 v_mean2d, mat2 v_cov2,
                    out mat3 v_covc) {
    float fx = intrinsics.x, fy = intrinsics.y;
    bvec2 clamped;
    vec2 txy = frustum_clamped_xy(p, intrinsics, size, clamped);
    float tx = txy.x, ty = txy.y;
    mat3x2 jac = persp_jacobian(p, intrinsics, txy);
    v_covc = transpose(jac) * v_cov2 * jac;
    mat3x2 v_jac = 2.0 * (v_cov2 * jac * covc);

    float rz = 1.0 / p.z;
    vec3 v_p = vec3(fx * rz * v_mean2d.x, fy * rz * v_mean2d.y,
                    -(fx * p.x * v_mean2d.x + fy * p.y * v_mean2d.y) * rz * rz);
    float rz2 = rz * rz, rz3 = rz2 * rz;
    v_p.z += -fx * rz2 * v_jac[0][0] - fy * rz2 * v_jac[1][1];
    if (clamped.x) {
        v_p.z += fx * tx * rz3 * v_jac[2][0];
    } else {
        v_p.x += -fx * rz2 * v_jac[2][0];
        v_p.z += 2.0 * fx * tx * rz3 * v_jac[2][0];
    }
    if (clamped.y) {
        v_p.z += fy * ty * rz3 * v_jac[2][1];
    } else {
        v_p.y += -fy * rz2 * v_jac[2][1];
        v_p.z += 2.0 * fy * ty * rz3 * v_jac[2][1];
    }
    return v_p;
}

// The dilated 2D covariance cov2 + COV2D_DILATION I. Its gradient passes through unchanged.
vec3 dilate_cov2(vec3 cov2) {
    return vec3(cov2.x + COV2D_DILATION, cov2.y, cov2.z + COV2D_DILATION);
}

// The conic: inverse of the dilated cov2 = dilate_cov2(cov.xyz), from the undilated
// covariance and its determinant cov.w (persp_proj_cov_det): det(cov + d I) = det(cov) +
// d tr(cov) + d^2, clamped at DET_MIN.
vec3 dilated_conic(vec4 cov) {
    vec3 cov2 = dilate_cov2(cov.xyz);
    const float d = COV2D_DILATION;
    float det = max(cov.w + d * (cov.x + cov.z) + d * d, DET_MIN);
    return vec3(cov2.z / det, -cov2.y / det, cov2.x / det);
}

// Whether every component is a finite float (NaN compares false).
bool all_finite(vec3 v) {
    return all(lessThanEqual(abs(v), vec3(3.4028235e38)));
}

// conic = cov2^-1: dL/dcov2 = -conic G conic, G the symmetric gradient of the conic built
// from v_conic = dL/d(A, B, C) (B appears twice in the matrix, so each off-diagonal entry
// gets half of dL/dB).
mat2 cov2_to_conic_vjp(vec3 conic, vec3 v_conic) {
    mat2 con = mat2(conic.x, conic.y, conic.y, conic.z);
    mat2 g_conic = mat2(v_conic.x, 0.5 * v_conic.y, 0.5 * v_conic.y, v_conic.z);
    return -(con * g_conic * con);
}

#endif
