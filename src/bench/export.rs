//! Writes a benchmark's inputs as files other tools read (`--export DIR`): the scene as an
//! INRIA 3DGS PLY, the cameras as semsplat camera JSON, the label maps as one `.npy`, and a
//! `bench.json` saying what they are. Peer renderers benchmarked beside semsplat (gsplat,
//! FlashSplat's rasterizer; `tools/gpu/`) then work on the same bytes.

use std::path::Path;

use anyhow::{ensure, Context, Result};
use serde::Serialize;

use crate::fuse::{LabelSource, NO_LABEL};
use crate::render::RenderOptions;
use crate::scene::cameras_json::write_semsplat_cameras;
use crate::scene::ply::write_ply;
use crate::scene::scene_file::{CAMERAS_FILE, SCENE_FILE};
use crate::scene::{Camera, Gaussians};
use crate::util::atomic_write::write_bytes_atomic;
use crate::util::npy::write_npy_rows;

/// `labels.npy`'s value for an unlabeled pixel (a `u16` class id otherwise).
pub const EXPORT_NO_LABEL: u16 = u16::MAX;

/// `bench.json`: what the exported files hold.
#[derive(Serialize)]
struct ExportMeta {
    n: usize,
    /// Semantic channels in the PLY (`sem_*` properties).
    channels: usize,
    /// Label classes of `labels.npy` (0 without labels).
    classes: usize,
    width: u32,
    height: u32,
    views: usize,
    near: f32,
    far: f32,
    sh_degree: u32,
    /// `labels.npy`'s value for an unlabeled pixel.
    no_label: u16,
}

/// The label maps' file of an export (`uint16 [views, height, width]`).
pub const LABELS_FILE: &str = "labels.npy";
/// The benchmark's description in an export.
pub const META_FILE: &str = "bench.json";
/// Every file an export may write into its folder.
pub const EXPORT_FILES: [&str; 4] = [SCENE_FILE, CAMERAS_FILE, LABELS_FILE, META_FILE];

/// Label maps to export: the source and its class count.
pub struct ExportLabels<'a> {
    pub source: &'a dyn LabelSource,
    pub classes: usize,
}

/// Writes `scene.ply`, `cameras.json`, `bench.json` and (with `labels`) `labels.npy`
/// (`uint16 [views, height, width]`, [`EXPORT_NO_LABEL`] where unlabeled) into `dir`.
pub fn export_inputs(
    dir: &Path,
    g: &Gaussians,
    cams: &[Camera],
    opts: &RenderOptions,
    labels: Option<ExportLabels>,
) -> Result<()> {
    ensure!(!cams.is_empty(), "no camera to export");
    let (width, height) = (cams[0].width, cams[0].height);
    ensure!(
        cams.iter().all(|c| (c.width, c.height) == (width, height)),
        "the exported cameras must share one image size"
    );
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the export folder {}", dir.display()))?;
    write_ply(&dir.join(SCENE_FILE), g)?;
    write_semsplat_cameras(&dir.join(CAMERAS_FILE), cams)?;
    let classes = labels.as_ref().map_or(0, |l| l.classes);
    if let Some(l) = labels {
        export_labels(&dir.join(LABELS_FILE), cams, &l)?;
    }
    let meta = ExportMeta {
        n: g.len(),
        channels: g.semantics.as_ref().map_or(0, |s| s.channels),
        classes,
        width,
        height,
        views: cams.len(),
        near: opts.near,
        far: opts.far,
        sh_degree: g.sh_degree,
        no_label: EXPORT_NO_LABEL,
    };
    write_bytes_atomic(&dir.join(META_FILE), &serde_json::to_vec_pretty(&meta)?)
}

/// Streams every view's label map into one `uint16` array, view by view.
fn export_labels(path: &Path, cams: &[Camera], labels: &ExportLabels) -> Result<()> {
    ensure!(
        labels.classes < EXPORT_NO_LABEL as usize,
        "{} classes do not fit a uint16 label map",
        labels.classes
    );
    let (w, h) = (cams[0].width as u64, cams[0].height as u64);
    write_npy_rows::<u16, Vec<u16>>(path, &[cams.len() as u64, h, w], |view| {
        let map = labels
            .source
            .labels(view, &cams[view])?
            .unwrap_or_else(|| vec![NO_LABEL; (w * h) as usize]);
        Ok(map
            .into_iter()
            .map(|c| {
                if c == NO_LABEL {
                    EXPORT_NO_LABEL
                } else {
                    c as u16
                }
            })
            .collect())
    })
}
