//! The training losses of Gaussian Semantics (Sec. 3.4) on the device, recorded into the caller's
//! Recorder without host syncs: the 3DGS photometric loss 0.8 L1 + 0.2 (1 - SSIM), the
//! semantic cross-entropy on the normalized semantic image, and (loss_entropy.rs) the
//! per-Gaussian entropy regularizer. Each writes its gradient and the partial sums of its
//! value; `ImageLoss::read_values` fetches every value with one download afterwards.
//!
//! Kernels (glsl/train/): ssim_blur_inputs -> ssim_forward -> ssim_blur_grads ->
//! ssim_backward for L1 + SSIM (separable 11-tap blurs, the backward blurs the per-pixel
//! partials with the same window); loss_count_labels -> loss_cross_entropy for the
//! semantic term; loss_reduce adds each workgroup's partials in a fixed order.

use anyhow::{bail, ensure, Result};

pub use super::loss_entropy::entropy_weight;
pub use super::loss_values::LossValues;
use super::loss_values::{L1_WEIGHT, SLOTS, SLOT_CE, SLOT_L1, SLOT_LABELED, SLOT_SE, SSIM_WEIGHT};
use crate::contract::params::{
    BlurGradsParams, BlurInputsParams, CountLabelsParams, CrossEntropyParams, LossReduceParams,
    SsimBackwardParams, SsimForwardParams,
};
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, Recorder};
use crate::render::SemanticMode;

/// Invocations per workgroup of the 1D loss kernels.
pub(crate) use crate::contract::LOSS_WG;
/// Edge of the 2D workgroups of the ssim_* kernels.
use crate::contract::SSIM_TILE as TILE;
/// Most workgroups one dispatch dimension may have on every Vulkan device.
const MAX_GROUPS: u32 = 65_535;
/// Loop iterations we let one invocation run: lavapipe ends every loop of an invocation
/// after 65,535 iterations in total, silently (docs/TOOLCHAIN.md).
pub(crate) const LOOP_BUDGET: u64 = 60_000;
/// Moment planes the SSIM forward blurs: x, y, x^2, y^2, xy.
const MOMENT_PLANES: u64 = 5;
/// Moment gradients the SSIM backward blurs: d/d blur(x), blur(x^2), blur(xy).
const GRAD_PLANES: u64 = 3;

/// The semantic term of one view: the buffers and how to read them.
#[derive(Clone, Copy)]
pub struct SemanticTerm<'a> {
    /// The normalized rendered semantic image, f32 [pixels * channels], channel fastest.
    pub sem_norm: &'a Buffer,
    /// Compact class per pixel, u32 [pixels]; [`IGNORE_LABEL`] (or any value >= channels)
    /// leaves the pixel out.
    pub labels: &'a Buffer,
    /// RawLogits: sem_norm holds logits (CE of their softmax); Softmax: sem_norm already
    /// holds a distribution (CE = -log max(p, 1e-6)).
    pub mode: SemanticMode,
    /// lambda_sem: scales the gradient (the logged CE value is unweighted).
    pub lambda: f32,
    /// Gets dL/d sem_norm, f32 [pixels * channels]; overwritten, zero on ignored pixels.
    pub v_sem_norm: &'a Buffer,
}

/// A pixel without a label.
pub use crate::dataset::NO_LABEL as IGNORE_LABEL;

/// The photometric loss's images: the render, its target, and the gradient written back.
struct RgbImages<'a> {
    rgb: &'a Buffer,
    target: &'a Buffer,
    v_rgb: &'a Buffer,
}

/// The loss scratch for views of one size (W x H, C semantic channels), and the values
/// buffer every loss term of an iteration leaves its mean in.
pub struct ImageLoss {
    pub(crate) gpu: Gpu,
    width: u32,
    height: u32,
    pub(crate) channels: u32,
    /// [5][pixels][3] blurred moments; the SSIM backward reuses its first three planes.
    moments: Buffer,
    /// [3][pixels][3] dL/d(blurred moment) per pixel and channel.
    moment_grads: Buffer,
    /// [SLOTS][stride] one partial sum per workgroup and slot.
    pub(crate) partials: Buffer,
    /// [SLOT_LABELED + 1][stride]: the labeled count's partials, apart from `partials` so
    /// their reduce runs beside the SSIM forward writing those: in one buffer the
    /// synchronization validation (which sees whole bindings, not slots) reports a
    /// write-after-read hazard.
    count_partials: Buffer,
    pub(crate) stride: u32,
    /// [SLOTS] the means (loss_values.rs: SLOT_*).
    pub(crate) values: Buffer,
    /// Made for the photometric term ([`ImageLoss::new`]); else the semantic term alone
    /// ([`ImageLoss::semantic`]), without the SSIM's per-pixel planes.
    photometric: bool,
}

impl ImageLoss {
    /// Scratch for W x H views with `channels` semantic classes (0: RGB only).
    pub fn new(gpu: &Gpu, width: u32, height: u32, channels: u32) -> Result<ImageLoss> {
        Self::with_terms(gpu, width, height, channels, true)
    }

    /// Scratch for [`ImageLoss::record_semantic`] alone: without the SSIM's planes (60
    /// bytes a pixel), which a run that never reads a target image would not use.
    pub fn semantic(gpu: &Gpu, width: u32, height: u32, channels: u32) -> Result<ImageLoss> {
        ensure!(channels > 0, "a semantic loss needs at least one class");
        Self::with_terms(gpu, width, height, channels, false)
    }

    fn with_terms(
        gpu: &Gpu,
        width: u32,
        height: u32,
        channels: u32,
        photometric: bool,
    ) -> Result<ImageLoss> {
        ensure!(
            width > 0 && height > 0,
            "loss image must not be empty ({width}x{height})"
        );
        let pixels = width as u64 * height as u64;
        let pixel_groups = pixels.div_ceil(LOSS_WG as u64);
        ensure!(
            pixel_groups <= MAX_GROUPS as u64
                && width.div_ceil(TILE) <= MAX_GROUPS
                && height.div_ceil(TILE) <= MAX_GROUPS,
            "loss image {width}x{height} is too large for one dispatch"
        );
        // The kernels reach the per-pixel arrays by address: one allocation bounds them.
        let planes_bytes = |planes: u64| match photometric {
            true => planes * pixels * 3 * 4,
            false => 4,
        };
        // loss_cross_entropy runs three loops over the channels per pixel.
        ensure!(
            3 * channels as u64 + 3 <= LOOP_BUDGET,
            "{channels} semantic channels exceed the per-invocation loop budget"
        );
        let tiles = width.div_ceil(TILE) * height.div_ceil(TILE);
        let stride = tiles
            .max(pixel_groups as u32)
            .max(super::loss_entropy::ENTROPY_GROUPS);
        let moments = gpu.buffer("loss-moments", planes_bytes(MOMENT_PLANES))?;
        let moment_grads = gpu.buffer("loss-moment-grads", planes_bytes(GRAD_PLANES))?;
        let partials = gpu.buffer("loss-partials", SLOTS as u64 * stride as u64 * 4)?;
        let count_partials = gpu.buffer(
            "loss-count-partials",
            (SLOT_LABELED as u64 + 1) * stride as u64 * 4,
        )?;
        // Zeros until a term is recorded: a loop that never records entropy reads 0.
        let values = gpu.buffer_from("loss-values", &[0f32; SLOTS as usize])?;
        Ok(ImageLoss {
            gpu: gpu.clone(),
            width,
            height,
            channels,
            moments,
            moment_grads,
            partials,
            count_partials,
            stride,
            values,
            photometric,
        })
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    pub fn channels(&self) -> u32 {
        self.channels
    }

    fn pixels(&self) -> u32 {
        self.width * self.height
    }

    /// Records L_rgb = 0.8 mean|x - y| + 0.2 (1 - mean SSIM(x, y)) of the rendered `rgb`
    /// against `target` (f32 [pixels * 3], channel fastest), OVERWRITING `v_rgb` with
    /// dL_rgb/d rgb, and, with `semantics`, lambda * mean CE over the labeled pixels,
    /// overwriting its v_sem_norm. Barriers before and after: inputs written earlier in
    /// `rec` are seen, outputs are visible to what is recorded next. The values are read
    /// with [`ImageLoss::read_values`] after the submission; without `semantics` the CE
    /// value and labeled count read 0.
    pub fn record(
        &self,
        rec: &mut Recorder,
        rgb: &Buffer,
        target: &Buffer,
        v_rgb: &Buffer,
        semantics: Option<&SemanticTerm<'_>>,
    ) -> Result<()> {
        ensure!(
            self.photometric,
            "this ImageLoss was made for the semantic term alone (ImageLoss::semantic)"
        );
        self.check_rgb(rgb, target, v_rgb)?;
        let images = RgbImages { rgb, target, v_rgb };
        self.record_terms(rec, Some(&images), semantics)
    }

    /// Records the semantic term alone, as [`ImageLoss::record`] does beside the
    /// photometric one, for views without a target image (`train --semantics-only`, whose
    /// frozen colours the photometric loss could not change). The L1, SSIM and MSE values
    /// read 0; nothing writes a `v_rgb`.
    pub fn record_semantic(&self, rec: &mut Recorder, semantics: &SemanticTerm<'_>) -> Result<()> {
        self.record_terms(rec, None, Some(semantics))
    }

    /// Four phases between barriers, each pairing an SSIM kernel (with `images`) with the
    /// semantic or reduction work that does not depend on it.
    fn record_terms(
        &self,
        rec: &mut Recorder,
        images: Option<&RgbImages<'_>>,
        semantics: Option<&SemanticTerm<'_>>,
    ) -> Result<()> {
        if let Some(s) = semantics {
            self.check_semantics(s)?;
        }
        rec.barrier();
        self.record_count_and_blur(rec, images, semantics)?;
        rec.barrier();
        self.record_ssim_forward(rec, images, semantics)?;
        rec.barrier();
        self.record_ce_and_blur_grads(rec, images.is_some(), semantics)?;
        rec.barrier();
        self.record_rgb_backward_and_sums(rec, images, semantics)?;
        rec.barrier();
        Ok(())
    }

    /// Workgroups of the 2D (ssim_*) kernels.
    fn tiles(&self) -> [u32; 3] {
        [self.width.div_ceil(TILE), self.height.div_ceil(TILE), 1]
    }

    /// Workgroups of the per-pixel 1D kernels.
    fn pixel_groups(&self) -> u32 {
        self.pixels().div_ceil(LOSS_WG)
    }

    /// Floats the photometric loss averages over.
    fn rgb_count(&self) -> f32 {
        3.0 * self.pixels() as f32
    }

    fn check_rgb(&self, rgb: &Buffer, target: &Buffer, v_rgb: &Buffer) -> Result<()> {
        let rgb_bytes = self.pixels() as u64 * 3 * 4;
        for (what, buf) in [("rgb", rgb), ("target", target), ("v_rgb", v_rgb)] {
            ensure!(
                buf.size() >= rgb_bytes,
                "{what} holds {} bytes; a {}x{} RGB image needs {rgb_bytes}",
                buf.size(),
                self.width,
                self.height
            );
        }
        Ok(())
    }

    /// Phase 1: counting the labeled pixels (or zeroing the count and CE without
    /// semantics) beside the blur of the SSIM moments.
    fn record_count_and_blur(
        &self,
        rec: &mut Recorder,
        images: Option<&RgbImages<'_>>,
        semantics: Option<&SemanticTerm<'_>>,
    ) -> Result<()> {
        match semantics {
            Some(s) => rec.dispatch(
                ids::TRAIN_LOSS_COUNT_LABELS,
                &[("partials", &self.count_partials)],
                &CountLabelsParams {
                    labels_addr: s.labels.address_words(4)?,
                    pixels: self.pixels(),
                    channels: self.channels,
                    stride: self.stride,
                },
                [self.pixel_groups(), 1, 1],
            )?,
            // The count and the CE are adjacent slots.
            None => rec.fill(&self.values, SLOT_LABELED as u64 * 4, 8, 0),
        }
        // L1, SSIM and SE are adjacent slots.
        const _: () = assert!(SLOT_SE == SLOT_L1 + 2);
        let Some(images) = images else {
            // Here, a phase before the reductions that write the other slots.
            rec.fill(&self.values, SLOT_L1 as u64 * 4, 3 * 4, 0);
            return Ok(());
        };
        rec.dispatch(
            ids::TRAIN_SSIM_BLUR_INPUTS,
            &[],
            &BlurInputsParams {
                rgb_addr: images.rgb.address_words(4)?,
                target_addr: images.target.address_words(4)?,
                moments_addr: self.moments.address_words(4)?,
                width: self.width,
                height: self.height,
            },
            self.tiles(),
        )?;
        Ok(())
    }

    /// Phase 2: reducing the labeled count beside the SSIM forward (per-pixel L1 and SSIM
    /// partials, and the SSIM's gradient with respect to the blurred moments).
    fn record_ssim_forward(
        &self,
        rec: &mut Recorder,
        images: Option<&RgbImages<'_>>,
        semantics: Option<&SemanticTerm<'_>>,
    ) -> Result<()> {
        if semantics.is_some() {
            self.reduce_from(
                rec,
                &self.count_partials,
                SLOT_LABELED,
                1,
                self.pixel_groups(),
            )?;
        }
        let Some(images) = images else {
            return Ok(());
        };
        let count = self.rgb_count();
        rec.dispatch(
            ids::TRAIN_SSIM_FORWARD,
            &[("partials", &self.partials)],
            &SsimForwardParams {
                rgb_addr: images.rgb.address_words(4)?,
                target_addr: images.target.address_words(4)?,
                moments_addr: self.moments.address_words(4)?,
                moment_grads_addr: self.moment_grads.address_words(4)?,
                width: self.width,
                height: self.height,
                stride: self.stride,
                inv_count: 1.0 / count,
                ssim_weight: -SSIM_WEIGHT / count,
            },
            self.tiles(),
        )?;
        Ok(())
    }

    /// Phase 3: the cross-entropy and its gradient (which read the labeled count) beside
    /// the blur of the moment gradients.
    fn record_ce_and_blur_grads(
        &self,
        rec: &mut Recorder,
        photometric: bool,
        semantics: Option<&SemanticTerm<'_>>,
    ) -> Result<()> {
        if let Some(s) = semantics {
            rec.dispatch(
                ids::TRAIN_LOSS_CROSS_ENTROPY,
                &[("values", &self.values), ("partials", &self.partials)],
                &CrossEntropyParams {
                    sem_norm_addr: s.sem_norm.address_words(4)?,
                    labels_addr: s.labels.address_words(4)?,
                    v_sem_norm_addr: s.v_sem_norm.address_words(4)?,
                    pixels: self.pixels(),
                    channels: self.channels,
                    stride: self.stride,
                    mode: match s.mode {
                        SemanticMode::RawLogits => 0,
                        SemanticMode::Softmax => 1,
                    },
                    lambda: s.lambda,
                },
                [self.pixel_groups(), 1, 1],
            )?;
        }
        if !photometric {
            return Ok(());
        }
        rec.dispatch(
            ids::TRAIN_SSIM_BLUR_GRADS,
            &[],
            &BlurGradsParams {
                moment_grads_addr: self.moment_grads.address_words(4)?,
                blurred_addr: self.moments.address_words(4)?,
                width: self.width,
                height: self.height,
            },
            self.tiles(),
        )?;
        Ok(())
    }

    /// Phase 4: dL_rgb/d rgb into `v_rgb`, beside the reductions of the L1, SSIM, SE and
    /// CE partials into their values.
    fn record_rgb_backward_and_sums(
        &self,
        rec: &mut Recorder,
        images: Option<&RgbImages<'_>>,
        semantics: Option<&SemanticTerm<'_>>,
    ) -> Result<()> {
        if semantics.is_some() {
            self.record_reduce(rec, SLOT_CE, 1, self.pixel_groups())?;
        }
        let Some(images) = images else {
            return Ok(());
        };
        rec.dispatch(
            ids::TRAIN_SSIM_BACKWARD,
            &[],
            &SsimBackwardParams {
                rgb_addr: images.rgb.address_words(4)?,
                target_addr: images.target.address_words(4)?,
                blurred_addr: self.moments.address_words(4)?,
                v_rgb_addr: images.v_rgb.address_words(4)?,
                width: self.width,
                height: self.height,
                l1_weight: L1_WEIGHT / self.rgb_count(),
            },
            self.tiles(),
        )?;
        let tiles = self.tiles();
        self.record_reduce(rec, SLOT_L1, 3, tiles[0] * tiles[1])
    }

    fn check_semantics(&self, s: &SemanticTerm<'_>) -> Result<()> {
        if self.channels == 0 {
            bail!("this ImageLoss was made without semantic channels");
        }
        let pixels = self.pixels() as u64;
        let sem_bytes = pixels * self.channels as u64 * 4;
        for (what, buf, need) in [
            ("sem_norm", s.sem_norm, sem_bytes),
            ("v_sem_norm", s.v_sem_norm, sem_bytes),
            ("labels", s.labels, pixels * 4),
        ] {
            ensure!(
                buf.size() >= need,
                "{what} holds {} bytes; {}x{} pixels with {} channels need {need}",
                buf.size(),
                self.width,
                self.height,
                self.channels
            );
        }
        Ok(())
    }

    /// Adds the `groups` partials of `slots` slots from `first_slot` into their values.
    pub(crate) fn record_reduce(
        &self,
        rec: &mut Recorder,
        first_slot: u32,
        slots: u32,
        groups: u32,
    ) -> Result<()> {
        self.reduce_from(rec, &self.partials, first_slot, slots, groups)
    }

    /// [`ImageLoss::record_reduce`] of the partials in `partials`.
    fn reduce_from(
        &self,
        rec: &mut Recorder,
        partials: &Buffer,
        first_slot: u32,
        slots: u32,
        groups: u32,
    ) -> Result<()> {
        rec.dispatch(
            ids::TRAIN_LOSS_REDUCE,
            &[("partials", partials), ("values", &self.values)],
            &LossReduceParams {
                first_slot,
                groups,
                stride: self.stride,
            },
            [slots, 1, 1],
        )?;
        Ok(())
    }

    /// The values of the last submission that recorded each term (one small download).
    pub fn read_values(&self) -> Result<LossValues> {
        let v: Vec<f32> = self.gpu.download(&self.values, 0, SLOTS as usize)?;
        Ok(LossValues::from_slots(&v))
    }
}
