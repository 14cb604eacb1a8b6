//! Spherical harmonics: view-dependent color, degree 0..=3, in the standard 3DGS basis
//! (INRIA `eval_sh` / gsplat `sh_coeffs_to_color`): real SH with the Condon-Shortley phase,
//! coefficient `k = l*l + l + m` for band `l`, order `m` in `-l..=l`.

use glam::DVec3;

/// Band 0.
pub const SH_C0: f64 = 0.282_094_791_773_878_14;
/// Band 1.
pub const SH_C1: f64 = 0.488_602_511_902_919_9;
/// Band 2, orders m = -2..=2.
pub const SH_C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
/// Band 3, orders m = -3..=3.
pub const SH_C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// The 16 basis functions (degree 3) at a unit direction; entries past the degree's
/// `(degree + 1)^2` are simply not used by [`eval_sh`].
pub fn sh_basis(dir: DVec3) -> [f64; 16] {
    let (x, y, z) = (dir.x, dir.y, dir.z);
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    [
        SH_C0,
        -SH_C1 * y,
        SH_C1 * z,
        -SH_C1 * x,
        SH_C2[0] * xy,
        SH_C2[1] * yz,
        SH_C2[2] * (2.0 * zz - xx - yy),
        SH_C2[3] * xz,
        SH_C2[4] * (xx - yy),
        SH_C3[0] * y * (3.0 * xx - yy),
        SH_C3[1] * xy * z,
        SH_C3[2] * y * (4.0 * zz - xx - yy),
        SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        SH_C3[4] * x * (4.0 * zz - xx - yy),
        SH_C3[5] * z * (xx - yy),
        SH_C3[6] * x * (xx - 3.0 * yy),
    ]
}

/// Raw SH value per channel (no +0.5 offset, no clamp). `coeffs` is `[coeff][rgb]`
/// with at least `(degree + 1)^2` coefficients; `dir` must be unit length.
pub fn eval_sh(degree: u32, coeffs: &[[f64; 3]], dir: DVec3) -> [f64; 3] {
    assert!(degree <= 3, "SH degree {degree} is not supported (0..=3)");
    let k = ((degree + 1) * (degree + 1)) as usize;
    assert!(
        coeffs.len() >= k,
        "degree {degree} needs {k} SH coefficients, got {}",
        coeffs.len()
    );
    let basis = sh_basis(dir);
    let mut out = [0.0; 3];
    for (b, c) in basis.iter().zip(coeffs).take(k) {
        for ch in 0..3 {
            out[ch] += b * c[ch];
        }
    }
    out
}

/// The 3DGS color: `max(0, SH(dir) + 0.5)` per channel, with `dir` = the normalized
/// vector from the camera center to the Gaussian's mean (world space). A Gaussian exactly
/// at the camera center has no direction; it gets `dir = 0`, i.e. the DC term only.
pub fn sh_color(degree: u32, coeffs: &[[f64; 3]], mean: DVec3, cam_center: DVec3) -> [f64; 3] {
    let dir = (mean - cam_center).normalize_or_zero();
    let raw = eval_sh(degree, coeffs, dir);
    raw.map(|v| (v + 0.5).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degree_zero_is_c0_times_dc() {
        let c = eval_sh(0, &[[1.0, -2.0, 0.5]], DVec3::Z);
        assert_eq!(c, [SH_C0, -2.0 * SH_C0, 0.5 * SH_C0]);
    }

    #[test]
    fn odd_bands_flip_sign_under_antipode() {
        let d = DVec3::new(0.3, -0.5, 0.8).normalize();
        let a = sh_basis(d);
        let b = sh_basis(-d);
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            let l = (k as f64).sqrt().floor() as i32;
            let sign = if l % 2 == 0 { 1.0 } else { -1.0 };
            assert!((x - sign * y).abs() < 1e-15, "k={k}");
        }
    }

    #[test]
    fn color_is_clamped_at_zero() {
        let c = sh_color(0, &[[-10.0, 0.0, 10.0]], DVec3::Z, DVec3::ZERO);
        assert_eq!(c[0], 0.0);
        assert_eq!(c[1], 0.5);
        assert!((c[2] - (10.0 * SH_C0 + 0.5)).abs() < 1e-15);
    }
}
