//! Label maps rendered from a scene whose Gaussians carry classes: each Gaussian blends a
//! one-hot vector of its class (unseen Gaussians blend zeros but still occlude), and the
//! pixel takes the argmax of the normalized semantics (Gaussian Semantics Eq. 2). The GPU
//! keeps only the running argmax per pixel and one class index per Gaussian, so memory does
//! not grow with the number of classes (1M Gaussians x 300 classes is 4 MB of indices, not
//! 1.2 GB of one-hot vectors).

use anyhow::{bail, Result};

use crate::dataset::NO_LABEL;
use crate::gpu::Gpu;
use crate::render::{BandWork, GpuScene, Rasterizer, RenderOptions, SemanticMode};
use crate::scene::classes::IGNORE_U16;
use crate::scene::{Camera, Gaussians};

/// Renders the class of every pixel of `cams` (None where no classified Gaussian shows).
pub struct LabelRenderer {
    scene: GpuScene,
    /// User class id of each class index, ascending.
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
        let index: Vec<u32> = class_ids
            .iter()
            .map(|&id| match channel_ids.binary_search(&(id as u32)) {
                Ok(k) if id >= 0 => k as u32,
                _ => NO_LABEL,
            })
            .collect();
        let classes = channel_ids.len().max(1) as u32;
        Ok(LabelRenderer {
            scene: GpuScene::upload_with_classes(gpu, g, &index, classes)?,
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
        let pixels = cam.width as usize * cam.height as usize;
        self.raster.run_tiled_in_bands(
            &self.scene,
            cam,
            &opts,
            BandWork::Overwrite,
            |rec, tiles| tiles.record_blend(rec),
        )?;
        Ok(self
            .raster
            .last_labels(pixels)?
            .into_iter()
            .map(|k| k.and_then(|k| self.channel_ids.get(k as usize).copied()))
            .collect())
    }

    /// Every class id fits a 16-bit label map ([`LabelRenderer::render`]): checked once
    /// before a run writes its first view.
    pub fn check_fits_16_bit(&self) -> Result<()> {
        check_ids_fit_16_bit(self.channel_ids.iter().map(|&id| id as i64))
    }

    /// [`LabelRenderer::render_ids`] for writing a 16-bit label map: an error when a class id
    /// does not fit below the 16-bit ignore value, never a silently cut id.
    pub fn render(&mut self, cam: &Camera) -> Result<Vec<Option<u16>>> {
        self.check_fits_16_bit()?;
        Ok(self
            .render_ids(cam)?
            .into_iter()
            .map(|p| p.map(|id| id as u16))
            .collect())
    }
}

/// Every class id is below the 16-bit label maps' ignore value (the maps a label render is
/// written as): an error naming the first that is not, never a silently cut id.
pub fn check_ids_fit_16_bit(ids: impl IntoIterator<Item = i64>) -> Result<()> {
    if let Some(id) = ids.into_iter().find(|&id| id >= i64::from(IGNORE_U16)) {
        bail!("class id {id} does not fit a 16-bit label map (ids must be below {IGNORE_U16})");
    }
    Ok(())
}
