//! Ctrl-C (SIGINT), SIGTERM and SIGHUP: the long loops stop cleanly, and no partial output
//! or temp file is left behind. A closed standard output (SIGPIPE) ends the process quietly.
//!
//! The handler sets a flag that the commands' loops poll ([`check`]); a cooperative command
//! then returns [`Interrupted`] and exits with [`EXIT_CODE`]. [`write_atomic`] refuses to
//! start or rename a file once the flag is set, so nothing new appears after Ctrl-C. A
//! second signal, or the first one while a command that does not poll runs, removes every
//! temp file in flight and exits at once.
//!
//! [`write_atomic`]: super::write_atomic

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard};

/// The shell's convention for "terminated by SIGINT" (128 + 2).
pub const EXIT_CODE: u8 = 130;

static INTERRUPTED: AtomicBool = AtomicBool::new(false);
static COOPERATIVE: AtomicBool = AtomicBool::new(false);
/// Temp files being written ([`super::atomic_write`]); created and renamed under this lock so
/// the handler never races a file into existence after removing the others.
static TEMP_FILES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The error a run stopped by a signal returns (main maps it to [`EXIT_CODE`]).
#[derive(Debug, thiserror::Error)]
#[error("interrupted (Ctrl-C or a termination signal): stopped before finishing; no file was left half-written")]
pub struct Interrupted;

/// Whether `e` (or any error in its chain) is [`Interrupted`].
pub fn is_interruption(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.is::<Interrupted>())
}

/// Installs the signal handler. `cooperative`: the command polls [`check`] in its long loops,
/// so the first signal only sets the flag; otherwise the first signal exits at once (after
/// removing temp files).
pub fn install_handler(cooperative: bool) -> anyhow::Result<()> {
    COOPERATIVE.store(cooperative, Ordering::SeqCst);
    ctrlc::set_handler(on_signal).map_err(|e| anyhow::anyhow!("installing the Ctrl-C handler: {e}"))
}

/// Lets a closed standard output (`semsplat eval ... | head`) end the process quietly, as it
/// ends a shell tool, instead of panicking at the next print: SIGPIPE back to its default
/// action (Rust starts programs with it ignored, so a write to the closed pipe fails and
/// `println!` panics). Outputs are written to temp files and renamed ([`super::write_atomic`]),
/// so no partial output can appear (a temp file the signal cuts short is a dead run's, which
/// the next write to that folder removes); the process writes to no other pipe or socket.
pub fn end_quietly_on_closed_stdout() {
    #[cfg(unix)]
    // SAFETY: called at the start of main, before any thread starts; SIG_DFL is a valid
    // disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Whether a signal arrived.
pub fn is_interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// `Err(Interrupted)` once a signal arrived: call it once per view, iteration or step.
pub fn check() -> Result<(), Interrupted> {
    if is_interrupted() {
        Err(Interrupted)
    } else {
        Ok(())
    }
}

/// The registry of temp files in flight (poison-tolerant: a panicking writer must not stop
/// the handler from cleaning up).
pub(crate) fn temp_files() -> MutexGuard<'static, Vec<PathBuf>> {
    TEMP_FILES.lock().unwrap_or_else(|p| p.into_inner())
}

/// Runs on ctrlc's own thread, not in signal context, so locking and file removal are safe.
fn on_signal() {
    let mut temps = temp_files();
    let again = INTERRUPTED.swap(true, Ordering::SeqCst);
    if again || !COOPERATIVE.load(Ordering::SeqCst) {
        for tmp in temps.drain(..) {
            let _ = std::fs::remove_file(tmp);
        }
        eprintln!("error: {Interrupted}");
        // Exits holding the lock: no writer can create or rename a file after this point.
        std::process::exit(i32::from(EXIT_CODE));
    }
    eprintln!("interrupting: stopping after the current step (press Ctrl-C again to stop at once)");
}
