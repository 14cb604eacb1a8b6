//! A scene's Gaussians uploaded once, structure-of-arrays as the kernels read them.

use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, GpuResult, Recorder};
use crate::scene::Gaussians;

use super::SemanticMode;
use crate::contract::params::SoftmaxParams;

/// Floats per Gaussian of the parameter tensors, in the order means, log-scales,
/// quaternions, opacity logits, SH: the layout of `GpuScene` and of its gradients.
pub(crate) fn parameter_floats(sh_coeffs: u32) -> [u64; 5] {
    [3, 3, 4, 1, 3 * sh_coeffs as u64]
}

/// Download ranges of `n` Gaussians' parameter tensors (or their gradients), in that order.
pub(crate) fn parameter_ranges(
    tensors: [&Buffer; 5],
    n: u64,
    sh_coeffs: u32,
) -> Vec<(&Buffer, u64, u64)> {
    tensors
        .into_iter()
        .zip(parameter_floats(sh_coeffs))
        .map(|(b, floats)| (b, 0, n * floats * 4))
        .collect()
}

/// Gaussians on the device. Semantic logits are optional; their softmax is computed on
/// the device the first time the softmax mode asks for it.
pub struct GpuScene {
    pub n: u32,
    pub sh_degree: u32,
    pub sh_coeffs: u32,
    /// Semantic channels C (0 without semantics).
    pub channels: u32,
    pub(crate) means: Buffer,
    pub(crate) log_scales: Buffer,
    pub(crate) quats: Buffer,
    pub(crate) opacity_logits: Buffer,
    pub(crate) sh: Buffer,
    pub(crate) logits: Option<Buffer>,
    pub(crate) probs: std::sync::OnceLock<Buffer>,
}

impl GpuScene {
    pub fn upload(gpu: &Gpu, g: &Gaussians) -> GpuResult<GpuScene> {
        let flat3 = |v: &[[f32; 3]]| -> Vec<f32> { v.iter().flatten().copied().collect() };
        let quats: Vec<f32> = g.quats.iter().flatten().copied().collect();
        let (channels, logits) = match &g.semantics {
            Some(s) if s.channels > 0 => (
                s.channels as u32,
                Some(gpu.buffer_from("logits", &s.logits)?),
            ),
            _ => (0, None),
        };
        Ok(GpuScene {
            n: g.len() as u32,
            sh_degree: g.sh_degree,
            sh_coeffs: g.sh_coeffs() as u32,
            channels,
            means: gpu.buffer_from("means", &flat3(&g.means))?,
            log_scales: gpu.buffer_from("log_scales", &flat3(&g.log_scales))?,
            quats: gpu.buffer_from("quats", &quats)?,
            opacity_logits: gpu.buffer_from("opacity_logits", &g.opacity_logits)?,
            sh: gpu.buffer_from("sh", &g.sh)?,
            logits,
            probs: std::sync::OnceLock::new(),
        })
    }

    /// The per-Gaussian semantic vectors blended in `mode` (None without semantics).
    pub(crate) fn semantics(&self, gpu: &Gpu, mode: SemanticMode) -> GpuResult<Option<&Buffer>> {
        let Some(logits) = &self.logits else {
            return Ok(None);
        };
        match mode {
            SemanticMode::RawLogits => Ok(Some(logits)),
            SemanticMode::Softmax => {
                if self.probs.get().is_none() {
                    let mut rec = Recorder::new(gpu)?;
                    self.record_softmax(&mut rec)?;
                    rec.submit_and_wait()?;
                }
                Ok(self.probs.get())
            }
        }
    }

    /// Records (re)computing softmax(logits) into the probabilities the softmax mode
    /// blends; training calls it every iteration since the logits change.
    pub(crate) fn record_softmax(&self, rec: &mut Recorder) -> GpuResult<()> {
        let Some(logits) = &self.logits else {
            return Ok(());
        };
        if self.probs.get().is_none() {
            let bytes = self.n.max(1) as u64 * self.channels as u64 * 4;
            let _ = self.probs.set(rec.gpu().buffer("probs", bytes)?);
        }
        let probs = self.probs.get().expect("set above");
        rec.dispatch(
            ids::RASTER_SOFTMAX,
            &[("logits", logits), ("probs", probs)],
            &SoftmaxParams {
                n: self.n,
                channels: self.channels,
            },
            ids::RASTER_SOFTMAX.groups_for(self.n),
        )?;
        rec.barrier();
        Ok(())
    }

    /// The parameter tensors in the order of [`parameter_floats`].
    pub(crate) fn parameters(&self) -> [&Buffer; 5] {
        [
            &self.means,
            &self.log_scales,
            &self.quats,
            &self.opacity_logits,
            &self.sh,
        ]
    }

    /// Downloads the parameters into `g`'s arrays (which must have this scene's shape:
    /// training changes values, and densification rebuilds `g` to the new count first).
    pub fn download_into(&self, gpu: &Gpu, g: &mut Gaussians) -> GpuResult<()> {
        let n = self.n as u64;
        let c = self.channels as u64;
        let mut ranges = parameter_ranges(self.parameters(), n, self.sh_coeffs);
        if let Some(logits) = &self.logits {
            ranges.push((logits, 0, n * c * 4));
        }
        let parts = gpu.download_many(&ranges)?;
        let f = |k: usize| -> Vec<f32> { bytemuck::pod_collect_to_vec(&parts[k]) };
        let triples = |v: Vec<f32>| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        g.means = triples(f(0));
        g.log_scales = triples(f(1));
        g.quats = f(2)
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        g.opacity_logits = f(3);
        g.sh = f(4);
        g.sh_degree = self.sh_degree;
        if self.logits.is_some() {
            g.semantics = Some(crate::scene::gaussians::SemanticLogits {
                channels: self.channels as usize,
                logits: f(5),
            });
        }
        Ok(())
    }
}
