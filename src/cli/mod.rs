//! One module per subcommand, and what several of them share.

/// `println!` for the commands whose results are files (`sweep`, `demo`): a standard
/// output that cannot be written (a pipe closed by `head`, a full disk) is said once on
/// stderr and the run goes on to write its files ([`print_line`]).
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::cli::print_line(format_args!($($arg)*))
    };
}

pub mod args;
pub mod bench;
pub mod demo;
pub mod eval;
pub mod fuse;
pub mod fuse_consensus;
pub mod info;
pub mod inspect;
pub mod joint_args;
pub mod merge;
pub mod progress;
pub mod render;
pub mod run_paths;
pub mod sweep;
pub mod synth;
pub mod train;

use std::path::Path;

use anyhow::{Context, Result};
use clap::Args;
use semsplat::dataset::{Dataset, DatasetPaths};
use semsplat::fuse::LabelSource;
use semsplat::scene::classes::ClassTable;
use semsplat::scene::labels::{list_some, LabelFormat};
use semsplat::scene::ply::{write_classes_sidecar, write_ply_to};
use semsplat::scene::{Camera, Gaussians};
use semsplat::util::interrupt;
use semsplat::util::stage_atomic;

pub use run_paths::{check_outputs, Input};

/// What to check when views see none of a scene (fuse, train, eval), completed by each.
pub const FRAME_HINT: &str = "Check that the cameras and the scene share one frame and scale \
     (a nerfstudio export's applied_transform, cameras of another reconstruction), that the \
     Gaussians are not all transparent (semsplat inspect SCENE)";

/// How label maps are read, shared by every command that reads them.
#[derive(Args, Clone, Copy, Debug, Default)]
pub struct LabelFormatArgs {
    /// Label value that means "no label" (0..65535). Default: 255 in 8-bit maps and 65535
    /// in 16-bit maps; ADE20K and ScanNet use 0. 65535 in a 16-bit map is always ignored.
    /// Binary masks (e.g. SAM's 0/255) need a value they do not use, or their object
    /// vanishes (a warning says so). Accepted map layouts: docs/label-maps.md.
    #[arg(long, value_name = "N")]
    pub ignore_id: Option<u16>,
}

impl LabelFormatArgs {
    pub fn format(&self) -> LabelFormat {
        LabelFormat::with_ignore_id(self.ignore_id)
    }
}

/// Opens the dataset and notes on stderr how many cameras have no label map and what
/// happens to them (`skipped`: "are skipped", "train appearance only"), and the dataset's
/// warnings (scaled intrinsics, binary masks).
pub fn open_dataset(paths: &DatasetPaths, skipped: &str) -> Result<Dataset> {
    let data = Dataset::open(paths)?;
    for warning in &data.warnings {
        eprintln!("{warning}");
    }
    if !data.labels.skipped().is_empty() {
        eprintln!(
            "note: {} views have no label map and {skipped}: {}",
            data.labels.skipped().len(),
            list_some(data.labels.skipped())
        );
    }
    Ok(data)
}

/// Writes a classified scene and its class table (`<out>.classes.json`) so that they never
/// mismatch: the PLY is written in full to a temp file first, then the table is renamed into
/// place, then the PLY. A failure while writing changes neither; a kill can only pair the new
/// table with the old PLY, never a new PLY with an old table.
/// A scene with non-finite values (a diverged training run) is refused, not written.
pub fn write_scene_with_table(out: &Path, g: &Gaussians, table: &ClassTable) -> Result<()> {
    g.validate()
        .with_context(|| format!("refusing to write {}", out.display()))?;
    let ply = stage_atomic(out, |w| write_ply_to(w, g))?;
    write_classes_sidecar(out, table)?;
    ply.commit()
}

/// A label source that stops the run at the next view once Ctrl-C was pressed: no map is
/// read after it, and no view's GPU work starts.
pub struct Interruptible<'a>(pub &'a dyn LabelSource);

impl LabelSource for Interruptible<'_> {
    fn labels(&self, view: usize, cam: &Camera) -> Result<Option<Vec<u32>>> {
        interrupt::check()?;
        self.0.labels(view, cam)
    }

    fn before_view(&self, view: usize) -> Result<()> {
        interrupt::check()?;
        self.0.before_view(view)
    }
}

/// Writes one line to standard output; where it fails, says so once on stderr (the
/// command's files are its results, and are still written).
pub fn print_line(line: std::fmt::Arguments) {
    use std::io::Write;
    static SAID: std::sync::Once = std::sync::Once::new();
    if let Err(e) = writeln!(std::io::stdout(), "{line}") {
        SAID.call_once(|| {
            eprintln!("note: writing standard output: {e}; the results still go to the files")
        });
    }
}

#[cfg(test)]
mod tests {
    use semsplat::scene::classes::{read_class_table, ClassTable};
    use semsplat::scene::ply::{classes_sidecar_path, read_ply};
    use semsplat::scene::Gaussians;

    use super::write_scene_with_table;

    fn scene(n: usize, class: i32) -> Gaussians {
        Gaussians {
            means: vec![[0.0, 1.0, 2.0]; n],
            log_scales: vec![[0.0; 3]; n],
            quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
            opacity_logits: vec![0.5; n],
            sh_degree: 0,
            sh: vec![0.1; 3 * n],
            class_ids: Some(vec![class; n]),
            ..Default::default()
        }
    }

    /// A failed write of either file leaves the old pair as it was, with no temp file.
    #[test]
    fn a_failed_write_keeps_the_old_scene_and_table_together() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("fused.ply");
        write_scene_with_table(&out, &scene(2, 0), &ClassTable::from_ids([0])).unwrap();
        let files = || std::fs::read_dir(dir.path()).unwrap().count();
        assert_eq!(files(), 2);

        // The PLY cannot be written (inconsistent layout): neither file changes.
        let mut broken = scene(3, 1);
        broken.sh.pop();
        assert!(write_scene_with_table(&out, &broken, &ClassTable::from_ids([1])).is_err());
        // The table cannot be written (invalid: a duplicate id): the PLY does not change.
        let mut bad_table = ClassTable::from_ids([1]);
        bad_table.classes.push(bad_table.classes[0].clone());
        assert!(write_scene_with_table(&out, &scene(3, 1), &bad_table).is_err());

        assert_eq!(read_ply(&out).unwrap().len(), 2);
        let table = read_class_table(&classes_sidecar_path(&out)).unwrap();
        assert_eq!(table.classes.iter().map(|c| c.id).collect::<Vec<_>>(), [0]);
        assert_eq!(files(), 2, "a temp file was left");

        // And a good write replaces both.
        write_scene_with_table(&out, &scene(3, 1), &ClassTable::from_ids([1])).unwrap();
        assert_eq!(read_ply(&out).unwrap().len(), 3);
        assert_eq!(files(), 2);
    }
}
