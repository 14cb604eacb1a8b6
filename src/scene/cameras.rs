//! Loading cameras from any supported format (detected from the path).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::camera::Camera;
use super::scene_file::CAMERAS_FILE;
use super::{cameras_json, colmap};

/// Image file extensions stripped from names to get the stem label maps are matched by.
const IMAGE_EXTENSIONS: &[&str] = &[
    "png", "jpg", "jpeg", "tif", "tiff", "exr", "bmp", "webp", "gif", "ppm", "pgm", "heic", "jxl",
    "avif", "dng", "raw",
];

/// The name label maps are matched by: the file name without directories and without an
/// image extension (`images/frame.001.JPG` -> `frame.001`). Names without a known image
/// extension are kept whole, so a stem that contains dots survives a round trip.
pub fn image_name_stem(name: &str) -> String {
    let base = name.rsplit(['/', '\\']).next().unwrap_or(name);
    match base.rsplit_once('.') {
        Some((stem, ext))
            if !stem.is_empty() && IMAGE_EXTENSIONS.iter().any(|e| e.eq_ignore_ascii_case(ext)) =>
        {
            stem.to_owned()
        }
        _ => base.to_owned(),
    }
}

/// The file name of an image path without a known image extension (as in
/// [`image_name_stem`], for the last component only).
fn strip_image_extension(base: &str) -> &str {
    match base.rsplit_once('.') {
        Some((stem, ext))
            if !stem.is_empty() && IMAGE_EXTENSIONS.iter().any(|e| e.eq_ignore_ascii_case(ext)) =>
        {
            stem
        }
        _ => base,
    }
}

/// Camera names for images named by relative paths (`cam0/00001.jpg`), in the same order: the
/// stem (`00001`) where no other image has it, so ordinary datasets keep their plain names;
/// otherwise (a multi-camera rig) the relative path without extension, `/`-separated
/// (`cam0/00001`), without `.` components and without the leading folders every image shares
/// (nerfstudio's `images/`), i.e. relative to the image root that label folders mirror.
/// The names are not checked here: [`validate_cameras`] refuses `..`, absolute paths and
/// other unsafe components, and names that still collide.
pub fn image_names(paths: &[&str]) -> Vec<String> {
    let split: Vec<Vec<&str>> = paths
        .iter()
        .map(|p| p.split(['/', '\\']).filter(|c| *c != ".").collect())
        .collect();
    let common = common_folder_count(&split);
    let stems: Vec<String> = paths.iter().map(|p| image_name_stem(p)).collect();
    let mut stem_count: HashMap<&str, usize> = HashMap::new();
    for s in &stems {
        *stem_count.entry(s.as_str()).or_default() += 1;
    }
    split
        .iter()
        .zip(&stems)
        .map(|(parts, stem)| {
            if stem_count[stem.as_str()] == 1 {
                return stem.clone();
            }
            let mut rel: Vec<&str> = parts[common..].to_vec();
            if let Some(last) = rel.last_mut() {
                *last = strip_image_extension(last);
            }
            rel.join("/")
        })
        .collect()
}

/// How many leading folders (not the file name) all paths share.
fn common_folder_count(split: &[Vec<&str>]) -> usize {
    let Some(first) = split.first() else {
        return 0;
    };
    let mut n = first.len().saturating_sub(1);
    for parts in &split[1..] {
        n = n.min(parts.len().saturating_sub(1));
        n = (0..n).take_while(|&i| parts[i] == first[i]).count();
    }
    n
}

/// Renames cameras whose `name` holds their image path (as the file lists it) to
/// [`image_names`].
pub fn name_by_image_paths(cameras: &mut [Camera]) {
    let paths: Vec<&str> = cameras.iter().map(|c| c.name.as_str()).collect();
    let names = image_names(&paths);
    for (cam, name) in cameras.iter_mut().zip(names) {
        cam.name = name;
    }
}

/// Checks every camera (see [`Camera::validate`]) and that names are unique (label maps
/// are matched by name).
pub fn validate_cameras(cameras: &[Camera]) -> Result<()> {
    validate_cameras_as(cameras, |i| format!("camera {i}"))
}

/// [`validate_cameras`], each camera named in errors by `named` of its index (a COLMAP
/// model's by its image id: a position in the sorted list reads as a camera id).
pub fn validate_cameras_as(cameras: &[Camera], named: impl Fn(usize) -> String) -> Result<()> {
    let mut seen: HashMap<&str, usize> = HashMap::with_capacity(cameras.len());
    for (i, cam) in cameras.iter().enumerate() {
        cam.validate().with_context(|| named(i))?;
        if let Some(first) = seen.insert(cam.name.as_str(), i) {
            bail!(
                "{} and {} share the name '{}': names (image stems, or relative image paths \
                 where stems repeat) must be unique because label maps are matched by name",
                named(first),
                named(i),
                cam.name
            );
        }
    }
    Ok(())
}

/// Where [`load_cameras`] reads a path's cameras from: one dispatch for the reader and for
/// [`camera_files`], so what an output must not replace is what the reader reads.
enum CameraSource {
    /// A COLMAP model: the folder [`colmap::find_colmap_model`] is given.
    Colmap(PathBuf),
    /// An INRIA, nerfstudio or semsplat camera JSON.
    Json(PathBuf),
}

/// A folder is a COLMAP model (itself, `sparse/0` or `sparse`), else an INRIA training
/// output's `cameras.json`, else a nerfstudio `transforms.json`; a file by its name.
fn camera_source(path: &Path) -> Result<CameraSource> {
    if !path.exists() {
        bail!("camera path {} does not exist", path.display());
    }
    if path.is_dir() {
        if colmap::find_colmap_model(path).is_ok() {
            return Ok(CameraSource::Colmap(path.to_path_buf()));
        }
        for file in [CAMERAS_FILE, "transforms.json"] {
            if path.join(file).is_file() {
                return Ok(CameraSource::Json(path.join(file)));
            }
        }
        bail!(
            "{} is not a COLMAP model (cameras/images .bin or .txt, here, in sparse/0 or in \
             sparse) and holds no INRIA cameras.json or nerfstudio transforms.json",
            path.display()
        );
    }
    let file_name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    let is_json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if is_json {
        return Ok(CameraSource::Json(path.to_path_buf()));
    }
    let colmap_files = ["cameras", "images", "points3D", "rigs", "frames"];
    let is_colmap_file = colmap_files.iter().any(|stem| {
        file_name == format!("{stem}.bin").as_str() || file_name == format!("{stem}.txt").as_str()
    });
    if is_colmap_file {
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        return Ok(CameraSource::Colmap(dir.to_path_buf()));
    }
    bail!(
        "cannot tell the camera format of {}: expected a COLMAP model folder (cameras/images \
         .bin or .txt, or a dataset folder with sparse/0), an INRIA cameras.json, or a semsplat \
         camera JSON",
        path.display()
    )
}

/// Loads cameras from a COLMAP model folder (or a dataset folder with `sparse/0`, or one of
/// the model's files), an INRIA `cameras.json` (or a training-output folder holding one), a
/// nerfstudio `transforms.json` (or its folder), or a semsplat camera JSON. The cameras are
/// validated; errors name the file and the problem.
pub fn load_cameras(path: &Path) -> Result<Vec<Camera>> {
    match camera_source(path)? {
        CameraSource::Colmap(dir) => colmap::read_colmap_model(&dir),
        CameraSource::Json(file) => cameras_json::read_cameras_json(&file),
    }
}

/// The files [`load_cameras`] reads for `path` (a COLMAP model's cameras and images files,
/// or the JSON); `path` itself where it names no camera source (its reader says why).
pub fn camera_files(path: &Path) -> Vec<PathBuf> {
    let model = match camera_source(path) {
        Ok(CameraSource::Json(file)) => return vec![file],
        Ok(CameraSource::Colmap(dir)) => colmap::find_colmap_model(&dir).ok(),
        Err(_) => None,
    };
    match model {
        Some((dir, format)) => ["cameras", "images"]
            .map(|stem| dir.join(format!("{stem}.{}", format.ext())))
            .to_vec(),
        None => vec![path.to_path_buf()],
    }
}
