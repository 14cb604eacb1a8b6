//! The GPU backward pass: blending backward (per tile, back to front, subgroup-reduced
//! atomics into screen-space gradients) then projection backward (per Gaussian, into the
//! stored parameters). Recorded into the same submission as the forward that produced the
//! tile lists, so an iteration needs no host round trip.
//!
//! The blend backward adds per-Gaussian sums from many tiles at once. By default
//! ([`Accumulation::FixedPoint`]) it adds them as 64-bit fixed-point integers, whose sums
//! do not depend on the order of the atomics: the gradients are bit-identical run to run.
//! The scale of each value group follows the gradients' magnitudes ([`FixedScale`]).

use anyhow::{bail, ensure, Result};

use super::chunks::{chunks, part_of};
use super::frame::RenderedFrame;
use super::gpu_scene::{GaussianParams, GpuScene, HostParams, ParamTensor};
use super::rasterizer::{Rasterizer, TileLists, RGB_BYTES};
use super::{project_params, RenderOptions, SemanticMode};
use crate::contract::params::{BlendParams, FixedResolveParams, SoftmaxBackwardParams};
use crate::contract::{
    FIXED_GROUPS, FIXED_PARAM_WORDS, FS_NONFINITE, FS_OVERFLOW, FS_STEP_MAX, FS_TOTAL_MAX,
    FS_WORDS, SEM_CHUNK, TILE_SIZE,
};
use crate::gpu::kernel_table::{ids, Kernel};
use crate::gpu::recorder::with_optional;
use crate::gpu::{Buffer, BufferRange, Gpu, Recorder};
use crate::scene::Camera;

pub use crate::contract::GRAD2D_STRIDE;
/// Floats carried per pixel between backward windows: T, S_rgb, S_sem chunk.
const CARRY_STRIDE: u64 = crate::contract::BACKWARD_CARRY_STRIDE as u64;

/// Bytes per pixel of the state the backward carries between windows of a frame walked
/// in `windows` windows (0 with one: the carry buffer is then a placeholder).
fn carry_bytes_per_pixel(windows: u32) -> u64 {
    if windows > 1 {
        CARRY_STRIDE * 4
    } else {
        0
    }
}

/// Upstream gradients per pixel, on the device: dL/d(rgb) [P*3], dL/d(accumulated alpha)
/// [P], and dL/d(normalized semantics) [P*C] (any buffer when C = 0).
pub struct PixelGrads<'a> {
    pub rgb: &'a Buffer,
    pub alpha: &'a Buffer,
    pub sem_norm: &'a Buffer,
}

/// Gradients of a scene's parameters, summed over the views recorded since the last
/// [`SceneGrads::record_zero`], plus the 3DGS densification statistics.
pub struct SceneGrads {
    pub n: u32,
    pub channels: u32,
    pub sh_coeffs: u32,
    /// dL/d of each parameter tensor, named `grad_` + the tensor's name.
    pub params: GaussianParams<Buffer>,
    /// dL/d(logits) [n*C].
    pub logits: Buffer,
    /// dL/d(softmax probabilities) [n*C], the blended vectors of the softmax mode.
    probs: Buffer,
    /// Sum over views of |dL/d(mean2d)| in NDC units, and the number of views that saw
    /// each Gaussian.
    pub densify_grad: Buffer,
    pub densify_count: Buffer,
    /// One view's screen-space gradients, [n * GRAD2D_STRIDE].
    pub screen: Buffer,
    carry: Buffer,
    placeholder: Buffer,
    /// How the blend backward adds its sums (see [`Accumulation`]).
    pub accumulation: Accumulation,
    /// Fixed-point sums of one view, two u32 words per value (FixedPoint only).
    screen_fixed: Buffer,
    sem_fixed: Buffer,
    /// Scales and overflow status of the fixed-point sums.
    pub fixed: FixedScale,
    /// Compute only the semantic vectors' gradient (training the logits with geometry
    /// frozen): a cheaper blend backward and no projection backward.
    pub semantics_only: bool,
}

/// How the blend backward adds per-Gaussian sums across tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Accumulation {
    /// 64-bit fixed-point integers (int64 atomics, or a pair of 32-bit ones where the
    /// device lacks them): order-independent, so training is reproducible. The default.
    FixedPoint,
    /// float32 atomic adds: the sums depend on the order the atomics land in.
    FloatAtomics,
    /// Compare-and-swap on the float bits (devices without float atomics); order-dependent.
    CompareAndSwap,
}

impl Accumulation {
    /// `deterministic` picks FixedPoint; otherwise float atomics where the device has them.
    pub fn choose(gpu: &Gpu, deterministic: bool) -> Accumulation {
        if deterministic {
            Accumulation::FixedPoint
        } else if gpu.caps().float_atomic_add {
            Accumulation::FloatAtomics
        } else {
            Accumulation::CompareAndSwap
        }
    }
}

/// Bits of headroom between the largest per-Gaussian total seen and the bound on one
/// step's scaled value: steps may exceed totals (sums that cancel) and gradients grow
/// between iterations; past the bound the view is redone with a smaller scale.
const FIXED_HEADROOM_BITS: i32 = 10;
/// The 64-bit sums stay below 2^62 (room for the sign and a margin).
const FIXED_TOTAL_BITS: u32 = 62;
/// A view is redone at most this many times for fixed-point overflow.
pub const FIXED_MAX_REDOS: u32 = 8;

/// The fixed-point scale per value group (mean2d, conic, opacity, color, semantics):
/// scale = 2^e with e = step_bits - FIXED_HEADROOM_BITS - ceil(log2(magnitude)), where
/// magnitude is the largest |per-Gaussian total| of the group in the last view (1 before
/// the first) and 2^step_bits bounds one step's |value * scale| so that a view's adds
/// (at most one per padded pixel and semantic chunk) keep every total below 2^62.
pub struct FixedScale {
    /// ceil(log2) of each group's magnitude.
    log2_magnitude: [i32; FIXED_GROUPS as usize],
    /// The current view's step bound exponent.
    step_bits: u32,
    /// [scale per group, 2^step_bits] (f32, FIXED_PARAM_WORDS).
    params: Buffer,
    /// FS_WORDS u32 (shared_constants.txt): overflow and non-finite flags, magnitudes.
    pub status: Buffer,
}

/// What a view's fixed-point status says (see [`FixedScale::check`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FixedCheck {
    /// The sums are exact; the scales follow the totals' magnitudes for the next view.
    Done,
    /// A step did not fit: the scales of the groups that overflowed were lowered, and the
    /// view must be recorded again (its gradients and statistics were not applied).
    Redo,
    /// A step's value was NaN or infinite.
    NonFinite,
}

impl FixedScale {
    fn new(gpu: &Gpu) -> Result<FixedScale> {
        let scale = FixedScale {
            log2_magnitude: [0; FIXED_GROUPS as usize],
            step_bits: 32,
            params: gpu.buffer("fixed_params", FIXED_PARAM_WORDS as u64 * 4)?,
            status: gpu.buffer("fixed_status", FS_WORDS as u64 * 4)?,
        };
        let mut rec = Recorder::new(gpu)?;
        rec.fill(&scale.status, 0, scale.status.size(), 0);
        rec.submit_and_wait()?;
        Ok(scale)
    }

    /// Sets the step bound for views of `width` x `height` walked in `chunks` semantic
    /// chunks; errors if no bound leaves room for a useful scale.
    fn set_view(&mut self, width: u32, height: u32, chunks: u32) -> Result<()> {
        let padded = |v: u32| v.div_ceil(TILE_SIZE) as u64 * TILE_SIZE as u64;
        let adds = padded(width) * padded(height) * chunks.max(1) as u64;
        let add_bits = 64 - (adds - 1).leading_zeros(); // ceil(log2(adds))
        ensure!(
            add_bits + 24 <= FIXED_TOTAL_BITS,
            "a {width}x{height} view is too large for deterministic (fixed-point) gradients; \
             train without --deterministic"
        );
        self.step_bits = FIXED_TOTAL_BITS - add_bits;
        Ok(())
    }

    fn exponent(&self, group: usize) -> i32 {
        let e = self.step_bits as i32 - FIXED_HEADROOM_BITS - self.log2_magnitude[group];
        e.clamp(-120, 120)
    }

    /// Records the upload of the current scales (before the view's blend backward).
    fn record_params(&self, rec: &mut Recorder) {
        let mut words = [0f32; FIXED_PARAM_WORDS as usize];
        for (g, w) in words.iter_mut().take(FIXED_GROUPS as usize).enumerate() {
            *w = 2f32.powi(self.exponent(g));
        }
        words[FIXED_GROUPS as usize] = 2f32.powi(self.step_bits as i32);
        rec.update(&self.params, 0, bytemuck::cast_slice(&words));
    }

    /// Records the clearing of the status (start of a gradient accumulation).
    pub fn record_clear(&self, rec: &mut Recorder) {
        rec.fill(&self.status, 0, self.status.size(), 0);
    }

    /// Reads the status of the views recorded since [`FixedScale::record_clear`] and
    /// adapts the scales to the magnitudes it holds.
    pub fn check(&mut self, gpu: &Gpu) -> Result<FixedCheck> {
        let status: Vec<u32> = gpu.download(&self.status, 0, FS_WORDS as usize)?;
        if status[FS_NONFINITE as usize] != 0 {
            return Ok(FixedCheck::NonFinite);
        }
        let magnitude = |word: u32| {
            let m = f32::from_bits(status[word as usize]);
            (m > 0.0 && m.is_finite()).then(|| m.log2().ceil() as i32)
        };
        if status[FS_OVERFLOW as usize] != 0 {
            for g in 0..FIXED_GROUPS as usize {
                if let Some(bits) = magnitude(FS_STEP_MAX + g as u32) {
                    // The step's own magnitude, and at least one bit lower than before.
                    let lowered = self.log2_magnitude[g] + 1;
                    self.log2_magnitude[g] = bits.max(lowered);
                }
            }
            return Ok(FixedCheck::Redo);
        }
        for g in 0..FIXED_GROUPS as usize {
            if let Some(bits) = magnitude(FS_TOTAL_MAX + g as u32) {
                self.log2_magnitude[g] = bits;
            }
        }
        Ok(FixedCheck::Done)
    }

    /// The scales of `other` (a model rebuilt by densification keeps its magnitudes).
    pub fn adopt(&mut self, other: &FixedScale) {
        self.log2_magnitude = other.log2_magnitude;
    }
}

/// Gradients downloaded to the host (tests, diagnostics).
#[derive(Clone, Debug, Default)]
pub struct HostGrads {
    pub params: HostParams,
    pub logits: Vec<f32>,
    /// The last view's screen-space gradients, GRAD2D_STRIDE per Gaussian.
    pub screen: Vec<f32>,
    pub densify_grad: Vec<f32>,
    pub densify_count: Vec<f32>,
}

impl SceneGrads {
    /// Zeroed gradients for `scene`'s shape.
    pub fn new(gpu: &Gpu, scene: &GpuScene, accumulation: Accumulation) -> Result<SceneGrads> {
        let n = scene.n.max(1) as u64;
        let c = scene.channels.max(1) as u64;
        let b = |name: &str, floats: u64| gpu.buffer(name, floats * 4);
        let sh_coeffs = scene.sh_coeffs.max(1);
        // The fixed-point sums take two words per value, only in that mode.
        let fixed_words = |floats: u64| match accumulation {
            Accumulation::FixedPoint => floats * 2,
            _ => 1,
        };
        let grads = SceneGrads {
            n: scene.n,
            channels: scene.channels,
            sh_coeffs: scene.sh_coeffs,
            params: GaussianParams::try_from_fn(|p| {
                b(
                    &format!("grad_{}", p.name()),
                    n * p.floats(sh_coeffs) as u64,
                )
            })?,
            logits: b("grad_logits", n * c)?,
            probs: b("grad_probs", n * c)?,
            densify_grad: b("densify_grad", n)?,
            densify_count: b("densify_count", n)?,
            screen: b("grad2d", n * GRAD2D_STRIDE as u64)?,
            carry: b("backward_carry", 1)?,
            placeholder: b("placeholder", 4)?,
            screen_fixed: b("grad2d_fixed", fixed_words(n * GRAD2D_STRIDE as u64))?,
            sem_fixed: b("grad_sem_fixed", fixed_words(n * c))?,
            fixed: FixedScale::new(gpu)?,
            accumulation,
            semantics_only: false,
        };
        let mut rec = Recorder::new(gpu)?;
        grads.record_zero(&mut rec);
        grads.record_zero_densify(&mut rec);
        rec.submit_and_wait()?;
        Ok(grads)
    }

    /// Sizes the per-pixel carry buffer for views of `cam`'s size walked in `windows`
    /// windows (only needed when a tile list spans more than one window), and sets the
    /// fixed-point range for the view.
    pub fn prepare_view(&mut self, gpu: &Gpu, cam: &Camera, windows: u32) -> Result<()> {
        let pixels = cam.width as u64 * cam.height as u64;
        let chunks = self.channels.div_ceil(SEM_CHUNK);
        self.fixed.set_view(cam.width, cam.height, chunks)?;
        let need = (pixels * carry_bytes_per_pixel(windows)).max(4);
        if self.carry.size() < need {
            self.carry = gpu.buffer("backward_carry", need)?;
        }
        Ok(())
    }

    /// Records zeroing of the parameter gradients and the fixed-point status (start of an
    /// iteration).
    pub fn record_zero(&self, rec: &mut Recorder) {
        self.fixed.record_clear(rec);
        let semantic = [&self.logits, &self.probs];
        for b in self
            .params
            .as_ref()
            .into_array()
            .into_iter()
            .chain(semantic)
        {
            rec.fill(b, 0, b.size(), 0);
        }
        rec.barrier();
    }

    /// Records zeroing of the densification statistics.
    pub fn record_zero_densify(&self, rec: &mut Recorder) {
        for b in [&self.densify_grad, &self.densify_count] {
            rec.fill(b, 0, b.size(), 0);
        }
        rec.barrier();
    }

    /// Records the softmax backward that turns the probabilities' gradient into the
    /// logits' (softmax mode; once per iteration, after every view's backward).
    pub fn record_softmax_backward(&self, rec: &mut Recorder, scene: &GpuScene) -> Result<()> {
        let Some(probs) = scene.probs.get() else {
            return Ok(()); // nothing was rendered in softmax mode
        };
        rec.dispatch(
            ids::RASTER_SOFTMAX_BACKWARD,
            &[],
            &SoftmaxBackwardParams {
                n: self.n,
                channels: self.channels,
                probs_addr: probs.address_words(4)?,
                grad_probs_addr: self.probs.address_words(4)?,
                grad_logits_addr: self.logits.address_words(4)?,
            },
            ids::RASTER_SOFTMAX_BACKWARD.groups_for(self.n),
        )?;
        rec.barrier();
        Ok(())
    }

    /// Downloads every gradient.
    pub fn download(&self, gpu: &Gpu) -> Result<HostGrads> {
        let n = self.n as u64;
        let c = self.channels as u64;
        let extra = [
            (&self.logits, 0, n * c * 4),
            (&self.screen, 0, n * GRAD2D_STRIDE as u64 * 4),
            (&self.densify_grad, 0, n * 4),
            (&self.densify_count, 0, n * 4),
        ];
        let (params, extra) = self
            .params
            .download_with(gpu, self.n, self.sh_coeffs, &extra)?;
        let [logits, screen, densify_grad, densify_count] =
            <[Vec<f32>; 4]>::try_from(extra).expect("one part per extra range");
        Ok(HostGrads {
            params,
            logits,
            screen,
            densify_grad,
            densify_count,
        })
    }
}

impl TileLists<'_> {
    /// Records the backward pass of the view these lists hold, after its forward blend
    /// ([`TileLists::record_blend`]): adds the view's parameter gradients into `grads`.
    /// `upstream` holds dL/d of the view's outputs.
    pub fn record_backward(
        &self,
        rec: &mut Recorder,
        scene: &GpuScene,
        upstream: &PixelGrads,
        grads: &SceneGrads,
    ) -> Result<()> {
        ensure!(
            grads.n == scene.n && grads.channels == scene.channels,
            "gradient buffers were made for another scene"
        );
        let f = &self.frame;
        let pixels = f.cam.width as u64 * f.cam.height as u64;
        ensure!(
            grads.carry.size() >= pixels * carry_bytes_per_pixel(f.windows),
            "SceneGrads::prepare_view was not called for this view size"
        );
        let fixed = grads.accumulation == Accumulation::FixedPoint;
        rec.fill(&grads.screen, 0, grads.screen.size(), 0);
        if fixed {
            rec.fill(&grads.screen_fixed, 0, grads.screen_fixed.size(), 0);
            rec.fill(&grads.sem_fixed, 0, grads.sem_fixed.size(), 0);
            grads.fixed.record_params(rec);
        }
        rec.barrier();
        self.record_blend_backward(rec, upstream, grads)?;
        if fixed {
            self.record_fixed_resolve(rec, grads)?;
        }
        if grads.semantics_only {
            return Ok(());
        }
        self.record_project_backward(rec, scene, f.cam, grads)
    }

    /// The per-tile half of the backward: every semantic chunk, windows back to front.
    fn record_blend_backward(
        &self,
        rec: &mut Recorder,
        upstream: &PixelGrads,
        grads: &SceneGrads,
    ) -> Result<()> {
        let f = &self.frame;
        let sem_target = match f.semantics {
            Some((SemanticMode::RawLogits, _)) => &grads.logits,
            Some((SemanticMode::Softmax, _)) => &grads.probs,
            None => &grads.placeholder,
        };
        let sem_norm = if f.channels > 0 {
            self.sem_norm()
        } else {
            &grads.placeholder
        };
        let kernel = backward_kernel(grads, rec.gpu());
        // The fixed-point variants add into their integer buffers instead.
        let (screen_target, sem_target) = match grads.accumulation {
            Accumulation::FixedPoint => (&grads.screen_fixed, &grads.sem_fixed),
            _ => (&grads.screen, sem_target),
        };
        // Element sizes for the index bound only: the kernels index 32-bit words.
        let grad2d_addr = screen_target.address_words(4)?;
        let grad_sem_addr = sem_target.address_words(4)?;
        // Bands of tile rows whose per-pixel buffers each fit one binding (the widest:
        // the carried state, the semantic channels or RGB).
        let (sem_bytes, carry_bytes) = (f.channels as u64 * 4, carry_bytes_per_pixel(f.windows));
        let bands = f.bands(RGB_BYTES.max(sem_bytes).max(carry_bytes))?;
        let windows = self.pass_windows(rec, &bands)?;
        for chunk in 0..f.sem_chunks() {
            for (window, start) in f.window_starts().rev() {
                let params = BlendParams {
                    grad2d_addr,
                    grad_sem_addr,
                    ..self.blend_params(start, chunk, false)?
                };
                for (band_index, band) in bands.iter().enumerate() {
                    let params = BlendParams {
                        tile_row_base: band.first_tile_row,
                        ..params
                    };
                    let px = |buf, bytes_per_pixel| band.range_or_whole(buf, bytes_per_pixel);
                    let bindings = [
                        ("tile_ranges", BufferRange::whole(self.ranges())),
                        ("isect_ids", BufferRange::whole(self.isect_ids())),
                        ("final_t", px(self.final_t(), 4)),
                        ("last_entry", px(self.last_entry(), 4)),
                        ("n_contrib", px(self.n_contrib(), 4)),
                        ("v_sem_norm", px(upstream.sem_norm, sem_bytes)),
                        ("carry", px(&grads.carry, carry_bytes)),
                    ];
                    // What the alpha, color and screen-space gradients read and write (not
                    // the semantic-only variant).
                    let optional = [
                        ("sem_norm", px(sem_norm, sem_bytes)),
                        ("v_rgb", px(upstream.rgb, RGB_BYTES)),
                        ("v_alpha", px(upstream.alpha, 4)),
                        ("fixed_params", BufferRange::whole(&grads.fixed.params)),
                        ("fixed_status", BufferRange::whole(&grads.fixed.status)),
                    ];
                    let bindings = with_optional(kernel, &bindings, &optional);
                    windows.dispatch(rec, kernel, &bindings, &params, (window, band_index))?;
                }
                rec.barrier();
            }
        }
        Ok(())
    }

    /// Turns the view's fixed-point sums into the float gradients: the screen-space ones
    /// (overwritten: one view) and the semantic ones (added to what earlier views left).
    fn record_fixed_resolve(&self, rec: &mut Recorder, grads: &SceneGrads) -> Result<()> {
        let sem_target = match self.frame.semantics {
            Some((SemanticMode::RawLogits, _)) => Some(&grads.logits),
            Some((SemanticMode::Softmax, _)) => Some(&grads.probs),
            None => None,
        };
        let screen = (!grads.semantics_only).then_some((&grads.screen_fixed, &grads.screen));
        let semantic = sem_target.map(|t| (&grads.sem_fixed, t));
        for (semantic_rows, parts) in [(false, screen), (true, semantic)] {
            let Some((fixed, target)) = parts else {
                continue;
            };
            let params = FixedResolveParams {
                rows: grads.n,
                stride: if semantic_rows {
                    grads.channels
                } else {
                    GRAD2D_STRIDE
                },
                semantic: semantic_rows as u32,
                accumulate: semantic_rows as u32,
                fixed_sums_addr: fixed.address_words(8)?,
                out_grad_addr: target.address_words(4)?,
            };
            rec.dispatch(
                ids::TRAIN_GRAD_FIXED_RESOLVE,
                &[
                    ("fixed_params", &grads.fixed.params),
                    ("fixed_status", &grads.fixed.status),
                ],
                &params,
                ids::TRAIN_GRAD_FIXED_RESOLVE.groups_for(grads.n),
            )?;
        }
        rec.barrier();
        Ok(())
    }

    /// The projection's backward, in chunks of Gaussians whose per-Gaussian ranges each fit
    /// one binding (as the forward projection's).
    fn record_project_backward(
        &self,
        rec: &mut Recorder,
        scene: &GpuScene,
        cam: &Camera,
        grads: &SceneGrads,
    ) -> Result<()> {
        // The backward culls nothing itself: it reads the forward's visibility flags.
        let mut params = project_params(cam, scene, 0.0, f32::INFINITY);
        for range in chunks(scene.n, self.frame.gaussian_chunk) {
            params.n = range.len() as u32;
            let per_gaussian = |buf, bytes: u64| part_of(buf, &range, bytes);
            let grad = |p: ParamTensor| {
                per_gaussian(&grads.params[p], p.floats(scene.sh_coeffs) as u64 * 4)
            };
            let param = |p: ParamTensor| scene.param_range(p, &range);
            rec.dispatch_ranges(
                ids::RASTER_PROJECT_BACKWARD,
                &[
                    ("means", param(ParamTensor::Means)),
                    ("log_scales", param(ParamTensor::LogScales)),
                    ("quats", param(ParamTensor::Quats)),
                    ("opacity_logits", param(ParamTensor::OpacityLogits)),
                    ("sh", param(ParamTensor::Sh)),
                    ("visible", per_gaussian(self.visible_flags(), 4)),
                    (
                        "grad2d",
                        per_gaussian(&grads.screen, GRAD2D_STRIDE as u64 * 4),
                    ),
                    ("grad_means", grad(ParamTensor::Means)),
                    ("grad_log_scales", grad(ParamTensor::LogScales)),
                    ("grad_quats", grad(ParamTensor::Quats)),
                    ("grad_opacity_logits", grad(ParamTensor::OpacityLogits)),
                    ("grad_sh", grad(ParamTensor::Sh)),
                    ("densify_grad", per_gaussian(&grads.densify_grad, 4)),
                    ("densify_count", per_gaussian(&grads.densify_count, 4)),
                    ("fixed_status", BufferRange::whole(&grads.fixed.status)),
                    ("raster_status", self.status()),
                ],
                &params,
                ids::RASTER_PROJECT_BACKWARD.groups_for(params.n),
            )?;
        }
        rec.barrier();
        Ok(())
    }
}

/// Which backward kernels [`Rasterizer::render_backward`] runs.
#[derive(Clone, Copy, Debug)]
pub struct BackwardVariant {
    /// true: the deterministic fixed-point accumulation (float_atomics is then ignored).
    pub deterministic: bool,
    /// false: the compare-and-swap accumulation, as on devices without float atomics.
    pub float_atomics: bool,
    /// Only the semantic vectors' gradient (see [`SceneGrads::semantics_only`]).
    pub semantics_only: bool,
}

impl Default for BackwardVariant {
    fn default() -> Self {
        BackwardVariant {
            deterministic: true,
            float_atomics: true,
            semantics_only: false,
        }
    }
}

/// Upstream gradients on the host, for [`Rasterizer::render_backward`].
pub struct HostPixelGrads<'a> {
    pub rgb: &'a [f32],
    pub alpha: &'a [f32],
    pub sem_norm: &'a [f32],
}

impl Rasterizer {
    /// Renders one view and back-propagates the given per-pixel gradients through it, in
    /// one submission; returns the frame and the parameter gradients (tests, tools).
    pub fn render_backward(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        upstream: &HostPixelGrads,
        variant: BackwardVariant,
    ) -> Result<(RenderedFrame, HostGrads)> {
        let gpu = self.gpu().clone();
        let pixels = cam.width as u64 * cam.height as u64;
        let channels = match opts.semantics {
            Some(_) => scene.channels,
            None => 0,
        };
        ensure!(
            upstream.rgb.len() as u64 == pixels * 3
                && upstream.alpha.len() as u64 == pixels
                && upstream.sem_norm.len() as u64 == pixels * channels as u64,
            "upstream gradients do not match the view ({} pixels, {channels} channels)",
            pixels
        );
        let v_rgb = gpu.buffer_from("v_rgb", upstream.rgb)?;
        let v_alpha = gpu.buffer_from("v_alpha", upstream.alpha)?;
        let v_sem = if channels > 0 {
            gpu.buffer_from("v_sem_norm", upstream.sem_norm)?
        } else {
            gpu.buffer("v_sem_norm", 4)?
        };
        let accumulation = match (variant.deterministic, variant.float_atomics) {
            (true, _) => Accumulation::FixedPoint,
            (false, true) if gpu.caps().float_atomic_add => Accumulation::FloatAtomics,
            (false, _) => Accumulation::CompareAndSwap,
        };
        let mut grads = SceneGrads::new(&gpu, scene, accumulation)?;
        grads.semantics_only = variant.semantics_only;
        grads.prepare_view(&gpu, cam, self.windows_for(scene.n))?;
        let pixel_grads = PixelGrads {
            rgb: &v_rgb,
            alpha: &v_alpha,
            sem_norm: &v_sem,
        };
        let mut redos = 0;
        let run = loop {
            let run = self.run_tiled(scene, cam, opts, |rec, tiles| {
                tiles.record_blend(rec)?;
                grads.record_zero(rec);
                // The densification statistics are not cleared per attempt (as in training,
                // where they sum over iterations): an overflowed attempt adds nothing to them.
                tiles.record_backward(rec, scene, &pixel_grads, &grads)
            })?;
            match grads.fixed.check(&gpu)? {
                FixedCheck::Done => break run,
                FixedCheck::NonFinite => bail!("a gradient of view {} is not finite", cam.name),
                FixedCheck::Redo => {
                    redos += 1;
                    ensure!(
                        redos <= FIXED_MAX_REDOS,
                        "view {}: the fixed-point gradients overflow at every scale tried",
                        cam.name
                    );
                }
            }
        };
        let mut rec = Recorder::new(&gpu)?;
        grads.record_softmax_backward(&mut rec, scene)?;
        rec.submit_and_wait()?;
        let frame = self.download_frame(cam, &run)?;
        Ok((frame, grads.download(&gpu)?))
    }
}

/// The blend-backward variant for `grads`' accumulation (fixed point with 64-bit atomics
/// where the device has them) and parameters (all, or the semantic vectors only), in the
/// device's per-tile form ([`Kernel::for_device`]).
fn backward_kernel(grads: &SceneGrads, gpu: &Gpu) -> Kernel<BlendParams> {
    let int64_atomics = gpu.caps().int64_atomics;
    let (narrow, wide) = match (grads.semantics_only, grads.accumulation) {
        (false, Accumulation::FloatAtomics) => {
            (ids::RASTER_BLEND_BACKWARD, ids::RASTER_BLEND_BACKWARD_WIDE)
        }
        (false, Accumulation::CompareAndSwap) => (
            ids::RASTER_BLEND_BACKWARD_CAS,
            ids::RASTER_BLEND_BACKWARD_CAS_WIDE,
        ),
        (false, Accumulation::FixedPoint) if int64_atomics => (
            ids::RASTER_BLEND_BACKWARD_FIXED64,
            ids::RASTER_BLEND_BACKWARD_FIXED64_WIDE,
        ),
        (false, Accumulation::FixedPoint) => (
            ids::RASTER_BLEND_BACKWARD_FIXED32X2,
            ids::RASTER_BLEND_BACKWARD_FIXED32X2_WIDE,
        ),
        (true, Accumulation::FloatAtomics) => (
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY,
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY_WIDE,
        ),
        (true, Accumulation::CompareAndSwap) => (
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY_CAS,
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY_CAS_WIDE,
        ),
        (true, Accumulation::FixedPoint) if int64_atomics => (
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY_FIXED64,
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY_FIXED64_WIDE,
        ),
        (true, Accumulation::FixedPoint) => (
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY_FIXED32X2,
            ids::RASTER_BLEND_BACKWARD_SEM_ONLY_FIXED32X2_WIDE,
        ),
    };
    narrow.for_device(wide, gpu)
}
