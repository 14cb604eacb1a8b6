//! One module per subcommand, and what several of them share.

pub mod args;
pub mod bench;
pub mod demo;
pub mod eval;
pub mod fuse;
pub mod info;
pub mod inspect;
pub mod joint_args;
pub mod progress;
pub mod render;
pub mod sweep;
pub mod synth;
pub mod train;

use std::path::Path;

use anyhow::Result;
use semsplat::dataset::{Dataset, DatasetPaths};
use semsplat::fuse::LabelSource;
use semsplat::scene::classes::ClassTable;
use semsplat::scene::ply::{write_classes_sidecar, write_ply_to};
use semsplat::scene::{Camera, Gaussians};
use semsplat::util::interrupt;
use semsplat::util::{check_output_file, check_output_folder, stage_atomic};

/// Opens the dataset and notes on stderr how many cameras have no label map and what
/// happens to them (`skipped`: "are skipped", "train appearance only").
pub fn open_dataset(paths: &DatasetPaths, skipped: &str) -> Result<Dataset> {
    let data = Dataset::open(paths)?;
    if !data.labels.skipped().is_empty() {
        eprintln!(
            "note: {} views have no label map and {skipped}",
            data.labels.skipped().len()
        );
    }
    Ok(data)
}

/// Checks, before any long work, that every output can be written (see
/// [`check_output_file`]): `files` and `folders` pair each path with its option's name.
/// Missing options are `None` and skipped.
pub fn check_outputs(
    files: &[(&str, Option<&Path>)],
    folders: &[(&str, Option<&Path>)],
) -> Result<()> {
    for (option, path) in files {
        if let Some(path) = path {
            check_output_file(option, path)?;
        }
    }
    for (option, path) in folders {
        if let Some(path) = path {
            check_output_folder(option, path)?;
        }
    }
    Ok(())
}

/// Writes a classified scene and its class table (`<out>.classes.json`) so that they never
/// mismatch: the PLY is written in full to a temp file first, then the table is renamed into
/// place, then the PLY. A failure while writing changes neither; a kill can only pair the new
/// table with the old PLY, never a new PLY with an old table.
pub fn write_scene_with_table(out: &Path, g: &Gaussians, table: &ClassTable) -> Result<()> {
    let ply = stage_atomic(out, |w| write_ply_to(w, g))?;
    write_classes_sidecar(out, table)?;
    ply.commit()
}

/// A label source that stops the run at the next view once Ctrl-C was pressed.
pub struct Interruptible<'a>(pub &'a dyn LabelSource);

impl LabelSource for Interruptible<'_> {
    fn labels(&self, view: usize, cam: &Camera) -> Result<Option<Vec<u32>>> {
        interrupt::check()?;
        self.0.labels(view, cam)
    }
}
