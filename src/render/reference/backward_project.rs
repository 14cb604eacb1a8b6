//! [`project_one`](super::project_one) evaluated on f64 parameters: the same projection
//! code (tests assert bitwise-equal results), so finite differences of the forward can use
//! steps far below float32 resolution.

use glam::DVec3;

use super::backward_params::GaussianParams;
use super::project::{project_values, GaussianValues};
use super::{Culled, ProjectedGaussian, RenderSettings};
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
    let values = GaussianValues {
        mean: DVec3::from(params.means[i]),
        log_scale: params.log_scales[i],
        quat: params.quats[i],
        opacity_logit: params.opacity_logits[i],
        sh_degree: params.sh_degree,
        sh: params.sh_of(i),
    };
    project_values(&values, i as u32, cam, settings)
}
