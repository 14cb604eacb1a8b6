//! What a training run does: iterations, learning rates, loss weights and the
//! densification schedule. Defaults are 3DGS's (Kerbl et al. 2023) and Gaussian Semantics', with
//! the 30k-iteration schedule scaled to the run's length.

use serde::Serialize;

use crate::render::gpu_scene::ParamTensor;
use crate::render::SemanticMode;

/// 3DGS's schedule is written for this many iterations.
const REFERENCE_ITERS: f64 = 30_000.0;

/// Learning rates (Adam), 3DGS's defaults. Positions decay exponentially from `means` to
/// `means_final` and are scaled by the scene extent.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct LearningRates {
    pub means: f64,
    pub means_final: f64,
    /// All SH coefficients (3DGS uses this for the DC term and 1/20 of it for higher
    /// bands; one rate here, exact for degree-0 scenes).
    pub sh: f64,
    pub opacity: f64,
    pub log_scales: f64,
    pub quats: f64,
    /// Semantic logits (not in 3DGS; chosen by measurement, see README).
    pub logits: f64,
}

impl LearningRates {
    /// The constant rate of a parameter tensor; None for the means, whose rate follows
    /// the position schedule ([`super::adam::ExponentialLr::positions`]).
    pub fn constant(&self, param: ParamTensor) -> Option<f64> {
        match param {
            ParamTensor::Means => None,
            ParamTensor::LogScales => Some(self.log_scales),
            ParamTensor::Quats => Some(self.quats),
            ParamTensor::OpacityLogits => Some(self.opacity),
            ParamTensor::Sh => Some(self.sh),
        }
    }
}

impl Default for LearningRates {
    fn default() -> Self {
        LearningRates {
            means: 1.6e-4,
            means_final: 1.6e-6,
            sh: 2.5e-3,
            opacity: 0.025,
            log_scales: 5e-3,
            quats: 1e-3,
            logits: 0.05,
        }
    }
}

/// When densification runs (iterations).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct DensifySchedule {
    pub from: u32,
    pub until: u32,
    pub every: u32,
    pub opacity_reset_every: u32,
    pub grad_threshold: f32,
    /// Hard cap on the number of Gaussians.
    pub max_gaussians: u32,
}

impl DensifySchedule {
    /// 3DGS's schedule (500..15000 every 100) scaled to `iters`; the opacity reset stays
    /// every 3000 iterations (opacities need about that long to recover from 0.01 at
    /// their learning rate, so short runs never reset).
    pub fn scaled_to(iters: u32) -> DensifySchedule {
        let s = iters as f64 / REFERENCE_ITERS;
        let at = |v: f64| (v * s).round().max(1.0) as u32;
        DensifySchedule {
            from: at(500.0),
            until: at(15_000.0),
            every: at(100.0).max(10),
            opacity_reset_every: 3000,
            grad_threshold: 2e-4,
            max_gaussians: 3_000_000,
        }
    }
}

/// A training run.
#[derive(Clone, Debug, Serialize)]
pub struct TrainConfig {
    pub iters: u32,
    /// Train only the semantic logits; geometry and colors stay as loaded.
    pub semantics_only: bool,
    pub semantic_mode: SemanticMode,
    pub lambda_sem: f32,
    pub lambda_entropy: f32,
    /// Iterations over which lambda_entropy grows linearly from 0.
    pub entropy_warmup: u32,
    pub lr: LearningRates,
    /// None: no densification.
    pub densify: Option<DensifySchedule>,
    pub background: [f32; 3],
    /// Read the losses back every this many iterations (a host sync).
    pub log_every: u32,
    pub seed: u64,
    /// Order-independent (fixed-point) gradient sums: the same inputs and seed give the
    /// same model on the same device and driver (see docs/joint-training.md).
    pub deterministic: bool,
}

impl TrainConfig {
    /// Gaussian Semantics' defaults (lambda_sem 1, lambda_H 0.01 warmed up over the first 5k of
    /// 30k iterations) and 3DGS's densification, scaled to `iters`.
    pub fn new(iters: u32) -> TrainConfig {
        TrainConfig {
            iters,
            semantics_only: false,
            semantic_mode: SemanticMode::RawLogits,
            lambda_sem: 1.0,
            lambda_entropy: 0.01,
            entropy_warmup: (5000.0 * iters as f64 / REFERENCE_ITERS).round() as u32,
            lr: LearningRates::default(),
            densify: Some(DensifySchedule::scaled_to(iters)),
            background: [0.0; 3],
            log_every: 10,
            seed: 0,
            deterministic: false,
        }
    }

    /// Logits only: no densification, geometry frozen.
    pub fn semantics_only(iters: u32) -> TrainConfig {
        TrainConfig {
            semantics_only: true,
            densify: None,
            ..TrainConfig::new(iters)
        }
    }
}
