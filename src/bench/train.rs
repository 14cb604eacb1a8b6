//! Training-iteration throughput: the joint trainer's iterations on one view of a random
//! scene (or a scene folder), full or semantics-only, with the GPU time of each stage.
//! The forward and backward stages here are also the benchmark of the backward pass.

use std::time::Instant;

use anyhow::{ensure, Result};
use serde::Serialize;

use super::fuse::BlockLabels;
use super::render::BenchInput;
use super::{median, warm_up};
use crate::fuse::LabelSource;
use crate::gpu::timings::KernelTotal;
use crate::gpu::Gpu;
use crate::train::config::TrainConfig;
use crate::train::trainer::{StageTotals, Trainer};
use crate::train::views::TrainView;
use crate::util::Rng;

/// Iterations the trainer is configured for beyond the timed ones: the warm-up's (see
/// [`warm_up`]); a long warm-up may use them all, and then stops there.
const WARMUP_ITERS: u32 = 1000;

#[derive(Debug, Serialize)]
pub struct TrainBench {
    #[serde(flatten)]
    pub input: BenchInput,
    pub gaussians: usize,
    pub semantics_only: bool,
    /// Whether the view has a target image (false: the semantic loss alone, as `train
    /// --semantics-only` without --images).
    pub images: bool,
    pub iters: u32,
    pub device: String,
    /// Median wall time of one iteration (both submissions and their waits).
    pub iter_ms: f64,
    /// Mean GPU time per iteration of each stage, from timestamps.
    pub forward_ms: f64,
    /// Photometric (L1 + SSIM) and semantic (cross-entropy) losses and their gradients.
    pub loss_ms: f64,
    /// Blend and projection backward (the softmax backward too).
    pub backward_ms: f64,
    /// Entropy regularizer and Adam.
    pub optimizer_ms: f64,
    /// GPU time per kernel of the last iteration.
    pub kernels: Vec<KernelTotal>,
}

/// Runs `iters` timed iterations (after a short warm-up) without densification; without
/// `images` (`semantics_only` only) the view has no target image.
pub fn bench_train(
    gpu: &Gpu,
    input: &BenchInput,
    iters: u32,
    semantics_only: bool,
    images: bool,
) -> Result<TrainBench> {
    ensure!(iters > 0, "--iters must be at least 1");
    let (g, cam) = input.load()?;
    let view = target_view(&cam, input.channels, input.seed, images)?;
    let mut cfg = TrainConfig::new(WARMUP_ITERS + iters);
    cfg.semantics_only = semantics_only;
    cfg.densify = None;
    cfg.log_every = u32::MAX; // no loss read-back inside the timed iterations
    let mut trainer = Trainer::new(gpu, &g, std::slice::from_ref(&view), cfg, &[])?;
    let mut warm_iters = 0;
    warm_up(|| {
        if warm_iters < WARMUP_ITERS {
            warm_iters += 1;
            trainer.step()?;
        }
        Ok(())
    })?;
    let before = trainer.times();
    let mut walls = Vec::with_capacity(iters as usize);
    for _ in 0..iters {
        let start = Instant::now();
        trainer.step()?;
        walls.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let per_iter = |f: fn(&StageTotals) -> f64| (f(&trainer.times()) - f(&before)) / iters as f64;
    Ok(TrainBench {
        input: input.with_size_of(&cam),
        gaussians: g.len(),
        semantics_only,
        images,
        iters,
        device: gpu.caps().name.clone(),
        iter_ms: median(&mut walls),
        forward_ms: per_iter(|t| t.forward_ms),
        loss_ms: per_iter(|t| t.loss_ms),
        backward_ms: per_iter(|t| t.backward_ms),
        optimizer_ms: per_iter(|t| t.optimizer_ms),
        kernels: trainer.last_kernels().to_vec(),
    })
}

/// A training target for `cam`: a noisy gray image (with `image`) and, with classes, block
/// label maps as `bench fuse` draws them.
fn target_view(
    cam: &crate::scene::Camera,
    channels: usize,
    seed: u64,
    image: bool,
) -> Result<TrainView> {
    let pixels = cam.width as usize * cam.height as usize;
    let mut rng = Rng::new(seed ^ 0x7a29e7);
    let values = if image { pixels * 3 } else { 0 };
    let rgb = (0..values)
        .map(|_| (0.5 + 0.1 * rng.normal()).clamp(0.0, 1.0) as f32)
        .collect();
    let labels = if channels > 0 {
        let blocks = BlockLabels::new(channels, seed);
        blocks.labels(0, cam)?.unwrap_or_default()
    } else {
        Vec::new()
    };
    Ok(TrainView {
        camera: cam.clone(),
        rgb,
        labels,
    })
}
