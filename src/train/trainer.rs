//! The training loop of joint optimization (Gaussian Semantics) on the GPU. One iteration, one
//! view: render (RGB + semantics), losses, backward, in one submission; then softmax
//! backward, entropy, Adam in a second (so an intersection-buffer overflow, which re-runs
//! the first, never applies a step twice). Densification rebuilds every tensor on the
//! device. Nothing is read back except the 64-byte frame status and, every `log_every`
//! iterations, the loss values.

use std::collections::HashMap;
use std::sync::OnceLock;
use std::time::Instant;

use anyhow::{bail, ensure, Result};
use glam::DVec3;
use serde::Serialize;

use super::adam::{record_adam, AdamMoments, AdamStep, AdamTensor, ExponentialLr};
use super::config::TrainConfig;
use super::densify::{
    reset_opacity, Densifier, DensifyConfig, DensifyInputs, DensifyPlan, Role, OPACITY_RESET,
};
use super::loss::{ImageLoss, SemanticTerm};
use super::loss_entropy::entropy_weight;
use super::loss_values::LossValues;
use super::tensors::{new_moments, tensors, PerTensor, TensorRef};
use super::views::{DeviceView, TrainView};
use crate::gpu::timings::KernelTotal;
use crate::gpu::{Buffer, Gpu, Mark, Recorder};
use crate::render::backward::{Accumulation, FixedCheck, PixelGrads, SceneGrads, FIXED_MAX_REDOS};
use crate::render::{GpuScene, Rasterizer, RenderOptions, SemanticMode};
use crate::scene::gaussians::SemanticLogits;
use crate::scene::{Camera, Gaussians};
use crate::util::Rng;

/// GPU milliseconds per stage, summed over the iterations so far.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StageTotals {
    /// Projection, sorting, binning and forward blending.
    pub forward_ms: f64,
    /// Photometric and semantic losses and their image gradients.
    pub loss_ms: f64,
    /// Blend and projection backward (and the softmax backward).
    pub backward_ms: f64,
    /// Entropy regularizer and Adam.
    pub optimizer_ms: f64,
    /// Densification and pruning (wall time: it reads back counts).
    pub densify_ms: f64,
    pub iterations: u32,
}

/// One densification step, for the log.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct DensifyEvent {
    pub iteration: u32,
    pub before: u32,
    pub after: u32,
    pub pruned: u32,
    pub cloned: u32,
    pub split: u32,
    pub capped: u32,
}

/// The result of a run.
pub struct TrainOutput {
    /// Trained Gaussians with their semantic logits (and no class fields: see
    /// [`classes_from_logits`]).
    pub gaussians: Gaussians,
    /// Per Gaussian: whether some training view with a label map saw it.
    pub seen: Vec<bool>,
    /// The riders given to [`Trainer::new`], carried through densification.
    pub riders: Vec<Vec<f32>>,
    pub times: StageTotals,
    pub densify_events: Vec<DensifyEvent>,
    /// Device memory the run held at its end (buffers of the final model, gradients,
    /// moments, views).
    pub peak_device_bytes: u64,
}

pub struct Trainer {
    gpu: Gpu,
    cfg: TrainConfig,
    scene: GpuScene,
    grads: SceneGrads,
    moments: PerTensor<AdamMoments>,
    riders: Vec<Buffer>,
    rasterizer: Rasterizer,
    losses: HashMap<(u32, u32), ImageLoss>,
    views: Vec<DeviceView>,
    v_rgb: Buffer,
    v_alpha: Buffer,
    v_sem_norm: Buffer,
    densifier: Densifier,
    extent: f64,
    position_lr: ExponentialLr,
    iter: u32,
    order: Vec<usize>,
    rng: Rng,
    times: StageTotals,
    events: Vec<DensifyEvent>,
    last_loss: Option<(u32, u32)>,
    /// GPU time per kernel of the last iteration (both submissions), for benchmarks.
    last_kernels: Vec<KernelTotal>,
}

/// 3DGS's scene extent: 1.1 times the largest distance of a camera center from their mean.
pub fn scene_extent(cams: &[Camera]) -> f64 {
    let centers: Vec<DVec3> = cams.iter().map(|c| c.center()).collect();
    let mean = centers.iter().copied().sum::<DVec3>() / centers.len().max(1) as f64;
    let radius = centers
        .iter()
        .map(|c| c.distance(mean))
        .fold(0.0f64, f64::max);
    1.1 * radius.max(1e-3)
}

/// Whether the views have target images: every one (true), or, with `semantics_only`,
/// none (false); a mix is refused.
fn check_target_images(views: &[TrainView], semantics_only: bool) -> Result<bool> {
    let without = views.iter().filter(|v| v.rgb.is_empty()).count();
    match without {
        0 => Ok(true),
        n if n == views.len() && semantics_only => Ok(false),
        n if n == views.len() => bail!(
            "the views have no target images: training geometry and colours needs them \
             (--semantics-only alone trains without)"
        ),
        n => bail!(
            "{n} of {} views have no target image: give every view one, or none \
             (--semantics-only)",
            views.len()
        ),
    }
}

impl Trainer {
    /// Prepares a run: `init` must carry semantic logits with `channels` classes (see
    /// [`with_initial_logits`]); `riders` are per-Gaussian values carried unchanged through
    /// densification (e.g. a ground-truth class, for evaluation).
    pub fn new(
        gpu: &Gpu,
        init: &Gaussians,
        views: &[TrainView],
        cfg: TrainConfig,
        riders: &[Vec<f32>],
    ) -> Result<Trainer> {
        ensure!(!views.is_empty(), "training needs at least one view");
        ensure!(cfg.iters > 0, "training needs at least one iteration");
        ensure!(!init.is_empty(), "the initial scene has no Gaussians");
        let channels = init.semantics.as_ref().map_or(0, |s| s.channels) as u32;
        ensure!(
            channels > 0 || !cfg.semantics_only,
            "--semantics-only needs semantic classes (the labels' classes; `bench train`: --channels of at least 1)"
        );
        for r in riders {
            ensure!(r.len() == init.len(), "a rider has the wrong length");
        }
        let photometric = check_target_images(views, cfg.semantics_only)?;
        let scene = GpuScene::upload(gpu, init)?;
        let accumulation = Accumulation::choose(gpu, cfg.deterministic);
        let mut grads = SceneGrads::new(gpu, &scene, accumulation)?;
        grads.semantics_only = cfg.semantics_only;
        let device_views = views
            .iter()
            .map(|v| v.upload(gpu, channels))
            .collect::<Result<Vec<_>>>()?;
        let max_pixels = views
            .iter()
            .map(|v| v.camera.width as u64 * v.camera.height as u64)
            .max()
            .unwrap_or(1);
        let cams: Vec<Camera> = views.iter().map(|v| v.camera.clone()).collect();
        let extent = scene_extent(&cams);
        let v_alpha = gpu.buffer("v_alpha", max_pixels * 4)?;
        let mut rec = Recorder::new(gpu)?;
        rec.fill(&v_alpha, 0, v_alpha.size(), 0); // no loss reads the accumulated alpha
        rec.submit_and_wait()?;
        let moments = new_moments(gpu, &scene)?;
        Ok(Trainer {
            gpu: gpu.clone(),
            position_lr: ExponentialLr::positions(extent, cfg.iters),
            scene,
            grads,
            moments,
            riders: riders
                .iter()
                .map(|r| gpu.buffer_from("rider", r))
                .collect::<Result<_, _>>()?,
            rasterizer: Rasterizer::new(gpu),
            losses: HashMap::new(),
            views: device_views,
            // The semantic-only backward reads no v_rgb: without target images it stays a
            // placeholder.
            v_rgb: gpu.buffer("v_rgb", if photometric { max_pixels * 12 } else { 4 })?,
            v_alpha,
            v_sem_norm: gpu.buffer("v_sem_norm", max_pixels * channels.max(1) as u64 * 4)?,
            densifier: Densifier::new(gpu),
            extent,
            iter: 0,
            order: Vec::new(),
            rng: Rng::new(cfg.seed ^ 0x7261_696e),
            times: StageTotals::default(),
            events: Vec::new(),
            last_loss: None,
            last_kernels: Vec::new(),
            cfg,
        })
    }

    /// The trained tensors, in the order of [`PerTensor::iter`].
    fn tensors(&self) -> PerTensor<TensorRef<'_>> {
        tensors(&self.scene, &self.grads, &self.moments, &self.cfg.lr)
    }

    pub fn iteration(&self) -> u32 {
        self.iter
    }

    pub fn gaussian_count(&self) -> u32 {
        self.scene.n
    }

    pub fn times(&self) -> StageTotals {
        self.times
    }

    /// GPU time per kernel of the last iteration's two submissions (a kernel in both, the
    /// loss's reduction, is one entry of both's dispatches).
    pub fn last_kernels(&self) -> &[KernelTotal] {
        &self.last_kernels
    }

    pub fn extent(&self) -> f64 {
        self.extent
    }

    /// Views in a fresh random order each epoch (3DGS).
    fn next_view(&mut self) -> usize {
        if self.order.is_empty() {
            self.order = (0..self.views.len()).collect();
            for i in (1..self.order.len()).rev() {
                let j = (self.rng.next_u32() as usize) % (i + 1);
                self.order.swap(i, j);
            }
        }
        self.order.pop().expect("refilled")
    }

    /// Runs one iteration; returns the loss values when this iteration read them back.
    pub fn step(&mut self) -> Result<Option<LossValues>> {
        let step = self.iter + 1;
        let vi = self.next_view();
        let key = self.run_view_checked(vi, step)?;
        self.run_update(step, key)?;
        self.iter = step;
        self.times.iterations = step;
        self.last_loss = Some(key);
        self.densify_on_schedule(step)?;
        let log = step.is_multiple_of(self.cfg.log_every.max(1)) || step == self.cfg.iters;
        if log {
            let values = self.losses[&key].read_values()?;
            ensure!(
                values.is_finite(),
                "training diverged: the loss is not finite at iteration {step} ({}); lower the \
                 learning rates or the loss weights (diverged in the first iterations: check the \
                 initial scene with semsplat inspect, for colours or scales past any scene's)",
                values.listed()
            );
            Ok(Some(values))
        } else {
            Ok(None)
        }
    }

    /// [`Trainer::run_view`], redone with smaller fixed-point scales while a gradient sum
    /// does not fit (nothing of a redone view was applied); errors on a non-finite
    /// gradient, naming the iteration.
    fn run_view_checked(&mut self, vi: usize, step: u32) -> Result<(u32, u32)> {
        for _ in 0..=FIXED_MAX_REDOS {
            let key = self.run_view(vi)?;
            match self.grads.fixed.check(&self.gpu)? {
                FixedCheck::Done => return Ok(key),
                FixedCheck::Redo => continue,
                FixedCheck::NonFinite => bail!(
                    "training diverged: a gradient is not finite at iteration {step} (view {}); \
                     lower the learning rates or the loss weights",
                    self.views[vi].camera.name
                ),
            }
        }
        bail!("iteration {step}: the fixed-point gradients overflow at every scale tried")
    }

    /// The loss scratch of views of `cam`'s size (made on first use; its key is the size),
    /// with the backward carry sized for the view.
    fn prepare_view(&mut self, cam: &Camera) -> Result<(u32, u32)> {
        let key = (cam.width, cam.height);
        if !self.losses.contains_key(&key) {
            let (w, h, channels) = (cam.width, cam.height, self.scene.channels);
            let loss = match self.views[0].rgb {
                Some(_) => ImageLoss::new(&self.gpu, w, h, channels)?,
                None => ImageLoss::semantic(&self.gpu, w, h, channels)?,
            };
            self.losses.insert(key, loss);
        }
        let windows = self.rasterizer.windows_for(self.scene.n);
        self.grads.prepare_view(&self.gpu, cam, windows)?;
        Ok(key)
    }

    /// The first submission of an iteration: renders view `vi` (RGB + semantics), records
    /// its losses and backward after the forward blend, and adds their GPU times. An
    /// intersection-buffer overflow re-runs it whole. Returns the view's loss key.
    fn run_view(&mut self, vi: usize) -> Result<(u32, u32)> {
        let cam = self.views[vi].camera.clone();
        let key = self.prepare_view(&cam)?;
        let channels = self.scene.channels;
        let mode = self.cfg.semantic_mode;
        let opts = RenderOptions {
            background: self.cfg.background,
            semantics: (channels > 0).then_some(mode),
            ..Default::default()
        };
        let (scene, grads, view, loss) = (
            &self.scene,
            &self.grads,
            &self.views[vi],
            &self.losses[&key],
        );
        let (v_rgb, v_alpha, v_sem_norm) = (&self.v_rgb, &self.v_alpha, &self.v_sem_norm);
        let lambda_sem = self.cfg.lambda_sem;
        let mut marks: [Option<Mark>; 3] = [None; 3];
        let run = self
            .rasterizer
            .run_tiled(scene, &cam, &opts, |rec, tiles| {
                if mode == SemanticMode::Softmax && channels > 0 {
                    scene.record_softmax(rec)?;
                }
                grads.record_zero(rec);
                tiles.record_blend(rec)?;
                marks[0] = rec.mark();
                let term = SemanticTerm {
                    sem_norm: tiles.sem_norm(),
                    labels: &view.labels,
                    mode,
                    lambda: lambda_sem,
                    v_sem_norm,
                };
                match &view.rgb {
                    Some(target) => {
                        let semantics = (channels > 0).then_some(&term);
                        loss.record(rec, tiles.rgb(), target, v_rgb, semantics)?
                    }
                    None => loss.record_semantic(rec, &term)?,
                }
                marks[1] = rec.mark();
                let upstream = PixelGrads {
                    rgb: v_rgb,
                    alpha: v_alpha,
                    sem_norm: v_sem_norm,
                };
                tiles.record_backward(rec, scene, &upstream, grads)?;
                marks[2] = rec.mark();
                Ok(())
            })?;
        let ms = |a: Option<Mark>, b: Option<Mark>| run.timings.between(a, b).unwrap_or(0.0) * 1e-6;
        self.times.forward_ms += ms(run.marks[0], marks[0]);
        self.times.loss_ms += ms(marks[0], marks[1]);
        self.times.backward_ms += ms(marks[1], marks[2]);
        self.last_kernels = run.timings.by_kernel();
        Ok(key)
    }

    /// The second submission of iteration `step`: softmax backward, the entropy
    /// regularizer (through the loss scratch of `key`), and Adam on every trained tensor.
    fn run_update(&mut self, step: u32, key: (u32, u32)) -> Result<()> {
        let mut rec = Recorder::new(&self.gpu)?;
        let m0 = rec.mark();
        if self.cfg.semantic_mode == SemanticMode::Softmax {
            self.grads.record_softmax_backward(&mut rec, &self.scene)?;
        }
        let m1 = rec.mark();
        let lambda_h = entropy_weight(self.cfg.lambda_entropy, step, self.cfg.entropy_warmup);
        if let (Some(logits), true) = (&self.scene.logits, lambda_h > 0.0) {
            self.losses[&key].record_entropy(
                &mut rec,
                logits,
                self.scene.n,
                lambda_h,
                &self.grads.logits,
            )?;
        }
        let pos_lr = self.position_lr.at(step);
        for t in self.tensors().iter() {
            if self.cfg.semantics_only && t.geometry {
                continue;
            }
            let tensor = AdamTensor {
                param: t.param,
                grad: t.grad,
                exp_avg: &t.moments.exp_avg,
                exp_avg_sq: &t.moments.exp_avg_sq,
                count: self.scene.n * t.width,
            };
            record_adam(
                &mut rec,
                &tensor,
                AdamStep::new(t.lr.unwrap_or(pos_lr), step),
            )?;
        }
        let m2 = rec.mark();
        let timings = rec.submit_and_wait()?;
        self.times.backward_ms += timings.between(m0, m1).unwrap_or(0.0) * 1e-6;
        self.times.optimizer_ms += timings.between(m1, m2).unwrap_or(0.0) * 1e-6;
        timings.add_to(&mut self.last_kernels);
        Ok(())
    }

    /// Densifies and resets opacities when the schedule says so after iteration `step`.
    fn densify_on_schedule(&mut self, step: u32) -> Result<()> {
        if let Some(d) = self.cfg.densify {
            let start = Instant::now();
            if step < d.until && step > d.from && step.is_multiple_of(d.every) {
                self.densify(step > d.opacity_reset_every)?;
            }
            if step < d.until && step.is_multiple_of(d.opacity_reset_every) {
                self.reset_opacity()?;
            }
            self.times.densify_ms += start.elapsed().as_secs_f64() * 1e3;
        }
        Ok(())
    }

    /// The loss values of the last iteration (one small download).
    pub fn last_losses(&self) -> Result<Option<LossValues>> {
        match self.last_loss {
            Some(key) => Ok(Some(self.losses[&key].read_values()?)),
            None => Ok(None),
        }
    }

    /// One densify-and-prune step (3DGS): rebuilds every tensor, its Adam moments and the
    /// riders for the new set.
    fn densify(&mut self, prune_large: bool) -> Result<()> {
        let sched = self.cfg.densify.expect("scheduled");
        let config = DensifyConfig {
            grad_threshold: sched.grad_threshold,
            extent: self.extent as f32,
            prune_large,
            max_gaussians: sched.max_gaussians.max(1),
            seed: self.cfg.seed.wrapping_add(self.iter as u64),
            ..Default::default()
        };
        let inputs = DensifyInputs {
            n: self.scene.n,
            log_scales: &self.scene.params.log_scales,
            quats: &self.scene.params.quats,
            opacity_logits: &self.scene.params.opacity_logits,
            grad_accum: &self.grads.densify_grad,
            grad_count: &self.grads.densify_count,
        };
        let plan: DensifyPlan = self.densifier.plan(&inputs, &config)?;
        let mut rec = Recorder::new(&self.gpu)?;
        let d = &self.densifier;
        let rebuilt = self.tensors().try_map(|t| {
            let param = d.apply(&mut rec, &plan, t.param, t.width, t.role)?;
            let mut moment = |m: &Buffer| d.apply(&mut rec, &plan, m, t.width, Role::AdamMoment);
            let moments = AdamMoments {
                exp_avg: moment(&t.moments.exp_avg)?,
                exp_avg_sq: moment(&t.moments.exp_avg_sq)?,
            };
            anyhow::Ok((param, moments))
        })?;
        let riders = self
            .riders
            .iter()
            .map(|r| self.densifier.apply(&mut rec, &plan, r, 1, Role::Copy))
            .collect::<Result<Vec<_>>>()?;
        rec.submit_and_wait()?;
        let (params, param_moments) = rebuilt.params.unzip();
        let (logits, logit_moments) = rebuilt.logits.unzip();
        let old = &self.scene;
        let scene = GpuScene {
            n: plan.new_n,
            sh_degree: old.sh_degree,
            sh_coeffs: old.sh_coeffs,
            channels: old.channels,
            attributes: old.attributes,
            class_index: None,
            params,
            logits,
            probs: OnceLock::new(),
            origin: old.origin,
        };
        let mut grads = SceneGrads::new(&self.gpu, &scene, self.grads.accumulation)?;
        grads.semantics_only = self.grads.semantics_only;
        grads.fixed.adopt(&self.grads.fixed);
        self.grads = grads;
        self.scene = scene;
        self.moments = PerTensor {
            params: param_moments,
            logits: logit_moments,
        };
        self.riders = riders;
        self.events.push(DensifyEvent {
            iteration: self.iter,
            before: plan.n,
            after: plan.new_n,
            pruned: plan.pruned,
            cloned: plan.cloned,
            split: plan.split,
            capped: plan.capped(),
        });
        Ok(())
    }

    /// 3DGS's opacity reset: opacities capped at 0.01, their Adam moments restarted.
    fn reset_opacity(&mut self) -> Result<()> {
        let mut rec = Recorder::new(&self.gpu)?;
        let m = &self.moments.params.opacity_logits;
        reset_opacity(
            &mut rec,
            self.scene.n,
            &self.scene.params.opacity_logits,
            &[&m.exp_avg, &m.exp_avg_sq],
            OPACITY_RESET,
        )?;
        rec.submit_and_wait()?;
        Ok(())
    }

    /// Downloads the current model (Gaussians with logits).
    pub fn gaussians(&self) -> Result<Gaussians> {
        let mut g = Gaussians::default();
        self.scene.download_into(&self.gpu, &mut g)?;
        Ok(g)
    }

    /// Per Gaussian, whether some training view with a label map renders it (one pass over
    /// those views): only they give its logits evidence; a Gaussian no such view sees keeps
    /// what the entropy term made of its start, which is no class.
    pub fn seen_by_views(&mut self) -> Result<Vec<bool>> {
        let mut seen = vec![false; self.scene.n as usize];
        self.each_view_visibility(true, |flags| {
            for (s, f) in seen.iter_mut().zip(flags) {
                *s |= *f != 0;
            }
            true
        })?;
        Ok(seen)
    }

    /// Whether some training view renders some Gaussian (stops at the first that does).
    pub fn some_view_sees_a_gaussian(&mut self) -> Result<bool> {
        let mut seen = false;
        self.each_view_visibility(false, |flags| {
            seen = flags.iter().any(|&f| f != 0);
            !seen
        })?;
        Ok(seen)
    }

    /// Renders the training views (`labeled_only`: those with a label map) in turn, handing
    /// each one's visibility flags (one per Gaussian) to `visit`, until it returns false.
    fn each_view_visibility(
        &mut self,
        labeled_only: bool,
        mut visit: impl FnMut(&[u32]) -> bool,
    ) -> Result<()> {
        let opts = RenderOptions {
            semantics: None,
            ..Default::default()
        };
        for vi in 0..self.views.len() {
            if labeled_only && !self.views[vi].labeled {
                continue;
            }
            let cam = self.views[vi].camera.clone();
            self.rasterizer
                .run_tiled(&self.scene, &cam, &opts, |_, _| Ok(()))?;
            if !visit(&self.rasterizer.last_visible_flags(self.scene.n)?) {
                break;
            }
        }
        Ok(())
    }

    /// Ends the run: the model, which Gaussians the training views see, the riders.
    pub fn finish(mut self) -> Result<TrainOutput> {
        let peak_device_bytes = self.gpu.memory_reserved();
        let gaussians = self.gaussians()?;
        let seen = self.seen_by_views()?;
        let riders = self
            .riders
            .iter()
            .map(|r| self.gpu.download::<f32>(r, 0, self.scene.n as usize))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(TrainOutput {
            gaussians,
            seen,
            riders,
            times: self.times,
            densify_events: self.events,
            peak_device_bytes,
        })
    }
}

/// How a run's semantic logits start where no fusion gives them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogitInit {
    /// All zero: every class equally likely, and the entropy regularizer's gradient zero
    /// (uniform is its maximum), so a Gaussian keeps them until the cross-entropy reaches it.
    Uniform,
    /// Small random values (Gaussian Semantics: "initialized with small random values"),
    /// standard deviation 0.01, from the run's seed. Under Adam (eps 1e-15, 3DGS's) the
    /// entropy regularizer's gradient on them, however small, moves a logit by the learning
    /// rate each iteration: every Gaussian the cross-entropy has not reached yet is sharpened
    /// toward its random first choice, whatever the warm-up's weight (docs/joint-training.md,
    /// "Where joint training's Gaussians go wrong").
    SmallRandom,
}

impl LogitInit {
    /// The start of a run that trains the logits alone (`semantics_only`) or with the
    /// geometry: uniform for the logits alone (their accuracy, measured, is all it changes);
    /// the paper's small random values with the geometry: the entropy term's sharpening of
    /// them keeps the cross-entropy's gradients into the geometry strong early, so the
    /// densification grows more Gaussians (higher PSNR, lower mIoU than uniform, measured).
    pub fn default_for(semantics_only: bool) -> LogitInit {
        match semantics_only {
            true => LogitInit::Uniform,
            false => LogitInit::SmallRandom,
        }
    }
}

/// Gives every Gaussian `channels` logits started as `start` says (`seed`: the random
/// values'), replacing any it had.
pub fn with_initial_logits(
    g: &Gaussians,
    channels: usize,
    start: LogitInit,
    seed: u64,
) -> Gaussians {
    let logits = match start {
        LogitInit::Uniform => vec![0.0; g.len() * channels],
        LogitInit::SmallRandom => {
            let mut rng = Rng::new(seed);
            (0..g.len() * channels)
                .map(|_| (rng.normal() * 0.01) as f32)
                .collect()
        }
    };
    let mut out = g.clone();
    out.semantics = Some(SemanticLogits { channels, logits });
    out.class_ids = None;
    out.class_conf = None;
    out
}

/// Confidence given a fused class that comes without one (`class_conf` missing, or not in
/// [0, 1)).
pub const FUSED_DEFAULT_CONF: f32 = 0.9;

/// `g` with semantic logits over `channels` classes that start where a fusion ended: a
/// Gaussian of compact class `c` with confidence `p` gets logit `ln(p (C - 1) / (1 - p))`
/// for `c` and 0 for the others, so the softmax of its logits gives `c` probability `p`
/// (capped at 0.999); a Gaussian without a class (unseen, or a class the labels lack) gets
/// zeros, the uniform distribution. Confidence 0 with a class (segment consensus's class
/// for a Gaussian no view saw, taken from its neighbours) is a class without evidence: it
/// starts with a lean to it, ln 2 (twice each other class's probability), so that training
/// keeps it where no view says otherwise (uniform, such Gaussians ended without a class:
/// 2,076 of a tiny room's 24k, held-out mIoU 0.917 -> 0.864 before any training).
pub fn with_logits_from_classes(
    g: &Gaussians,
    classes: &[Option<u32>],
    conf: Option<&[f32]>,
    channels: usize,
) -> Gaussians {
    let mut logits = vec![0.0f32; g.len() * channels];
    for (i, class) in classes.iter().enumerate() {
        let Some(c) = class.filter(|&c| (c as usize) < channels) else {
            continue;
        };
        let given = conf.map(|v| v[i]);
        if given == Some(0.0) {
            logits[i * channels + c as usize] = std::f32::consts::LN_2;
            continue;
        }
        let p = given
            .filter(|p| *p > 0.0 && *p < 1.0)
            .unwrap_or(FUSED_DEFAULT_CONF)
            .clamp(1.0 / channels as f32, 0.999) as f64;
        let others = (channels - 1).max(1) as f64;
        logits[i * channels + c as usize] = (p * others / (1.0 - p)).ln().max(0.0) as f32;
    }
    let mut out = g.clone();
    out.semantics = Some(SemanticLogits { channels, logits });
    out.class_ids = None;
    out.class_conf = None;
    out
}

/// Class (compact index) and confidence (softmax probability of the winner) per Gaussian
/// from its logits; None (confidence 0) where no view sees it or its top logits tie
/// exactly (uniform logits the cross-entropy never reached: a class id would break the tie).
pub fn classes_from_logits(g: &Gaussians, seen: &[bool]) -> (Vec<Option<u32>>, Vec<f32>) {
    let Some(s) = &g.semantics else {
        return (vec![None; g.len()], vec![0.0; g.len()]);
    };
    let c = s.channels;
    (0..g.len())
        .map(|i| {
            let row = &s.logits[i * c..(i + 1) * c];
            let (best, &max) = row
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .expect("channels > 0");
            let tied = row.iter().filter(|&&v| v == max).count() > 1;
            let sum: f32 = row.iter().map(|v| (v - max).exp()).sum();
            if seen.get(i).copied().unwrap_or(false) && !tied {
                (Some(best as u32), 1.0 / sum)
            } else {
                (None, 0.0)
            }
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::random_scene::{random_scene, RandomSceneSpec};

    fn softmax(l: &[f32]) -> Vec<f64> {
        let e: Vec<f64> = l.iter().map(|&x| (x as f64).exp()).collect();
        let sum: f64 = e.iter().sum();
        e.iter().map(|x| x / sum).collect()
    }

    #[test]
    fn logits_from_fused_classes_give_back_class_and_confidence() {
        let g = random_scene(&RandomSceneSpec {
            n: 6,
            ..Default::default()
        });
        let classes = [Some(2), None, Some(0), Some(7), Some(1), Some(3)];
        let conf = [0.8, 0.5, 0.0, 0.9, 1.0, -0.5];
        let out = with_logits_from_classes(&g, &classes, Some(&conf), 4);
        let s = out.semantics.expect("logits");
        let probs = |i: usize| softmax(&s.logits[i * 4..(i + 1) * 4]);
        assert!((probs(0)[2] - 0.8).abs() < 1e-5, "{:?}", probs(0));
        // No class, or one past the channels: uniform.
        for i in [1, 3] {
            assert!(probs(i).iter().all(|p| (p - 0.25).abs() < 1e-6), "{i}");
        }
        // A class no view gave (confidence 0): twice as likely as each other class.
        assert!((probs(2)[0] - 0.4).abs() < 1e-6 && (probs(2)[1] - 0.2).abs() < 1e-6);
        // A confidence outside [0, 1) falls back to the default; 1.0 is no certainty.
        assert!((probs(4)[1] - FUSED_DEFAULT_CONF as f64).abs() < 1e-5);
        assert!((probs(5)[3] - FUSED_DEFAULT_CONF as f64).abs() < 1e-5);
        assert!(out.class_ids.is_none());
    }

    /// A tie at the top is no class (a class id would break it), whatever the ids; a clear
    /// top is its class with its softmax probability; an unseen Gaussian none.
    #[test]
    fn classes_from_logits_leave_ties_and_unseen_without_a_class() {
        let g = random_scene(&RandomSceneSpec {
            n: 5,
            ..Default::default()
        });
        let rows = [
            [0.0, 0.0, 0.0],  // uniform: tied
            [0.5, -1.0, 0.5], // tied top, first and last
            [0.1, 0.3, -0.2], // class 1
            [2.0, 0.0, 0.0],  // class 0, but unseen
            [0.0, 0.0, 1e-6], // class 2 by a hair
        ];
        let mut g = with_initial_logits(&g, 3, LogitInit::Uniform, 0);
        g.semantics.as_mut().unwrap().logits = rows.concat();
        let seen = [true, true, true, false, true];
        let (classes, conf) = classes_from_logits(&g, &seen);
        assert_eq!(classes, [None, None, Some(1), None, Some(2)]);
        let p1 = softmax(&rows[2])[1] as f32;
        assert!((conf[2] - p1).abs() < 1e-6, "{conf:?}");
        assert_eq!([conf[0], conf[1], conf[3]], [0.0; 3]);
    }

    /// Uniform logits are all zero; small random ones differ from Gaussian to Gaussian,
    /// about 0.01 in size, the same for the same seed.
    #[test]
    fn initial_logits_uniform_or_small_random() {
        let g = random_scene(&RandomSceneSpec {
            n: 200,
            ..Default::default()
        });
        let logits = |start, seed| {
            let out = with_initial_logits(&g, 4, start, seed);
            out.semantics.unwrap().logits
        };
        assert!(logits(LogitInit::Uniform, 1).iter().all(|&v| v == 0.0));
        let random = logits(LogitInit::SmallRandom, 1);
        assert_eq!(random, logits(LogitInit::SmallRandom, 1));
        assert_ne!(random, logits(LogitInit::SmallRandom, 2));
        let rms = (random.iter().map(|v| v * v).sum::<f32>() / random.len() as f32).sqrt();
        assert!((0.008..0.012).contains(&rms), "{rms}");
    }
}
