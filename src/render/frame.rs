//! One rendered view, downloaded: images as row-major f32 arrays.

use anyhow::Result;

use super::StageTimes;
use crate::gpu::{Buffer, Gpu};
use crate::scene::Camera;

/// Images of one view. Pixel (x, y) is index y * width + x; multi-channel images are
/// pixel-major with the channel fastest.
#[derive(Clone, Debug)]
pub struct RenderedFrame {
    pub width: u32,
    pub height: u32,
    /// Semantic channels C (0 when rendered without semantics).
    pub channels: u32,
    /// [H, W, 3], background included.
    pub rgb: Vec<f32>,
    /// [H, W]: accumulated alpha, 1 - final T.
    pub alpha: Vec<f32>,
    /// [H, W]: expected depth, sum(w z) / (1 - T); 0 where nothing was blended.
    pub depth: Vec<f32>,
    /// [H, W]: transmittance after the last blended Gaussian.
    pub final_t: Vec<f32>,
    /// [H, W]: position of the last blended Gaussian in the tile-sorted list.
    pub last: Vec<u32>,
    /// [H, W]: number of blended Gaussians.
    pub n_contrib: Vec<u32>,
    /// [H, W, C]: sum of alpha * T * s.
    pub sem: Vec<f32>,
    /// [H, W, C]: `sem / (1 - T)` (Gaussian Semantics Eq. 2); 0 where nothing was blended.
    pub sem_norm: Vec<f32>,
    /// Visible Gaussians and (tile, Gaussian) intersections in this frame.
    pub visible: u32,
    pub intersections: u32,
    pub stages: StageTimes,
}

impl RenderedFrame {
    pub(crate) fn download(
        gpu: &Gpu,
        cam: &Camera,
        channels: u32,
        [rgb, alpha, depth, final_t, last, n_contrib, sem, sem_norm]: [&Buffer; 8],
        visible: u32,
        intersections: u32,
        stages: StageTimes,
    ) -> Result<RenderedFrame> {
        let p = (cam.width as u64) * (cam.height as u64);
        let c = channels as u64;
        // One staging buffer and one submission for all outputs.
        let parts = gpu.download_many(&[
            (rgb, 0, p * 12),
            (alpha, 0, p * 4),
            (depth, 0, p * 4),
            (final_t, 0, p * 4),
            (last, 0, p * 4),
            (n_contrib, 0, p * 4),
            (sem, 0, p * c * 4),
            (sem_norm, 0, p * c * 4),
        ])?;
        let f32s = |k: usize| -> Vec<f32> { bytemuck::pod_collect_to_vec(&parts[k]) };
        let u32s = |k: usize| -> Vec<u32> { bytemuck::pod_collect_to_vec(&parts[k]) };
        Ok(RenderedFrame {
            width: cam.width,
            height: cam.height,
            channels,
            rgb: f32s(0),
            alpha: f32s(1),
            depth: f32s(2),
            final_t: f32s(3),
            last: u32s(4),
            n_contrib: u32s(5),
            sem: f32s(6),
            sem_norm: f32s(7),
            visible,
            intersections,
            stages,
        })
    }

    /// Argmax class (compact index) per pixel, or None where nothing was blended, C = 0, or
    /// the top channels tie exactly (Gaussians whose logits training never moved from a
    /// uniform start: no class, as `classes_from_logits` gives them none, not the last id).
    pub fn argmax_labels(&self) -> Vec<Option<u32>> {
        let c = self.channels as usize;
        (0..self.alpha.len())
            .map(|i| {
                if c == 0 || self.alpha[i] <= 0.0 {
                    return None;
                }
                let s = &self.sem_norm[i * c..(i + 1) * c];
                let (best, &top) = s.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
                let tied = s.iter().filter(|&&v| v == top).count() > 1;
                (!tied).then_some(best as u32)
            })
            .collect()
    }
}
