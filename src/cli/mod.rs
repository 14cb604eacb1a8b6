//! One module per subcommand, and what several of them share.

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

use anyhow::Result;
use clap::Args;
use semsplat::dataset::{Dataset, DatasetPaths};
use semsplat::scene::labels::LabelFormat;

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
            "note: {} views have no label map and {skipped}",
            data.labels.skipped().len()
        );
    }
    Ok(data)
}
