//! RGB images of the views, matched to cameras by name.

use std::path::Path;

use anyhow::{bail, Context, Result};

use super::Camera;

/// Loads `<name>.png|jpg|jpeg` (any case) for a camera as [H, W, 3] floats in [0, 1]; a
/// name with subfolders (`cam0/00001`) reads from the same subfolders of `dir`.
pub fn load_view_image(dir: &Path, cam: &Camera) -> Result<Vec<f32>> {
    let path = ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"]
        .iter()
        .map(|ext| dir.join(format!("{}.{ext}", cam.name)))
        .find(|p| p.is_file())
        .with_context(|| {
            format!(
                "no image for camera {} in {} (expected {}.png or .jpg)",
                cam.name,
                dir.display(),
                cam.name
            )
        })?;
    let img = image::open(&path)
        .with_context(|| format!("reading {}", path.display()))?
        .to_rgb8();
    if img.width() != cam.width || img.height() != cam.height {
        bail!(
            "{} is {}x{}, but camera {} renders at {}x{} (its label map's size, where the \
             label maps are a resized copy): images and label maps must have one size",
            path.display(),
            img.width(),
            img.height(),
            cam.name,
            cam.width,
            cam.height
        );
    }
    Ok(img.as_raw().iter().map(|&v| v as f32 / 255.0).collect())
}
