//! The GPU backward pass: blending backward (per tile, back to front, subgroup-reduced
//! atomics into screen-space gradients) then projection backward (per Gaussian, into the
//! stored parameters). Recorded into the same submission as the forward that produced the
//! tile lists, so an iteration needs no host round trip.

use anyhow::{ensure, Result};

use super::frame::RenderedFrame;
use super::gpu_scene::{GaussianParams, GpuScene, HostParams};
use super::rasterizer::{Rasterizer, TileLists};
use super::{project_params, RenderOptions, SemanticMode};
use crate::contract::params::SoftmaxParams;
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, Recorder};
use crate::scene::Camera;

pub use crate::contract::GRAD2D_STRIDE;
/// Floats carried per pixel between backward windows: T, S_rgb, S_sem chunk.
const CARRY_STRIDE: u64 = crate::contract::BACKWARD_CARRY_STRIDE as u64;

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
    /// Accumulate with float atomics (default where the device has them) or with the
    /// compare-and-swap fallback.
    pub float_atomics: bool,
    /// Compute only the semantic vectors' gradient (training the logits with geometry
    /// frozen): a cheaper blend backward and no projection backward.
    pub semantics_only: bool,
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
    pub fn new(gpu: &Gpu, scene: &GpuScene) -> Result<SceneGrads> {
        let n = scene.n.max(1) as u64;
        let c = scene.channels.max(1) as u64;
        let b = |name: &str, floats: u64| gpu.buffer(name, floats * 4);
        let sh_coeffs = scene.sh_coeffs.max(1);
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
            float_atomics: gpu.caps().float_atomic_add,
            semantics_only: false,
        };
        let mut rec = Recorder::new(gpu)?;
        grads.record_zero(&mut rec);
        grads.record_zero_densify(&mut rec);
        rec.submit_and_wait()?;
        Ok(grads)
    }

    /// Sizes the per-pixel carry buffer for views of `pixels` pixels walked in `windows`
    /// windows (only needed when a tile list spans more than one window).
    pub fn prepare_view(&mut self, gpu: &Gpu, pixels: u64, windows: u32) -> Result<()> {
        let need = if windows > 1 {
            pixels * CARRY_STRIDE * 4
        } else {
            4
        };
        if self.carry.size() < need {
            self.carry = gpu.buffer("backward_carry", need)?;
        }
        Ok(())
    }

    /// Records zeroing of the parameter gradients (start of an iteration).
    pub fn record_zero(&self, rec: &mut Recorder) {
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
            &[
                ("probs", probs),
                ("grad_probs", &self.probs),
                ("grad_logits", &self.logits),
            ],
            &SoftmaxParams {
                n: self.n,
                channels: self.channels,
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
        ensure!(
            f.windows == 1
                || grads.carry.size()
                    >= f.cam.width as u64 * f.cam.height as u64 * CARRY_STRIDE * 4,
            "SceneGrads::prepare_view was not called for this view size"
        );
        rec.fill(&grads.screen, 0, grads.screen.size(), 0);
        rec.barrier();
        self.record_blend_backward(rec, upstream, grads)?;
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
        let (sem_in, sem_target) = match f.semantics {
            Some((SemanticMode::RawLogits, buf)) => (buf, &grads.logits),
            Some((SemanticMode::Softmax, buf)) => (buf, &grads.probs),
            None => (&grads.placeholder, &grads.placeholder),
        };
        let sem_norm = if f.channels > 0 {
            self.sem_norm()
        } else {
            &grads.placeholder
        };
        let kernel = match (grads.semantics_only, grads.float_atomics) {
            (false, true) => ids::RASTER_BLEND_BACKWARD,
            (false, false) => ids::RASTER_BLEND_BACKWARD_CAS,
            (true, true) => ids::RASTER_BLEND_BACKWARD_SEM_ONLY,
            (true, false) => ids::RASTER_BLEND_BACKWARD_SEM_ONLY_CAS,
        };
        for chunk in 0..f.sem_chunks() {
            for start in f.window_starts().rev() {
                let params = f.blend_params(start, chunk, false);
                let bindings: [(&str, &Buffer); 12] = [
                    ("tile_ranges", self.ranges()),
                    ("isect_ids", self.isect_ids()),
                    ("xy_depth_opacity", self.xy_depth_opacity()),
                    ("xy_frac", self.xy_frac()),
                    ("conics", self.conics()),
                    ("final_t", self.final_t()),
                    ("last_entry", self.last_entry()),
                    ("n_contrib", self.n_contrib()),
                    ("v_sem_norm", upstream.sem_norm),
                    ("carry", &grads.carry),
                    ("grad2d", &grads.screen),
                    ("grad_sem", sem_target),
                ];
                // What the alpha and color gradients read (not the semantic-only variant).
                let optional: [(&str, &Buffer); 5] = [
                    ("colors", self.colors()),
                    ("sem_in", sem_in),
                    ("sem_norm", sem_norm),
                    ("v_rgb", upstream.rgb),
                    ("v_alpha", upstream.alpha),
                ];
                rec.dispatch_with_optional(kernel, &bindings, &optional, &params, f.tile_groups())?;
                rec.barrier();
            }
        }
        Ok(())
    }

    fn record_project_backward(
        &self,
        rec: &mut Recorder,
        scene: &GpuScene,
        cam: &Camera,
        grads: &SceneGrads,
    ) -> Result<()> {
        // The backward culls nothing itself: it reads the forward's visibility flags.
        let params = project_params(cam, scene, 0.0, f32::INFINITY);
        rec.dispatch(
            ids::RASTER_PROJECT_BACKWARD,
            &[
                ("means", &scene.params.means),
                ("log_scales", &scene.params.log_scales),
                ("quats", &scene.params.quats),
                ("opacity_logits", &scene.params.opacity_logits),
                ("sh", &scene.params.sh),
                ("visible", self.visible_flags()),
                ("grad2d", &grads.screen),
                ("grad_means", &grads.params.means),
                ("grad_log_scales", &grads.params.log_scales),
                ("grad_quats", &grads.params.quats),
                ("grad_opacity_logits", &grads.params.opacity_logits),
                ("grad_sh", &grads.params.sh),
                ("densify_grad", &grads.densify_grad),
                ("densify_count", &grads.densify_count),
            ],
            &params,
            ids::RASTER_PROJECT_BACKWARD.groups_for(scene.n),
        )?;
        rec.barrier();
        Ok(())
    }
}

/// Which backward kernels [`Rasterizer::render_backward`] runs.
#[derive(Clone, Copy, Debug)]
pub struct BackwardVariant {
    /// false: the compare-and-swap accumulation, as on devices without float atomics.
    pub float_atomics: bool,
    /// Only the semantic vectors' gradient (see [`SceneGrads::semantics_only`]).
    pub semantics_only: bool,
}

impl Default for BackwardVariant {
    fn default() -> Self {
        BackwardVariant {
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
        let mut grads = SceneGrads::new(&gpu, scene)?;
        grads.float_atomics = variant.float_atomics && gpu.caps().float_atomic_add;
        grads.semantics_only = variant.semantics_only;
        grads.prepare_view(&gpu, pixels, self.windows_for(scene.n))?;
        let pixel_grads = PixelGrads {
            rgb: &v_rgb,
            alpha: &v_alpha,
            sem_norm: &v_sem,
        };
        let run = self.run_tiled(scene, cam, opts, |rec, tiles| {
            tiles.record_blend(rec)?;
            grads.record_zero(rec);
            grads.record_zero_densify(rec);
            tiles.record_backward(rec, scene, &pixel_grads, &grads)
        })?;
        let mut rec = Recorder::new(&gpu)?;
        grads.record_softmax_backward(&mut rec, scene)?;
        rec.submit_and_wait()?;
        let frame = self.download_frame(cam, &run)?;
        Ok((frame, grads.download(&gpu)?))
    }
}
