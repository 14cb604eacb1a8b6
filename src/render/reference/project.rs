//! 3D -> 2D: camera-space mean, 3D and 2D covariance (with gsplat's clamped Jacobian),
//! dilation, conic, opacity, color, and the opacity-aware screen extent.

use glam::{DMat3, DVec2, DVec3};

use super::sh::sh_color;
use super::tiles::TILE_SIZE;
use super::RenderSettings;
use crate::scene::{Camera, Gaussians};

/// A pixel is skipped when its alpha is below this (and a Gaussian whose opacity is below it
/// can never be blended).
pub const ALPHA_THRESHOLD: f64 = 1.0 / 255.0;
/// Added to the diagonal of every 2D covariance (a variance, px^2).
pub const COV2D_DILATION: f64 = 0.3;
/// Lower clamp of the determinant of the dilated 2D covariance.
pub const DET_MIN: f64 = 1e-10;
/// The Jacobian clamps x/z and y/z to the frustum widened by this fraction of tan(fov/2).
pub const FRUSTUM_MARGIN: f64 = 0.3;

/// Why a Gaussian is not visible in a view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Culled {
    /// A non-finite input value (mean, scale, quaternion or opacity logit), or a projection
    /// that came out non-finite or with a 2D covariance past float32's range.
    NonFinite,
    /// Camera-space depth `<= near` or `>= far`.
    Depth,
    /// The quaternion is all zeros, so it has no rotation.
    ZeroQuaternion,
    /// `sigmoid(logit) < 1/255`: no pixel can reach the alpha threshold.
    Opacity,
    /// The covered pixel range is empty (the extent lies outside the image).
    OffScreen,
}

/// Inclusive range of tiles `[x_min ..= x_max] x [y_min ..= y_max]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileRange {
    pub x_min: u32,
    pub x_max: u32,
    pub y_min: u32,
    pub y_max: u32,
}

impl TileRange {
    /// Number of tiles in the range.
    pub fn count(&self) -> usize {
        ((self.x_max - self.x_min + 1) * (self.y_max - self.y_min + 1)) as usize
    }

    /// Tile ids (`ty * tiles_x + tx`), row by row.
    pub fn tile_ids(&self, tiles_x: u32) -> impl Iterator<Item = u32> + '_ {
        (self.y_min..=self.y_max)
            .flat_map(move |ty| (self.x_min..=self.x_max).map(move |tx| ty * tiles_x + tx))
    }
}

/// A visible Gaussian after projection. All ranges are inclusive.
#[derive(Clone, Debug, PartialEq)]
pub struct ProjectedGaussian {
    /// Index of the Gaussian in the scene.
    pub id: u32,
    /// Camera-space mean `R * mean + t`.
    pub mean_cam: DVec3,
    /// Pixel coordinates of the mean (unclamped): `(fx x/z + cx, fy y/z + cy)`.
    pub mean2d: DVec2,
    /// Dilated 2D covariance `(xx + 0.3, xy, yy + 0.3)`.
    pub cov2d: [f64; 3],
    /// Inverse of `cov2d` with the determinant clamped at 1e-10: `(A, B, C)` with
    /// `sigma = 0.5 (A dx^2 + C dy^2) + B dx dy`.
    pub conic: [f64; 3],
    /// Camera-space depth `mean_cam.z`; the sort key within a tile.
    pub depth: f64,
    /// `sigmoid(opacity_logit)`.
    pub opacity: f64,
    /// `max(0, SH(dir) + 0.5)`.
    pub color: [f64; 3],
    /// Mahalanobis radius of the extent: `sqrt(2 ln(255 opacity))`.
    pub extent_sigma: f64,
    /// Covered pixel columns `[min, max]`, clamped to the image.
    pub px_range: [u32; 2],
    /// Covered pixel rows `[min, max]`, clamped to the image.
    pub py_range: [u32; 2],
    /// Tiles touched by the covered pixel range.
    pub tile_range: TileRange,
}

/// Rotation matrix of a wxyz quaternion after normalization; `None` for a zero quaternion.
pub fn quat_to_rotation(q: [f64; 4]) -> Option<DMat3> {
    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if norm == 0.0 {
        return None;
    }
    let (w, x, y, z) = (q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm);
    // Rows of the matrix, written out; `from_cols` takes columns, hence the transpose.
    let rows = DMat3::from_cols(
        DVec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ),
        DVec3::new(
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ),
        DVec3::new(
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    );
    Some(rows.transpose())
}

/// World-space covariance `Rq S S^T Rq^T` with `S = diag(exp(log_scale))`.
pub fn covariance_3d(log_scale: [f64; 3], quat: [f64; 4]) -> Option<DMat3> {
    let rot = quat_to_rotation(quat)?;
    let s = DMat3::from_diagonal(DVec3::from(log_scale.map(f64::exp)));
    let m = rot * s;
    Some(m * m.transpose())
}

/// gsplat's clamped `x/z` and `y/z` at camera-space `p` (the limits of
/// [`projection_jacobian`]), each with whether the clamp changed it.
pub(super) fn clamped_ratios(p: DVec3, cam: &Camera) -> [(f64, bool); 2] {
    let (w, h) = (cam.width as f64, cam.height as f64);
    let tan_fovx = 0.5 * w / cam.fx;
    let tan_fovy = 0.5 * h / cam.fy;
    let lim_x_pos = (w - cam.cx) / cam.fx + FRUSTUM_MARGIN * tan_fovx;
    let lim_x_neg = cam.cx / cam.fx + FRUSTUM_MARGIN * tan_fovx;
    let lim_y_pos = (h - cam.cy) / cam.fy + FRUSTUM_MARGIN * tan_fovy;
    let lim_y_neg = cam.cy / cam.fy + FRUSTUM_MARGIN * tan_fovy;
    let clamp = |ratio: f64, neg: f64, pos: f64| {
        let clamped = ratio.max(-neg).min(pos);
        (clamped, clamped != ratio)
    };
    [
        clamp(p.x / p.z, lim_x_neg, lim_x_pos),
        clamp(p.y / p.z, lim_y_neg, lim_y_pos),
    ]
}

/// gsplat's perspective Jacobian at camera-space point `p`, with x/z and y/z clamped to the
/// frustum widened by 0.3 tan(fov/2). Rows: `d(u)/d(p)`, `d(v)/d(p)`.
pub fn projection_jacobian(p: DVec3, cam: &Camera) -> [[f64; 3]; 2] {
    let [(rx, _), (ry, _)] = clamped_ratios(p, cam);
    let tx = p.z * rx;
    let ty = p.z * ry;
    let z2 = p.z * p.z;
    [
        [cam.fx / p.z, 0.0, -cam.fx * tx / z2],
        [0.0, cam.fy / p.z, -cam.fy * ty / z2],
    ]
}

/// `J cov_cam J^T` as `(xx, xy, yy)`, before dilation.
pub fn project_covariance(cov_cam: DMat3, p: DVec3, cam: &Camera) -> [f64; 3] {
    let j = projection_jacobian(p, cam);
    // Plain sums, element by element: out[r][c] = sum_k sum_l J[r][k] cov[k][l] J[c][l].
    let entry = |r: usize, c: usize| {
        let mut acc = 0.0;
        for k in 0..3 {
            for l in 0..3 {
                // glam is column-major: col(l)[k] is row k, column l.
                acc += j[r][k] * cov_cam.col(l)[k] * j[c][l];
            }
        }
        acc
    };
    [entry(0, 0), entry(0, 1), entry(1, 1)]
}

/// The inclusive range of pixel indices whose centers `i + 0.5` lie in
/// `[center - half, center + half]`, clamped to `[0, size - 1]`; `None` when empty.
pub fn pixel_range(center: f64, half: f64, size: u32) -> Option<[u32; 2]> {
    let lo = (center - half - 0.5).ceil();
    let hi = (center + half - 0.5).floor();
    if lo.is_nan() || hi.is_nan() {
        return None;
    }
    let lo = lo.max(0.0);
    let hi = hi.min(size as f64 - 1.0);
    if lo <= hi {
        Some([lo as u32, hi as u32])
    } else {
        None
    }
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

fn to_f64<const N: usize>(v: [f32; N]) -> [f64; N] {
    v.map(f64::from)
}

/// One Gaussian's parameters in f64, as the projection reads them (from a scene's f32
/// arrays, or from the f64 parameters the finite-difference tests perturb).
pub(super) struct GaussianValues {
    pub mean: DVec3,
    pub log_scale: [f64; 3],
    pub quat: [f64; 4],
    pub opacity_logit: f64,
    pub sh_degree: u32,
    pub sh: Vec<[f64; 3]>,
}

/// Projects Gaussian `i`; `Err` says why it is not visible. Panics when `i` is out of range.
pub fn project_one(
    g: &Gaussians,
    i: usize,
    cam: &Camera,
    settings: &RenderSettings,
) -> Result<ProjectedGaussian, Culled> {
    let k = g.sh_coeffs();
    let values = GaussianValues {
        mean: DVec3::from(to_f64(g.means[i])),
        log_scale: to_f64(g.log_scales[i]),
        quat: to_f64(g.quats[i]),
        opacity_logit: f64::from(g.opacity_logits[i]),
        sh_degree: g.sh_degree,
        sh: (0..k)
            .map(|j| {
                let o = (i * k + j) * 3;
                [g.sh[o], g.sh[o + 1], g.sh[o + 2]].map(f64::from)
            })
            .collect(),
    };
    project_values(&values, i as u32, cam, settings)
}

/// Projects one Gaussian given its values; `id` names it in the result.
pub(super) fn project_values(
    v: &GaussianValues,
    id: u32,
    cam: &Camera,
    settings: &RenderSettings,
) -> Result<ProjectedGaussian, Culled> {
    let (mean, log_scale, quat, logit) = (v.mean, v.log_scale, v.quat, v.opacity_logit);
    let finite = mean.is_finite()
        && log_scale.iter().all(|v| v.is_finite())
        && quat.iter().all(|v| v.is_finite())
        && logit.is_finite();
    if !finite {
        return Err(Culled::NonFinite);
    }

    let p = cam.world_to_camera(mean);
    if p.z <= settings.near || p.z >= settings.far {
        return Err(Culled::Depth);
    }
    let cov_world = covariance_3d(log_scale, quat).ok_or(Culled::ZeroQuaternion)?;
    let opacity = sigmoid(logit);
    if opacity < ALPHA_THRESHOLD {
        return Err(Culled::Opacity);
    }

    let r = cam.rotation;
    let cov_cam = r * cov_world * r.transpose();
    let [xx, xy, yy] = project_covariance(cov_cam, p, cam);
    let a = xx + COV2D_DILATION;
    let b = xy;
    let c = yy + COV2D_DILATION;
    let det = (a * c - b * b).max(DET_MIN);
    let conic = [c / det, -b / det, a / det];
    let mean2d = DVec2::new(cam.fx * p.x / p.z + cam.cx, cam.fy * p.y / p.z + cam.cy);
    // A 2D covariance past float32's range (scales of e^40 and more) is not drawn: the
    // device, which holds it in float32, has no footprint for it.
    let fits_f32 = [a, b, c].iter().all(|&v| v.abs() <= f32::MAX as f64);
    if !(mean2d.is_finite() && conic.iter().all(|v| v.is_finite()) && fits_f32) {
        return Err(Culled::NonFinite);
    }

    // alpha >= 1/255  <=>  d^T cov^-1 d <= 2 ln(255 o) = r^2, whose bounding box has
    // half-extents r sqrt(a), r sqrt(c).
    let extent_sigma = (2.0 * (255.0 * opacity).ln()).max(0.0).sqrt();
    let ex = extent_sigma * a.sqrt();
    let ey = extent_sigma * c.sqrt();
    let px_range = pixel_range(mean2d.x, ex, cam.width).ok_or(Culled::OffScreen)?;
    let py_range = pixel_range(mean2d.y, ey, cam.height).ok_or(Culled::OffScreen)?;
    let tile_range = TileRange {
        x_min: px_range[0] / TILE_SIZE,
        x_max: px_range[1] / TILE_SIZE,
        y_min: py_range[0] / TILE_SIZE,
        y_max: py_range[1] / TILE_SIZE,
    };

    let degree = match settings.sh_degree {
        Some(d) => d.min(v.sh_degree),
        None => v.sh_degree,
    };
    let color = sh_color(degree, &v.sh, mean, cam.center());

    Ok(ProjectedGaussian {
        id,
        mean_cam: p,
        mean2d,
        cov2d: [a, b, c],
        conic,
        depth: p.z,
        opacity,
        color,
        extent_sigma,
        px_range,
        py_range,
        tile_range,
    })
}

/// Projects every Gaussian and keeps the visible ones, in id order.
///
/// Panics when the scene's arrays are inconsistent ([`Gaussians::check_layout`]).
pub fn project(g: &Gaussians, cam: &Camera, settings: &RenderSettings) -> Vec<ProjectedGaussian> {
    if let Err(e) = g.check_layout() {
        panic!("reference renderer: invalid scene layout: {e}");
    }
    (0..g.len())
        .filter_map(|i| project_one(g, i, cam, settings).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    #[test]
    fn rotation_matches_glam() {
        let q = [0.7, -0.2, 0.4, 0.9];
        let ours = quat_to_rotation(q).unwrap();
        let glam_q = DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize();
        let theirs = DMat3::from_quat(glam_q);
        let diff = (ours - theirs).to_cols_array();
        assert!(
            diff.iter().all(|d| d.abs() < 1e-14),
            "{ours:?} vs {theirs:?}"
        );
        assert!(quat_to_rotation([0.0; 4]).is_none());
    }

    #[test]
    fn pixel_range_uses_pixel_centers() {
        // Centers 0.5, 1.5, 2.5, 3.5: [1.0, 3.0] holds 1.5 and 2.5.
        assert_eq!(pixel_range(2.0, 1.0, 10), Some([1, 2]));
        // Closed interval: [1.5, 2.5] holds both endpoints.
        assert_eq!(pixel_range(2.0, 0.5, 10), Some([1, 2]));
        // Between two centers, nothing covered.
        assert_eq!(pixel_range(2.0, 0.25, 10), None);
        assert_eq!(pixel_range(-5.0, 1.0, 10), None);
        assert_eq!(pixel_range(12.0, 3.0, 10), Some([9, 9]));
        assert_eq!(pixel_range(f64::NAN, 1.0, 10), None);
    }
}
