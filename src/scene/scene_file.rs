//! Opening a scene whatever form it comes in: a PLY (standard INRIA layout or SuperSplat's
//! compressed PLY), an antimatter15 `.splat`, a Niantic `.spz`, or an INRIA training-output
//! folder (`output/run` or `output/run/point_cloud`, whose latest `iteration_*/point_cloud.ply`
//! is used), or a scene folder holding `scene.ply` (as `synth` writes). semsplat writes only
//! the standard PLY. Where a command's `--cameras` is left out, the scene folder's
//! `cameras.json` is read ([`cameras_for_scene`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::gaussians::Gaussians;
use super::ply::{read_ply_unchecked, read_point_cloud_ply};
use super::point_cloud::gaussians_from_point_cloud;
use super::splat_formats::{parse_splat, parse_spz};

/// The scene file a user's `--scene` path names: the path itself for a file; for an INRIA
/// run folder (or its `point_cloud` folder) the `point_cloud.ply` of the numerically latest
/// `iteration_<N>` (so `iteration_30000` beats `iteration_7000`); for a scene folder its
/// `scene.ply`.
pub fn resolve_scene_path(path: &Path) -> Result<PathBuf> {
    if !path.is_dir() {
        if !path.exists() {
            bail!("scene {} does not exist", path.display());
        }
        return Ok(path.to_path_buf());
    }
    let iterations_dir = if path.join("point_cloud").is_dir() {
        path.join("point_cloud")
    } else {
        path.to_path_buf()
    };
    let latest = latest_iteration(&iterations_dir)?;
    match latest {
        Some(dir) => Ok(dir.join("point_cloud.ply")),
        None if path.join("point_cloud.ply").is_file() => Ok(path.join("point_cloud.ply")),
        None if path.join(SCENE_FILE).is_file() => Ok(path.join(SCENE_FILE)),
        None => bail!(
            "{} is a folder but neither an INRIA training output (point_cloud/iteration_<N>/\
             point_cloud.ply, or iteration_<N>/point_cloud.ply) nor a scene folder ({SCENE_FILE}, \
             as `synth` writes); pass a .ply, .splat or .spz file",
            path.display()
        ),
    }
}

/// The scene file of a scene folder (`synth`'s output, `bench --export`'s).
pub const SCENE_FILE: &str = "scene.ply";
/// The cameras file of a scene folder or an INRIA training output.
pub const CAMERAS_FILE: &str = "cameras.json";

/// The cameras a command reads: `cameras` where given, else the `cameras.json` of the
/// scene's folder (`scene` itself where it is a folder: a `synth` room, an INRIA run; else
/// the folder holding the scene file), said on stderr so the choice is never silent.
pub fn cameras_for_scene(cameras: Option<&Path>, scene: &Path) -> Result<PathBuf> {
    if let Some(path) = cameras {
        return Ok(path.to_path_buf());
    }
    // A mistyped scene is named as such, not as a folder without cameras.
    if !scene.exists() {
        bail!("scene {} does not exist", scene.display());
    }
    let Some(beside) = scene_cameras_file(scene) else {
        bail!(
            "--cameras is needed (a COLMAP model folder, an INRIA or nerfstudio camera file, or \
             a semsplat cameras.json): the scene's folder, {}, holds no {CAMERAS_FILE}",
            display_folder(scene_folder(scene))
        );
    };
    eprintln!(
        "cameras: {} (the scene's; --cameras to choose others)",
        beside.display()
    );
    Ok(beside)
}

/// The folder a scene given as a file or a folder lies in.
fn scene_folder(scene: &Path) -> &Path {
    match scene.is_dir() {
        true => scene,
        false => scene.parent().unwrap_or(Path::new("")),
    }
}

/// The scene's own cameras, where it has them: the `cameras.json` of its folder, or of the
/// INRIA run it lies in (`run/point_cloud` or `run/point_cloud/iteration_N`, the cameras
/// at `run/cameras.json`).
pub fn scene_cameras_file(scene: &Path) -> Option<PathBuf> {
    let folder = scene_folder(scene);
    // Absolute, so that `.` or a scene given from inside the run names its folders.
    let here = if folder.as_os_str().is_empty() {
        Path::new(".")
    } else {
        folder
    };
    let absolute = lexically_normal(&std::path::absolute(here).ok()?);
    let name_of = |p: &Path| p.file_name().and_then(|n| n.to_str()).map(str::to_owned);
    let mut run = absolute.as_path();
    if name_of(run).is_some_and(|n| n.starts_with("iteration_")) {
        run = run.parent().unwrap_or(run);
    }
    let run: Option<PathBuf> = match name_of(run).as_deref() {
        Some("point_cloud") => run.parent().map(Path::to_path_buf),
        _ => None,
    };
    [Some(folder.to_path_buf()), run]
        .into_iter()
        .flatten()
        .map(|f| f.join(CAMERAS_FILE))
        .find(|c| c.is_file())
}

/// `path` with its `.` and `..` resolved by name (`run/point_cloud/iteration_7/..` is
/// `run/point_cloud`), as a message's reader would: no links are followed.
fn lexically_normal(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for part in path.components() {
        match part {
            std::path::Component::CurDir => {}
            std::path::Component::ParentDir => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// A folder as a message names it (the current folder as `.`).
fn display_folder(folder: &Path) -> String {
    match folder.as_os_str().is_empty() {
        true => ".".into(),
        false => folder.display().to_string(),
    }
}

/// The `iteration_<N>` folder with the largest N that holds a `point_cloud.ply`.
fn latest_iteration(dir: &Path) -> Result<Option<PathBuf>> {
    let mut iterations: Vec<(u64, PathBuf)> = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("listing {}", dir.display()))? {
        let entry = entry?;
        let name = entry.file_name();
        let number = (name.to_str())
            .and_then(|s| s.strip_prefix("iteration_"))
            .and_then(|s| s.parse::<u64>().ok());
        if let Some(n) = number {
            iterations.push((n, entry.path()));
        }
    }
    iterations.sort();
    let has_cloud = |(_, path): &&(u64, PathBuf)| path.join("point_cloud.ply").is_file();
    let latest = iterations
        .iter()
        .rev()
        .find(has_cloud)
        .map(|(_, p)| p.clone());
    // A newer iteration without its point cloud (a run still writing, or cut short): the
    // older one is used, and said so rather than silently.
    if let (Some((_, newest)), Some(used)) = (iterations.last(), &latest) {
        // Once a process: a command resolves its scene more than once.
        static NOTED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
        let mut noted = NOTED.lock().unwrap_or_else(|p| p.into_inner());
        if newest != used && !noted.contains(newest) {
            eprintln!(
                "note: {} holds no point_cloud.ply; using {}",
                newest.display(),
                used.join("point_cloud.ply").display()
            );
            noted.push(newest.clone());
        }
    }
    Ok(latest)
}

/// Which reader a scene file needs, from its extension (PLY variants are told apart by their
/// header).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    Ply,
    Splat,
    Spz,
}

pub fn scene_format(path: &Path) -> Result<SceneFormat> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    Ok(match ext.as_str() {
        "ply" => SceneFormat::Ply,
        "splat" => SceneFormat::Splat,
        "spz" => SceneFormat::Spz,
        "ksplat" => bail!(
            "{}: .ksplat (mkkellogg's GaussianSplats3D format) is not supported; convert it to PLY \
             first (e.g. with that viewer's exporter)",
            path.display()
        ),
        "sog" | "json" | "glb" | "gltf" => bail!(
            "{}: .{ext} is not a supported scene format (supported: .ply, SuperSplat's \
             .compressed.ply, .splat, .spz); convert it to PLY first (e.g. with PlayCanvas \
             splat-transform)",
            path.display()
        ),
        _ => SceneFormat::Ply,
    })
}

/// Reads a scene in any supported form (see the module docs), values checked.
pub fn read_scene(path: &Path) -> Result<Gaussians> {
    let g = read_scene_unchecked(path)?;
    let file = resolve_scene_path(path)?;
    g.validate()
        .with_context(|| format!("scene {}", file.display()))?;
    Ok(g)
}

/// Like [`read_scene`] without the value checks (for `inspect`).
pub fn read_scene_unchecked(path: &Path) -> Result<Gaussians> {
    let file = resolve_scene_path(path)?;
    let format = scene_format(&file)?;
    let bytes = || std::fs::read(&file).with_context(|| format!("reading {}", file.display()));
    match format {
        SceneFormat::Ply => read_ply_unchecked(&file),
        SceneFormat::Splat => {
            parse_splat(&bytes()?).with_context(|| format!(".splat file {}", file.display()))
        }
        SceneFormat::Spz => {
            parse_spz(&bytes()?).with_context(|| format!(".spz file {}", file.display()))
        }
    }
}

/// A scene to start training from: any scene [`read_scene`] reads, or a plain point-cloud PLY
/// (an SfM `input.ply`) seeded into Gaussians by [`gaussians_from_point_cloud`] (said on
/// stderr, since the seed's scales and opacities are guesses, as in INRIA 3DGS).
pub fn read_scene_or_point_cloud(path: &Path) -> Result<Gaussians> {
    let file = resolve_scene_path(path)?;
    if path.is_dir() {
        // A synth room holds init.ply (its points) beside scene.ply (the true scene): say
        // which one a folder gave.
        eprintln!("{}: starting from {}", path.display(), file.display());
    }
    if scene_format(&file)? == SceneFormat::Ply {
        if let Some(cloud) = read_point_cloud_ply(&file)? {
            let g = gaussians_from_point_cloud(&cloud)
                .with_context(|| format!("point cloud {}", file.display()))?;
            eprintln!(
                "{} is a point cloud: seeded {} Gaussians from its points (INRIA 3DGS's \
                 initialization)",
                file.display(),
                g.len()
            );
            g.validate()?;
            return Ok(g);
        }
    }
    read_scene(&file)
}
