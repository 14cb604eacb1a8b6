//! The progress bars of the commands, on stderr (JSON on stdout stays clean). Where stderr
//! is not a terminal (a batch job's log, a pipe) a bar is a plain line of its counts every
//! [`LOG_EVERY`] instead: a fusion of a capture runs for minutes, and a log that shows
//! nothing in that time looks like a hung job. The library reports progress through
//! callbacks; only this layer draws.

use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle, TermLike};

/// How often a bar writes its line where stderr is not a terminal.
pub const LOG_EVERY: Duration = Duration::from_secs(15);

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
    let template = "{msg:>12} [{bar:32}] {pos}/{len} views ({elapsed})";
    let bar = drawn(ProgressBar::new(0), template, Some("=> "));
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
    drawn(bar, template, None)
}

/// `bar` drawn with `template` (and `chars` for its bar, else indicatif's) on a terminal;
/// elsewhere as [`LogLines`], without the template's bar (a log line of `=>` or blocks
/// says nothing its counts do not).
fn drawn(bar: ProgressBar, template: &str, chars: Option<&str>) -> ProgressBar {
    if std::io::stderr().is_terminal() {
        let style = ProgressStyle::with_template(template).expect("valid template");
        return bar.with_style(match chars {
            Some(chars) => style.progress_chars(chars),
            None => style,
        });
    }
    let style = ProgressStyle::with_template(&without_bar(template)).expect("valid template");
    bar.set_draw_target(ProgressDrawTarget::term_like_with_hz(
        Box::new(LogLines::every(LOG_EVERY)),
        1,
    ));
    bar.with_style(style)
}

/// `template` less its `{bar...}` field and what encloses it (`[{bar:32}] `).
fn without_bar(template: &str) -> String {
    let Some(start) = template.find("{bar") else {
        return template.to_string();
    };
    let end = start + template[start..].find('}').expect("a closed field") + 1;
    let (mut before, mut after) = (&template[..start], &template[end..]);
    if before.ends_with('[') && after.starts_with(']') {
        (before, after) = (&before[..before.len() - 1], &after[1..]);
    }
    format!("{}{}", before, after.trim_start())
}

/// A bar's drawing turned into a line on stderr at most once every `every`: indicatif
/// draws a bar as text written, padding and a flush, moving the cursor back over the last
/// drawing first; the text is kept, the cursor's moves dropped, and on a flush the text is
/// written as one line if `every` has passed since the last (the first after `every`).
#[derive(Debug)]
struct LogLines {
    every: Duration,
    state: Mutex<LogState>,
}

#[derive(Debug)]
struct LogState {
    text: String,
    last: Instant,
}

impl LogLines {
    fn every(every: Duration) -> Self {
        let state = LogState {
            text: String::new(),
            last: Instant::now(),
        };
        LogLines {
            every,
            state: Mutex::new(state),
        }
    }

    /// The line a flush writes, if any: the text since the last flush, once `every` passed.
    fn line_at(&self, now: Instant) -> Option<String> {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let text = std::mem::take(&mut state.text);
        let line = text.trim();
        if line.is_empty() || now.duration_since(state.last) < self.every {
            return None;
        }
        state.last = now;
        Some(line.to_string())
    }
}

impl TermLike for LogLines {
    fn width(&self) -> u16 {
        // Wide enough that indicatif never wraps or cuts a line; the padding is trimmed.
        400
    }

    fn height(&self) -> u16 {
        1
    }

    fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }

    fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }

    fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }

    fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
        Ok(())
    }

    fn write_line(&self, s: &str) -> std::io::Result<()> {
        self.write_str(s)
    }

    fn write_str(&self, s: &str) -> std::io::Result<()> {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        state.text.push_str(s);
        Ok(())
    }

    fn clear_line(&self) -> std::io::Result<()> {
        Ok(())
    }

    fn flush(&self) -> std::io::Result<()> {
        match self.line_at(Instant::now()) {
            Some(line) => writeln!(std::io::stderr(), "{line}"),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_line_drops_the_bar_and_its_brackets() {
        assert_eq!(
            without_bar("{bar:40} {pos}/{len} views {msg}"),
            "{pos}/{len} views {msg}"
        );
        assert_eq!(
            without_bar("{msg:>12} [{bar:32}] {pos}/{len} views ({elapsed})"),
            "{msg:>12} {pos}/{len} views ({elapsed})"
        );
        assert_eq!(without_bar("{pos}/{len}"), "{pos}/{len}");
    }

    /// A drawing's text becomes one trimmed line, at most once every `every`: the drawings
    /// between are dropped, not queued.
    #[test]
    fn log_lines_write_a_drawing_once_every_interval() {
        let log = LogLines::every(Duration::from_secs(15));
        let start = log.state.lock().unwrap().last;
        let draw = |text: &str| {
            log.write_str(text).unwrap();
            log.write_str("      ").unwrap();
        };
        draw("3/190 views");
        assert_eq!(log.line_at(start + Duration::from_secs(5)), None);
        draw("40/190 views");
        assert_eq!(
            log.line_at(start + Duration::from_secs(16)).as_deref(),
            Some("40/190 views")
        );
        draw("41/190 views");
        assert_eq!(log.line_at(start + Duration::from_secs(20)), None);
        draw("90/190 views");
        assert_eq!(
            log.line_at(start + Duration::from_secs(31)).as_deref(),
            Some("90/190 views")
        );
    }
}
