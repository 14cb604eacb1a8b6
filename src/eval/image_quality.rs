//! PSNR and SSIM of a scene's rendered RGB against reference images, for methods that
//! change appearance (joint training). SSIM is the 3DGS one (11x11 Gaussian window), computed
//! by the training loss kernels.

use anyhow::Result;
use serde::Serialize;

use crate::gpu::{Buffer, Gpu, Recorder};
use crate::render::{GpuScene, Rasterizer, RenderOptions};
use crate::scene::{Camera, Gaussians};
use crate::train::loss::ImageLoss;

/// Means over the views.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ImageQuality {
    /// Mean of the views' PSNR in dB: infinite where a view renders its image exactly, which
    /// JSON writes as null.
    pub psnr: f64,
    pub ssim: f64,
    pub views: usize,
}

/// Renders `g` from each camera and compares with its image ([H, W, 3] in [0, 1]);
/// rendered colors are clamped to [0, 1] first, as an 8-bit image would be.
pub fn image_quality(
    gpu: &Gpu,
    g: &Gaussians,
    views: &[(&Camera, &[f32])],
) -> Result<ImageQuality> {
    let scene = GpuScene::upload(gpu, g)?;
    let mut rasterizer = Rasterizer::new(gpu);
    let opts = RenderOptions {
        semantics: None,
        ..Default::default()
    };
    let (mut psnr, mut ssim) = (0.0, 0.0);
    // The loss and its buffers serve every view of one size.
    let mut sized: Option<(u32, u32, ImageLoss, [Buffer; 3])> = None;
    for (cam, image) in views {
        let frame = rasterizer.render(&scene, cam, &opts)?;
        let rendered: Vec<f32> = frame.rgb.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        if !matches!(&sized, Some((w, h, ..)) if (*w, *h) == (cam.width, cam.height)) {
            let bytes = rendered.len() as u64 * 4;
            let buffers = [
                gpu.buffer("rendered", bytes)?,
                gpu.buffer("image", bytes)?,
                gpu.buffer("v_rgb", bytes)?,
            ];
            let loss = ImageLoss::new(gpu, cam.width, cam.height, 0)?;
            sized = Some((cam.width, cam.height, loss, buffers));
        }
        let (_, _, loss, [rgb, target, v_rgb]) = sized.as_ref().expect("set above");
        gpu.upload(rgb, 0, &rendered)?;
        gpu.upload(target, 0, image)?;
        let mut rec = Recorder::new(gpu)?;
        loss.record(&mut rec, rgb, target, v_rgb, None)?;
        rec.submit_and_wait()?;
        let values = loss.read_values()?;
        psnr += values.psnr() as f64;
        ssim += values.ssim as f64;
    }
    let n = views.len().max(1) as f64;
    Ok(ImageQuality {
        psnr: psnr / n,
        ssim: ssim / n,
        views: views.len(),
    })
}
