//! Ctrl-C (SIGINT), SIGTERM and SIGHUP: the long loops stop cleanly, and no partial output
//! or temp file is left behind. A closed standard output (SIGPIPE) ends the process quietly
//! (but for `sweep` and `demo`, whose results are files: they go on and write them).
//!
//! The handler sets a flag that the commands' loops poll ([`check`]); a cooperative command
//! then returns [`Interrupted`] and exits with [`EXIT_CODE`]. [`write_atomic`] refuses to
//! start or rename a file once the flag is set, so nothing new appears after Ctrl-C. A
//! second signal, or the first one while a command that does not poll runs, removes every
//! temp file in flight and exits at once.
//!
//! [`write_atomic`]: super::write_atomic

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::{Mutex, MutexGuard};

/// The shell's convention for "terminated by SIGINT" (128 + 2), where no signal number is
/// known.
const SIGINT_EXIT_CODE: u8 = 130;

static INTERRUPTED: AtomicBool = AtomicBool::new(false);
/// The first signal that arrived (0: none), whose number the exit status carries.
static FIRST_SIGNAL: AtomicI32 = AtomicI32::new(0);
/// The pipe's write end the raw handler wakes the handling thread through (-1: none yet).
static WAKE_FD: AtomicI32 = AtomicI32::new(-1);
static COOPERATIVE: AtomicBool = AtomicBool::new(false);
/// Temp files being written ([`super::atomic_write`]); created and renamed under this lock so
/// the handler never races a file into existence after removing the others.
static TEMP_FILES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// The error a run stopped by a signal returns (main maps it to [`exit_code`]).
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
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let read_fd =
            raw::install().map_err(|e| anyhow::anyhow!("installing the Ctrl-C handler: {e}"))?;
        std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || raw::wait_for_signals(read_fd))?;
    }
    Ok(())
}

/// The exit status of a run a signal stopped: 128 plus the first signal's number, as a
/// shell reports a process that signal killed (130 for Ctrl-C, 143 for SIGTERM, 129 for
/// SIGHUP).
pub fn exit_code() -> u8 {
    match FIRST_SIGNAL.load(Ordering::SeqCst) {
        signal @ 1..=127 => 128 + signal as u8,
        _ => SIGINT_EXIT_CODE,
    }
}

/// The raw handlers: each only records its signal and writes one byte to a pipe (both safe
/// in a signal handler); a thread reading the pipe does the rest ([`on_signal`]) outside
/// signal context.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod raw {
    use super::{on_signal, FIRST_SIGNAL, WAKE_FD};
    use std::io;
    use std::sync::atomic::Ordering;

    const SIGNALS: [libc::c_int; 3] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP];

    extern "C" fn on_raw_signal(signal: libc::c_int) {
        let _ = FIRST_SIGNAL.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
        let byte = signal as u8;
        // SAFETY: write(2) is async-signal-safe; the fd is the pipe's write end, or -1 (then
        // write fails with EBADF, harmlessly). A full pipe drops the byte: the thread has
        // unread bytes to wake on already.
        unsafe {
            libc::write(
                WAKE_FD.load(Ordering::SeqCst),
                (&byte as *const u8).cast(),
                1,
            );
        }
    }

    /// Creates the pipe and installs the handler for SIGINT, SIGTERM and SIGHUP; returns
    /// the pipe's read end.
    pub(super) fn install() -> io::Result<libc::c_int> {
        let mut fds = [0 as libc::c_int; 2];
        // SAFETY: fds has room for the two descriptors pipe2 writes.
        if unsafe { libc::pipe2(fds.as_mut_ptr(), libc::O_CLOEXEC) } != 0 {
            return Err(io::Error::last_os_error());
        }
        // The handler must never block on a full pipe.
        // SAFETY: fds[1] is the pipe's write end, just created.
        if unsafe { libc::fcntl(fds[1], libc::F_SETFL, libc::O_NONBLOCK) } != 0 {
            return Err(io::Error::last_os_error());
        }
        WAKE_FD.store(fds[1], Ordering::SeqCst);
        for signal in SIGNALS {
            // SAFETY: a zeroed sigaction is valid; the handler is an extern "C" fn of one
            // c_int, and SA_RESTART keeps the program's blocking reads going.
            unsafe {
                let mut action: libc::sigaction = std::mem::zeroed();
                action.sa_sigaction = on_raw_signal as extern "C" fn(libc::c_int) as usize;
                action.sa_flags = libc::SA_RESTART;
                libc::sigemptyset(&mut action.sa_mask);
                if libc::sigaction(signal, &action, std::ptr::null_mut()) != 0 {
                    return Err(io::Error::last_os_error());
                }
            }
        }
        Ok(fds[0])
    }

    /// Runs [`on_signal`] for each signal the raw handler passed through the pipe.
    pub(super) fn wait_for_signals(read_fd: libc::c_int) {
        loop {
            let mut byte = 0u8;
            // SAFETY: reads one byte into `byte` from the pipe's read end.
            let n = unsafe { libc::read(read_fd, (&mut byte as *mut u8).cast(), 1) };
            match n {
                1 => on_signal(),
                _ if io::Error::last_os_error().kind() == io::ErrorKind::Interrupted => {}
                _ => return,
            }
        }
    }
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

/// Removes every temp file in flight and exits with `code` (an exit that skips their
/// owners' cleanup), after saying `error`.
pub fn exit_removing_temp_files(error: &str, code: u8) -> ! {
    remove_and_exit(temp_files(), error, code)
}

/// Exits holding the registry's lock (`temps`): no writer can create or rename a file
/// after its temp files are removed.
fn remove_and_exit(mut temps: MutexGuard<'static, Vec<PathBuf>>, error: &str, code: u8) -> ! {
    for tmp in temps.drain(..) {
        let _ = std::fs::remove_file(tmp);
    }
    eprintln!("error: {error}");
    std::process::exit(i32::from(code));
}

/// Runs on the signals thread, not in signal context, so locking and file removal are safe.
fn on_signal() {
    let temps = temp_files();
    let again = INTERRUPTED.swap(true, Ordering::SeqCst);
    if again || !COOPERATIVE.load(Ordering::SeqCst) {
        remove_and_exit(temps, &Interrupted.to_string(), exit_code());
    }
    drop(temps);
    let again = match FIRST_SIGNAL.load(Ordering::SeqCst) {
        2 | 0 => "press Ctrl-C again", // SIGINT (2), or none known
        _ => "send the signal again, or press Ctrl-C,",
    };
    eprintln!("interrupting: stopping after the current step ({again} to stop at once)");
}
