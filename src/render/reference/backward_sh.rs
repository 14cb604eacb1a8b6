//! Backward of the SH color `max(0, SH(dir) + 0.5)`, `dir = normalize(mean - camera
//! center)`: gradients of the coefficients and, through the direction, of the mean.

use glam::DVec3;

use super::{eval_sh, sh_basis, SH_C1, SH_C2, SH_C3};

/// The gradient `(d/dx, d/dy, d/dz)` of each of the 16 basis functions of
/// [`sh_basis`], taken as polynomials in `x, y, z` (the unit-norm constraint is applied
/// by the caller through the normalization's Jacobian).
pub fn sh_basis_grad(dir: DVec3) -> [DVec3; 16] {
    let (x, y, z) = (dir.x, dir.y, dir.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let v = DVec3::new;
    [
        v(0.0, 0.0, 0.0),
        // Band 1: -C1 y, C1 z, -C1 x.
        v(0.0, -SH_C1, 0.0),
        v(0.0, 0.0, SH_C1),
        v(-SH_C1, 0.0, 0.0),
        // Band 2: xy, yz, 2zz - xx - yy, xz, xx - yy.
        SH_C2[0] * v(y, x, 0.0),
        SH_C2[1] * v(0.0, z, y),
        SH_C2[2] * v(-2.0 * x, -2.0 * y, 4.0 * z),
        SH_C2[3] * v(z, 0.0, x),
        SH_C2[4] * v(2.0 * x, -2.0 * y, 0.0),
        // Band 3: y(3xx - yy), xyz, y(4zz - xx - yy), z(2zz - 3xx - 3yy),
        // x(4zz - xx - yy), z(xx - yy), x(xx - 3yy).
        SH_C3[0] * v(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0),
        SH_C3[1] * v(y * z, x * z, x * y),
        SH_C3[2] * v(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z),
        SH_C3[3] * v(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy),
        SH_C3[4] * v(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z),
        SH_C3[5] * v(2.0 * x * z, -2.0 * y * z, xx - yy),
        SH_C3[6] * v(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0),
    ]
}

/// Gradients of the SH color's inputs.
pub(super) struct ShGrads {
    /// `dL/dcoeffs`, `[coeff][rgb]`, as many coefficients as given (zero past the degree).
    pub coeffs: Vec<[f64; 3]>,
    /// `dL/dmean` through the view direction.
    pub mean: DVec3,
}

/// Backward of [`sh_color`](super::sh_color) given `dL/dcolor` (the clamped color).
pub(super) fn sh_color_backward(
    degree: u32,
    coeffs: &[[f64; 3]],
    mean: DVec3,
    cam_center: DVec3,
    grad_color: [f64; 3],
) -> ShGrads {
    let offset = mean - cam_center;
    let dir = offset.normalize_or_zero();
    let raw = eval_sh(degree, coeffs, dir);
    // max(0, raw + 0.5) passes the gradient only where it does not clamp.
    let grad_raw: [f64; 3] = std::array::from_fn(|ch| {
        if raw[ch] + 0.5 > 0.0 {
            grad_color[ch]
        } else {
            0.0
        }
    });

    let used = ((degree + 1) * (degree + 1)) as usize;
    let basis = sh_basis(dir);
    let basis_grad = sh_basis_grad(dir);
    let mut grad_coeffs = vec![[0.0; 3]; coeffs.len()];
    let mut grad_dir = DVec3::ZERO;
    for k in 0..used {
        for ch in 0..3 {
            grad_coeffs[k][ch] = basis[k] * grad_raw[ch];
            grad_dir += grad_raw[ch] * coeffs[k][ch] * basis_grad[k];
        }
    }

    // d(offset/|offset|)/d(offset) = (I - dir dir^T) / |offset|; a Gaussian at the camera
    // center has no direction (the forward uses dir = 0), so nothing flows back.
    let length = offset.length();
    let grad_mean = if dir == DVec3::ZERO {
        DVec3::ZERO
    } else {
        (grad_dir - dir * dir.dot(grad_dir)) / length
    };
    ShGrads {
        coeffs: grad_coeffs,
        mean: grad_mean,
    }
}
