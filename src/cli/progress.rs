//! The progress bar of commands that walk views, on stderr (indicatif hides it when stderr
//! is not a terminal, so logs and JSON on stdout stay clean).

use indicatif::{ProgressBar, ProgressStyle};

/// A bar counting views, with throughput, ETA and a message (e.g. the phase) after them.
pub fn views_bar(len: usize) -> ProgressBar {
    ProgressBar::new(len as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} views {per_sec} eta {eta} {msg}")
            .expect("valid template"),
    )
}
