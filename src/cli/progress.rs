//! The progress bars of the commands, on stderr (indicatif hides them when stderr is not a
//! terminal, so logs and JSON on stdout stay clean). The library reports progress through
//! callbacks; only this layer draws.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar counting views, with throughput, ETA and a message (e.g. the phase) after them.
pub fn views_bar(len: usize) -> ProgressBar {
    styled(
        ProgressBar::new(len as u64),
        "{bar:40} {pos}/{len} views {per_sec} eta {eta} {msg}",
    )
}

/// A bar counting rendered views, with the current view's name after it.
pub fn render_bar(len: usize) -> ProgressBar {
    styled(
        ProgressBar::new(len as u64),
        "{bar:40} {pos}/{len} views {msg}",
    )
}

/// A bar counting training iterations, with the latest losses after it.
pub fn iterations_bar(len: u32) -> ProgressBar {
    styled(
        ProgressBar::new(len as u64),
        "{bar:30} {pos}/{len} it {per_sec} eta {eta} {msg}",
    )
}

/// A bar for one phase of `synth` ("ray casting", "writing"), named before it.
pub fn phase_bar(what: &'static str) -> ProgressBar {
    let bar = ProgressBar::new(0);
    if let Ok(style) =
        ProgressStyle::with_template("{msg:>12} [{bar:32}] {pos}/{len} views ({elapsed})")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what);
    bar
}

/// A `(done, total)` progress callback that moves `bar`.
pub fn follow(bar: &ProgressBar) -> impl Fn(usize, usize) + Sync + '_ {
    move |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    }
}

fn styled(bar: ProgressBar, template: &str) -> ProgressBar {
    bar.with_style(ProgressStyle::with_template(template).expect("valid template"))
}
