//! The tensors a training run updates, in one shape: the Gaussian parameters and, with
//! semantic classes, the logits. Adam steps and densification walk them in the order of
//! [`PerTensor::iter`].

use anyhow::Result;

use super::adam::AdamMoments;
use super::config::LearningRates;
use super::densify::Role;
use crate::gpu::{Buffer, Gpu};
use crate::render::backward::SceneGrads;
use crate::render::gpu_scene::{GaussianParams, ParamTensor};
use crate::render::GpuScene;

/// One value per trained tensor.
pub(crate) struct PerTensor<T> {
    pub params: GaussianParams<T>,
    /// None without semantic classes.
    pub logits: Option<T>,
}

impl<T> PerTensor<T> {
    /// The parameters in [`ParamTensor::ALL`] order, then the logits.
    pub fn iter(&self) -> impl Iterator<Item = &T> {
        self.params
            .as_ref()
            .into_array()
            .into_iter()
            .chain(&self.logits)
    }

    /// Applies `f` to every tensor, in the order of [`PerTensor::iter`]; stops at the
    /// first error.
    pub fn try_map<U, E>(self, mut f: impl FnMut(T) -> Result<U, E>) -> Result<PerTensor<U>, E> {
        Ok(PerTensor {
            params: self.params.try_map(&mut f)?,
            logits: self.logits.map(f).transpose()?,
        })
    }
}

/// A trained tensor: its buffer, gradient and Adam moments, its width per Gaussian, how
/// densification rebuilds it, and its learning rate.
pub(crate) struct TensorRef<'a> {
    pub param: &'a Buffer,
    pub grad: &'a Buffer,
    pub moments: &'a AdamMoments,
    pub width: u32,
    pub role: Role,
    /// None: the position schedule's rate of this step.
    pub lr: Option<f64>,
    /// A geometry or color parameter (frozen by `--semantics-only`), not the logits.
    pub geometry: bool,
}

/// The trained tensors of `scene` with their gradients and moments.
pub(crate) fn tensors<'a>(
    scene: &'a GpuScene,
    grads: &'a SceneGrads,
    moments: &'a PerTensor<AdamMoments>,
    lr: &LearningRates,
) -> PerTensor<TensorRef<'a>> {
    let params = GaussianParams::from_fn(|p: ParamTensor| TensorRef {
        param: &scene.params[p],
        grad: &grads.params[p],
        moments: &moments.params[p],
        width: p.floats(scene.sh_coeffs),
        role: Role::of(p),
        lr: lr.constant(p),
        geometry: true,
    });
    let logits = scene.logits.as_ref().zip(moments.logits.as_ref());
    let logits = logits.map(|(param, moments)| TensorRef {
        param,
        grad: &grads.logits,
        moments,
        width: scene.channels,
        role: Role::Copy,
        lr: Some(lr.logits),
        geometry: false,
    });
    PerTensor { params, logits }
}

/// Zeroed Adam moments for every trained tensor of `scene`, named after the tensors.
pub(crate) fn new_moments(gpu: &Gpu, scene: &GpuScene) -> Result<PerTensor<AdamMoments>> {
    let n = scene.n;
    let params = GaussianParams::try_from_fn(|p| {
        AdamMoments::new(gpu, p.name(), n * p.floats(scene.sh_coeffs))
    })?;
    let logits = scene.logits.as_ref();
    let logits = logits.map(|l| AdamMoments::new(gpu, l.name(), n * scene.channels));
    Ok(PerTensor {
        params,
        logits: logits.transpose()?,
    })
}
