//! RGB images of the views, matched to cameras by name.

use std::path::Path;

use anyhow::{bail, Context, Result};

use super::Camera;

/// Loads `<name>.png|jpg|jpeg` (the extension in any case) for a camera as [H, W, 3]
/// floats in [0, 1]; a name with subfolders (`cam0/00001`) reads from the same subfolders of
/// `dir`. Two images of one name (`x.png` and `x.jpg`) are an error: which is the view's
/// would be a guess.
pub fn load_view_image(dir: &Path, cam: &Camera) -> Result<Vec<f32>> {
    let path = view_image_path(dir, &cam.name)?;
    let img = image::open(&path).with_context(|| format!("reading {}", path.display()))?;
    let (width, height) = (img.width(), img.height());
    if (width, height) != (cam.width, cam.height) {
        bail!(
            "{} is {width}x{height}, but camera {} renders at {}x{} (its label map's size, \
             where the label maps are a resized copy): images and label maps must have one size",
            path.display(),
            cam.name,
            cam.width,
            cam.height
        );
    }
    if !img.color().has_alpha() {
        return Ok(img
            .to_rgb8()
            .as_raw()
            .iter()
            .map(|&v| v as f32 / 255.0)
            .collect());
    }
    // Transparent pixels (a masked capture, a synthetic render) over black, as 3DGS's
    // default background composites them: their stored colour is no observation.
    let rgba = img.to_rgba32f();
    let over_black = rgba
        .pixels()
        .flat_map(|p| [p[0] * p[3], p[1] * p[3], p[2] * p[3]]);
    Ok(over_black.collect())
}

/// The image file of view `name` in `dir`.
fn view_image_path(dir: &Path, name: &str) -> Result<std::path::PathBuf> {
    let file = Path::new(name);
    let folder = match file.parent() {
        Some(sub) => dir.join(sub),
        None => dir.to_path_buf(),
    };
    let stem = file.file_name().and_then(|s| s.to_str()).unwrap_or(name);
    let entries = std::fs::read_dir(&folder).with_context(|| {
        format!(
            "no image for camera {name}: cannot list {}",
            folder.display()
        )
    })?;
    let mut found: Vec<std::path::PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.file_stem().and_then(|s| s.to_str()) == Some(stem))
        .filter(|p| {
            let ext = p.extension().and_then(|e| e.to_str()).unwrap_or_default();
            ["png", "jpg", "jpeg"].contains(&ext.to_ascii_lowercase().as_str())
        })
        .collect();
    found.sort();
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => bail!(
            "no image for camera {name} in {} (expected {name}.png or .jpg)",
            dir.display()
        ),
        _ => bail!(
            "camera {name} has {} images in {}: {}; keep one",
            found.len(),
            folder.display(),
            found
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}
