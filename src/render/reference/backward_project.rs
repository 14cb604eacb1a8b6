//! [`project_one`](super::project_one) evaluated on f64 parameters: the same operations in
//! the same order (tests assert bitwise-equal results), so finite differences of the
//! forward can use steps far below float32 resolution.

use glam::{DVec2, DVec3};

use super::backward_params::GaussianParams;
use super::{
    covariance_3d, pixel_range, project_covariance, sh_color, Culled, ProjectedGaussian,
    RenderSettings, TileRange, ALPHA_THRESHOLD, COV2D_DILATION, DET_MIN, TILE_SIZE,
};
use crate::scene::Camera;

pub(super) fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// The SH degree the forward evaluates: the settings' cap, at most the scene's degree.
pub(super) fn effective_sh_degree(params: &GaussianParams, settings: &RenderSettings) -> u32 {
    match settings.sh_degree {
        Some(d) => d.min(params.sh_degree),
        None => params.sh_degree,
    }
}

/// Projects Gaussian `i` of `params`; `Err` says why it is not visible.
pub fn project_params(
    params: &GaussianParams,
    i: usize,
    cam: &Camera,
    settings: &RenderSettings,
) -> Result<ProjectedGaussian, Culled> {
    let mean = DVec3::from(params.means[i]);
    let log_scale = params.log_scales[i];
    let quat = params.quats[i];
    let logit = params.opacity_logits[i];
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
    if !(mean2d.is_finite() && conic.iter().all(|v| v.is_finite())) {
        return Err(Culled::NonFinite);
    }

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

    let degree = effective_sh_degree(params, settings);
    let color = sh_color(degree, &params.sh_of(i), mean, cam.center());

    Ok(ProjectedGaussian {
        id: i as u32,
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
