//! RGB images of the views, matched to cameras by name.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{anyhow, bail, Result};

use super::Camera;

/// Loads one camera's image from `dir` (see [`ImageDir::load`]).
pub fn load_view_image(dir: &Path, cam: &Camera) -> Result<Vec<f32>> {
    ImageDir::new(dir).load(cam)
}

/// A folder of view images, matched to cameras as label maps are: `<name>.png|jpg|jpeg`
/// (the extension in any case), a name with subfolders (`cam0/00001`) in the same
/// subfolders, and a plain name not found there by its stem anywhere below (a rig whose
/// image stems are unique names its cameras by stem: `cam1/0005.jpg` is camera `0005`).
pub struct ImageDir {
    dir: PathBuf,
    /// Every image below `dir` by stem, listed once on the first name not found directly.
    by_stem: OnceLock<HashMap<String, Vec<PathBuf>>>,
    /// The cameras scaled to their label maps' size, by name, with the size their cameras
    /// file gives: an image of another size names the right culprit.
    scaled: HashMap<String, (u32, u32)>,
}

impl ImageDir {
    pub fn new(dir: &Path) -> ImageDir {
        ImageDir {
            dir: dir.to_path_buf(),
            by_stem: OnceLock::new(),
            scaled: HashMap::new(),
        }
    }

    /// The cameras a label folder scaled to its maps' size (`LabelDir::scaled_cameras`).
    pub fn with_scaled_cameras(mut self, scaled: HashMap<String, (u32, u32)>) -> ImageDir {
        self.scaled = scaled;
        self
    }

    /// The camera's image as [H, W, 3] floats in [0, 1]. Two images of one name (`x.png`
    /// and `x.jpg`, or one stem in two subfolders) are an error: which is the view's would
    /// be a guess.
    pub fn load(&self, cam: &Camera) -> Result<Vec<f32>> {
        let path = self.path_of(&cam.name)?;
        decode_view_image(&path, cam, self.scaled.get(&cam.name).copied())
    }

    fn path_of(&self, name: &str) -> Result<PathBuf> {
        let found = view_images_named(&self.dir, name)?;
        if !found.is_empty() || name.contains('/') {
            return one_image(&self.dir, name, found);
        }
        let index = self.by_stem.get_or_init(|| images_below(&self.dir));
        let below = index.get(name).cloned().unwrap_or_default();
        one_image(&self.dir, name, below)
    }
}

/// The images below `dir` (its subfolders too) by file stem.
fn images_below(dir: &Path) -> HashMap<String, Vec<PathBuf>> {
    let mut by_stem: HashMap<String, Vec<PathBuf>> = HashMap::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for path in entries.filter_map(|e| e.ok().map(|e| e.path())) {
            if path.is_dir() {
                folders.push(path);
            } else if let Some(stem) = path.file_stem().and_then(|s| s.to_str()) {
                if is_view_image(&path) {
                    by_stem.entry(stem.to_string()).or_default().push(path);
                }
            }
        }
    }
    for paths in by_stem.values_mut() {
        paths.sort();
    }
    by_stem
}

/// Decodes the image at `path` for `cam`, checking its size; `scaled_from`: the size its
/// cameras file gives, where the label maps scaled the camera to theirs.
fn decode_view_image(
    path: &Path,
    cam: &Camera,
    scaled_from: Option<(u32, u32)>,
) -> Result<Vec<f32>> {
    // The decoder's message already holds its source's: as context, it would be said twice.
    let img = image::open(path).map_err(|e| anyhow!("reading {}: {e}", path.display()))?;
    let (width, height) = (img.width(), img.height());
    if (width, height) != (cam.width, cam.height) {
        let (name, w, h) = (&cam.name, cam.width, cam.height);
        let (source, rule) = match scaled_from {
            Some((fw, fh)) => (
                format!("its label map's size (the label maps are a resized copy; its cameras file gives {fw}x{fh})"),
                "images and label maps must have one size",
            ),
            None => (
                "the size its cameras file gives".to_string(),
                "an image must have its camera's size (resized images need cameras of their size)",
            ),
        };
        bail!(
            "{} is {width}x{height}, but camera {name} renders at {w}x{h}, {source}: {rule}",
            path.display()
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

/// The extensions of view images (and of label maps, PNG), in lower case.
pub const VIEW_IMAGE_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// Whether `path` names a view image or label map by its extension, in any case.
pub fn is_view_image(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default();
    VIEW_IMAGE_EXTENSIONS.contains(&ext.to_ascii_lowercase().as_str())
}

/// The image files of view `name` at its path in `dir`, any case of extension.
fn view_images_named(dir: &Path, name: &str) -> Result<Vec<PathBuf>> {
    // The usual spellings first: a few stats a view, where listing the folder for every
    // view would read a capture's thousands of entries thousands of times.
    let spellings = VIEW_IMAGE_EXTENSIONS
        .iter()
        .flat_map(|e| [e.to_string(), e.to_uppercase()]);
    let spelled = spellings.map(|e| dir.join(format!("{name}.{e}")));
    let mut found: Vec<PathBuf> = spelled.filter(|p| p.is_file()).collect();
    if found.is_empty() {
        found = images_named(dir, name)?; // `.Png`, `.Jpg` and other mixed cases
    }
    // One file can answer to two spellings on a case-insensitive file system.
    found.dedup_by(|a, b| same_file(a, b));
    Ok(found)
}

/// The one image found for view `name`, or an error naming none or all.
fn one_image(dir: &Path, name: &str, mut found: Vec<PathBuf>) -> Result<PathBuf> {
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => bail!(
            "no image for camera {name} in {} (expected {name}.png or .jpg, there or by its \
             stem in a subfolder)",
            dir.display()
        ),
        _ => bail!(
            "camera {name} has {} images in {}: {}; keep one",
            found.len(),
            dir.display(),
            found
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The PNG and JPEG files of view `name` in `dir` (its subfolder for a rig view), any case
/// of extension, by listing the folder.
fn images_named(dir: &Path, name: &str) -> Result<Vec<PathBuf>> {
    let file = Path::new(name);
    let folder = file.parent().map_or(dir.to_path_buf(), |sub| dir.join(sub));
    let stem = file.file_name().and_then(|s| s.to_str()).unwrap_or(name);
    let Ok(entries) = std::fs::read_dir(&folder) else {
        return Ok(Vec::new()); // a missing folder: no image, said by the caller
    };
    let mut found: Vec<PathBuf> = (entries.filter_map(|e| e.ok().map(|e| e.path())))
        .filter(|p| p.file_stem().and_then(|s| s.to_str()) == Some(stem))
        .filter(|p| is_view_image(p) && p.is_file())
        .collect();
    found.sort();
    Ok(found)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
