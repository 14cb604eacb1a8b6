//! Label maps rendered from a scene whose Gaussians carry classes: each Gaussian blends a
//! one-hot vector of its class (unseen Gaussians blend zeros but still occlude), and the
//! pixel takes the argmax of the normalized semantics (Gaussian Semantics Eq. 2).

use anyhow::{bail, Result};

use crate::gpu::Gpu;
use crate::render::{GpuScene, Rasterizer, RenderOptions, SemanticMode};
use crate::scene::classes::IGNORE_U16;
use crate::scene::{Camera, Gaussians, SemanticLogits};

/// Renders the class of every pixel of `cams` (None where no classified Gaussian shows).
pub struct LabelRenderer {
    scene: GpuScene,
    /// User class id of each one-hot channel.
    channel_ids: Vec<u32>,
    raster: Rasterizer,
}

impl LabelRenderer {
    /// `classes` are the user ids in `g.class_ids` (-1 = unclassified).
    pub fn new(gpu: &Gpu, g: &Gaussians, class_ids: &[i32]) -> Result<LabelRenderer> {
        let mut channel_ids: Vec<u32> = class_ids
            .iter()
            .filter(|&&c| c >= 0)
            .map(|&c| c as u32)
            .collect();
        channel_ids.sort_unstable();
        channel_ids.dedup();
        let c = channel_ids.len().max(1);
        let mut logits = vec![0.0f32; g.len() * c];
        for (i, &id) in class_ids.iter().enumerate() {
            if id >= 0 {
                let k = channel_ids
                    .binary_search(&(id as u32))
                    .expect("collected above");
                logits[i * c + k] = 1.0;
            }
        }
        let mut scene = g.clone();
        scene.semantics = Some(SemanticLogits {
            channels: c,
            logits,
        });
        Ok(LabelRenderer {
            scene: GpuScene::upload(gpu, &scene)?,
            channel_ids,
            raster: Rasterizer::new(gpu),
        })
    }

    /// The user class id of every pixel, full width (ids are u32 all through).
    pub fn render_ids(&mut self, cam: &Camera) -> Result<Vec<Option<u32>>> {
        let opts = RenderOptions {
            semantics: Some(SemanticMode::RawLogits),
            ..Default::default()
        };
        let f = self.raster.render(&self.scene, cam, &opts)?;
        let c = f.channels as usize;
        Ok((0..f.alpha.len())
            .map(|p| {
                let s = &f.sem_norm[p * c..(p + 1) * c];
                let (k, &v) = s.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
                (v > 0.0)
                    .then(|| self.channel_ids.get(k).copied())
                    .flatten()
            })
            .collect())
    }

    /// [`LabelRenderer::render_ids`] for writing a 16-bit label map: an error when a class id
    /// does not fit below the 16-bit ignore value, never a silently cut id.
    pub fn render(&mut self, cam: &Camera) -> Result<Vec<Option<u16>>> {
        if let Some(&id) = self.channel_ids.iter().find(|&&id| id >= IGNORE_U16) {
            bail!("class id {id} does not fit a 16-bit label map (ids must be below {IGNORE_U16})");
        }
        Ok(self
            .render_ids(cam)?
            .into_iter()
            .map(|p| p.map(|id| id as u16))
            .collect())
    }
}
