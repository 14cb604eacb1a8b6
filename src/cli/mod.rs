//! One module per subcommand, and what several of them share.

pub mod bench;
pub mod demo;
pub mod eval;
pub mod fuse;
pub mod info;
pub mod inspect;
pub mod joint_args;
pub mod merge;
pub mod progress;
pub mod render;
pub mod sweep;
pub mod synth;
pub mod train;

use anyhow::Result;
use semsplat::dataset::{Dataset, DatasetPaths};

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
