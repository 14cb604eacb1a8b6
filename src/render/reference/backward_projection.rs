//! Backward of the projection: from one Gaussian's screen-space gradients (mean2d, conic,
//! opacity, color) to its stored parameters (mean, log-scale, raw quaternion, opacity
//! logit, SH coefficients).
//!
//! Forward chain (see `project.rs`): `p = Rc m + t`; `Rq = rot(q / |q|)`, `S = diag(exp(l))`,
//! `M = Rq S`, `Sigma = M M^T`, `Sigma_c = Rc Sigma Rc^T`; `cov2d = J Sigma_c J^T + 0.3 I`
//! with gsplat's clamped Jacobian `J(p)`; `conic = inverse(cov2d)` with the determinant
//! clamped at 1e-10; `mean2d = (fx x/z + cx, fy y/z + cy)`; `opacity = sigmoid(logit)`.

use glam::{DMat3, DVec3};

use super::backward_blend::ScreenGrads;
use super::backward_params::GaussianParams;
use super::backward_project::{effective_sh_degree, sigmoid};
use super::backward_sh::sh_color_backward;
use super::project::clamped_ratios;
use super::{projection_jacobian, quat_to_rotation, ProjectedGaussian, RenderSettings, DET_MIN};
use crate::scene::Camera;

/// `dL/d` of one Gaussian's stored parameters.
pub(super) struct StoredGrads {
    pub mean: [f64; 3],
    pub log_scale: [f64; 3],
    pub quat: [f64; 4],
    pub opacity_logit: f64,
    /// `[coeff][rgb]`, all stored coefficients (zero past the evaluated degree).
    pub sh: Vec<[f64; 3]>,
}

/// A 3x3 matrix from its rows.
fn from_rows(rows: [[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols_array_2d(&rows).transpose()
}

/// Entry (row, column).
fn at(m: DMat3, row: usize, col: usize) -> f64 {
    m.col(col)[row]
}

/// `dL/d(a, b, c)` of the dilated 2D covariance `[[a, b], [b, c]]` from `dL/dconic`, where
/// `conic = (c, -b, a) / det`, `det = max(ac - b^2, 1e-10)`.
fn conic_backward(cov2d: [f64; 3], grad_conic: [f64; 3]) -> [f64; 3] {
    let [a, b, c] = cov2d;
    let [ga, gb, gc] = grad_conic;
    let det_raw = a * c - b * b;
    let det = det_raw.max(DET_MIN);
    // Each conic entry is numerator / det, so d(entry)/d(det) = -entry / det.
    let conic = [c / det, -b / det, a / det];
    let grad_det = if det_raw > DET_MIN {
        -(ga * conic[0] + gb * conic[1] + gc * conic[2]) / det
    } else {
        // The clamp holds det constant. (It cannot bind for a PSD covariance: the 0.3
        // dilation alone keeps det >= 0.09.)
        0.0
    };
    [
        gc / det + grad_det * c,
        -gb / det - grad_det * 2.0 * b,
        ga / det + grad_det * a,
    ]
}

/// `dL/dq` of the raw quaternion from `dL/dRq`, through `q / |q|` and the rotation formula
/// of [`quat_to_rotation`].
fn quat_backward(q: [f64; 4], grad_rot: DMat3) -> [f64; 4] {
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = q.map(|v| v / norm);
    let g = |r, c| at(grad_rot, r, c);
    let grad_unit = [
        2.0 * (-z * g(0, 1) + y * g(0, 2) + z * g(1, 0) - x * g(1, 2) - y * g(2, 0) + x * g(2, 1)),
        2.0 * (y * g(0, 1) + z * g(0, 2) + y * g(1, 0) - 2.0 * x * g(1, 1) - w * g(1, 2)
            + z * g(2, 0)
            + w * g(2, 1)
            - 2.0 * x * g(2, 2)),
        2.0 * (-2.0 * y * g(0, 0) + x * g(0, 1) + w * g(0, 2) + x * g(1, 0) + z * g(1, 2)
            - w * g(2, 0)
            + z * g(2, 1)
            - 2.0 * y * g(2, 2)),
        2.0 * (-2.0 * z * g(0, 0) - w * g(0, 1) + x * g(0, 2) + w * g(1, 0) - 2.0 * z * g(1, 1)
            + y * g(1, 2)
            + x * g(2, 0)
            + y * g(2, 1)),
    ];
    // d(q/|q|)/dq = (I - u u^T) / |q| with u = q/|q|.
    let unit = [w, x, y, z];
    let along: f64 = unit.iter().zip(&grad_unit).map(|(u, g)| u * g).sum();
    std::array::from_fn(|k| (grad_unit[k] - unit[k] * along) / norm)
}

/// `dL/dp` (camera-space mean) through the Jacobian's dependence on `p`, given `dL/dJ`.
fn jacobian_backward(p: DVec3, cam: &Camera, grad_j: [[f64; 3]; 2]) -> DVec3 {
    let z = p.z;
    let z2 = z * z;
    // Row r of J is f/z at column r and -f ratio/z at column 2, `ratio` the clamped x/z
    // (or y/z): dJ/d(x or y) and dJ/dz, with `ratio` constant once clamped.
    let row = |r: usize, f: f64, along: f64| {
        let (ratio, clamped) = clamped_ratios(p, cam)[r];
        let (d_ratio_d_along, d_ratio_dz) = if clamped {
            (0.0, 0.0)
        } else {
            (1.0 / z, -along / z2)
        };
        let d_diag_dz = -f / z2;
        let d_last_d_along = -f * d_ratio_d_along / z;
        let d_last_dz = -f * (d_ratio_dz / z - ratio / z2);
        let grad = grad_j[r];
        (
            grad[2] * d_last_d_along,
            grad[r] * d_diag_dz + grad[2] * d_last_dz,
        )
    };
    let (gx, gz_from_x) = row(0, cam.fx, p.x);
    let (gy, gz_from_y) = row(1, cam.fy, p.y);
    DVec3::new(gx, gy, gz_from_x + gz_from_y)
}

/// Backward of the projection of Gaussian `p.id` given its screen-space gradients.
pub(super) fn projection_backward(
    params: &GaussianParams,
    p: &ProjectedGaussian,
    cam: &Camera,
    settings: &RenderSettings,
    grads: &ScreenGrads,
) -> StoredGrads {
    let i = p.id as usize;
    let q = params.quats[i];
    let scale = DVec3::from(params.log_scales[i].map(f64::exp));
    let rot_q = quat_to_rotation(q).expect("visible Gaussians have a nonzero quaternion");
    let rot_c = cam.rotation;
    let m = rot_q * DMat3::from_diagonal(scale);
    let cov_cam = rot_c * (m * m.transpose()) * rot_c.transpose();
    let pc = p.mean_cam;

    // conic -> dilated 2D covariance (the +0.3 is constant) -> J Sigma_c J^T.
    let [ga, gb, gc] = conic_backward(p.cov2d, grads.conic);
    // The 2x3 Jacobian and the 2x2 gradient padded with a zero row/column, so glam's 3x3
    // products apply. xy appears twice in the symmetric matrix, hence gb / 2.
    let jac = projection_jacobian(pc, cam);
    let j3 = from_rows([jac[0], jac[1], [0.0; 3]]);
    let g2 = from_rows([[ga, 0.5 * gb, 0.0], [0.5 * gb, gc, 0.0], [0.0; 3]]);
    let grad_cov_cam = j3.transpose() * g2 * j3;
    let grad_j3 = 2.0 * g2 * j3 * cov_cam;
    let grad_j = [0, 1].map(|r| [0, 1, 2].map(|c| at(grad_j3, r, c)));

    // Sigma_c = Rc Sigma Rc^T; Sigma = M M^T with M = Rq S.
    let grad_cov = rot_c.transpose() * grad_cov_cam * rot_c;
    let grad_m = 2.0 * grad_cov * m;
    let grad_rot_q = grad_m * DMat3::from_diagonal(scale);
    let grad_s = rot_q.transpose() * grad_m;
    let log_scale = [0, 1, 2].map(|k| at(grad_s, k, k) * scale[k]);
    let quat = quat_backward(q, grad_rot_q);

    // Camera-space mean: through mean2d and through J.
    let [gu, gv] = grads.mean2d;
    let (fx, fy, z) = (cam.fx, cam.fy, pc.z);
    let grad_pc = DVec3::new(
        gu * fx / z,
        gv * fy / z,
        -gu * fx * pc.x / (z * z) - gv * fy * pc.y / (z * z),
    ) + jacobian_backward(pc, cam, grad_j);

    let degree = effective_sh_degree(params, settings);
    let mean = DVec3::from(params.means[i]);
    let sh = sh_color_backward(degree, &params.sh_of(i), mean, cam.center(), grads.color);
    let grad_mean = rot_c.transpose() * grad_pc + sh.mean;

    let opacity = sigmoid(params.opacity_logits[i]);
    StoredGrads {
        mean: grad_mean.to_array(),
        log_scale,
        quat,
        opacity_logit: grads.opacity * opacity * (1.0 - opacity),
        sh: sh.coeffs,
    }
}
