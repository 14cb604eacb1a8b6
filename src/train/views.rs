//! Training views: a camera, its target image and its label map, held on the device for
//! the whole run (small next to the model; uploading them once keeps iterations free of
//! host transfers).

use anyhow::{ensure, Result};

use super::loss::IGNORE_LABEL;
use crate::gpu::{Buffer, Gpu};
use crate::scene::Camera;

/// One view on the host.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub camera: Camera,
    /// [H, W, 3] in [0, 1]; empty without a target image (`--semantics-only` alone trains
    /// without one: the frozen colours would learn nothing from it).
    pub rgb: Vec<f32>,
    /// [H, W] compact class per pixel, [`IGNORE_LABEL`] where there is none; empty when the
    /// view has no label map (it then trains appearance only).
    pub labels: Vec<u32>,
}

/// One view on the device.
pub(crate) struct DeviceView {
    pub camera: Camera,
    /// None without a target image.
    pub rgb: Option<Buffer>,
    pub labels: Buffer,
    /// The view has a label map (else it trains appearance only).
    pub labeled: bool,
}

impl TrainView {
    pub(crate) fn upload(&self, gpu: &Gpu, channels: u32) -> Result<DeviceView> {
        let c = &self.camera;
        let pixels = c.width as usize * c.height as usize;
        ensure!(
            self.rgb.is_empty() || self.rgb.len() == pixels * 3,
            "view {}: the image has {} values, {}x{}x3 expected",
            c.name,
            self.rgb.len(),
            c.width,
            c.height
        );
        ensure!(
            self.labels.is_empty() || self.labels.len() == pixels,
            "view {}: the label map has {} pixels, {}x{} expected",
            c.name,
            self.labels.len(),
            c.width,
            c.height
        );
        if let Some(bad) = self
            .labels
            .iter()
            .find(|&&l| l != IGNORE_LABEL && l >= channels)
        {
            anyhow::bail!(
                "view {}: label {bad} is not among the {channels} classes",
                c.name
            );
        }
        let labels = if self.labels.is_empty() {
            vec![IGNORE_LABEL; pixels]
        } else {
            self.labels.clone()
        };
        Ok(DeviceView {
            camera: c.clone(),
            rgb: match self.rgb.is_empty() {
                true => None,
                false => Some(gpu.buffer_from("target_rgb", &self.rgb)?),
            },
            labels: gpu.buffer_from("target_labels", &labels)?,
            labeled: !self.labels.is_empty(),
        })
    }
}
