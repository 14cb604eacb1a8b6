//! A scene's Gaussians uploaded once, structure-of-arrays as the kernels read them.

use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, GpuResult, Recorder};
use crate::scene::Gaussians;

use super::SemanticMode;

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
                    let probs = gpu.buffer("probs", self.n as u64 * self.channels as u64 * 4)?;
                    let mut rec = Recorder::new(gpu)?;
                    rec.dispatch(
                        ids::RASTER_SOFTMAX,
                        &[("logits", logits), ("probs", &probs)],
                        bytemuck::cast_slice(&[self.n, self.channels]),
                        [self.n.div_ceil(256), 1, 1],
                    )?;
                    rec.submit_and_wait()?;
                    let _ = self.probs.set(probs);
                }
                Ok(self.probs.get())
            }
        }
    }
}
