//! Every output file is written atomically: to a temp file beside the target, then renamed,
//! so a failure or Ctrl-C never leaves a half-written output.
//!
//! The target is resolved first: an existing symbolic link is written through (the temp file
//! and the rename happen in its target's folder, so the link stays a link), and anything that
//! is not a regular file (a folder, a device such as /dev/stdout, a FIFO, a socket) is
//! refused rather than replaced. Temp files are named `.NAME.semsplat-tmpPID-NONCE`, created
//! only where no file of that name exists, and locked by their writer until renamed or
//! removed; those left by a killed run (PID no longer alive, unlocked, untouched for a
//! minute) are removed at the next write into that folder. The lock and the nonce matter
//! where runs in several PID namespaces (containers) write into one shared folder: there a
//! live run's PID may name no process here, or the same number as this run's.

use std::collections::HashSet;
use std::fs;
use std::io::{BufWriter, ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{bail, Context, Result};

use super::interrupt;

/// The temp-name marker between the target's name and the writer's PID.
const TEMP_MARKER: &str = ".semsplat-tmp";
/// Appended to a scratch file's name before its temp name is formed.
const SCRATCH_MARKER: &str = ".semsplat-scratch";
/// The longest file name Linux's file systems hold, in bytes.
const MAX_FILE_NAME_BYTES: usize = 255;
/// Symbolic links followed before giving up (the kernel's own limit is 40).
const MAX_LINKS: usize = 40;

/// Temp files this young are never removed as stale: their writer may be between creating
/// and locking them.
const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(60);

/// `target`'s temp name with `nonce` (8 hex digits, so every temp name of a target is as
/// long as [`check_output_file`] checks).
fn temp_path(target: &Path, nonce: u32) -> PathBuf {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let pid = std::process::id();
    target.with_file_name(format!(".{name}{TEMP_MARKER}{pid}-{nonce:08x}"))
}

/// A nonce for a temp name: the clock's nanoseconds mixed with a count of this process's
/// temp files (two names of one process never share one; processes of two namespaces
/// with one PID draw apart by the clock, and a name taken is drawn again).
fn temp_nonce() -> u32 {
    use std::sync::atomic::{AtomicU32, Ordering};
    static MADE: AtomicU32 = AtomicU32::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos() ^ d.as_secs() as u32);
    let made = MADE.fetch_add(1, Ordering::Relaxed);
    nanos.wrapping_mul(0x9e37_79b9) ^ made.wrapping_mul(0x85eb_ca6b).rotate_left(16)
}

/// The file a write to `target` lands in: `target` itself, or the end of its chain of
/// symbolic links (which may not exist yet). Errors when that is a folder or a special file.
pub fn resolve_output_file(target: &Path) -> Result<PathBuf> {
    // What the kernel sees through every link first: /dev/stdout leads through a magic link
    // (/proc/self/fd/1 -> "pipe:[...]") that read_link cannot follow.
    match fs::metadata(target) {
        Ok(meta) if meta.is_dir() => {
            bail!("{} is a folder where this file is to be written: name another file, or move the folder away", target.display())
        }
        Ok(meta) if !meta.is_file() => bail!(
            "{} is not a regular file (a device, FIFO or socket); refusing to replace it: name \
             a regular file",
            target.display()
        ),
        _ => {}
    }
    let mut path = target.to_path_buf();
    for _ in 0..MAX_LINKS {
        let meta = match fs::symlink_metadata(&path) {
            // Missing (a new file or a dangling link's target), or under a non-folder, which
            // check_output_file reports by name.
            Err(e) if matches!(e.kind(), ErrorKind::NotFound | ErrorKind::NotADirectory) => {
                return Ok(path)
            }
            Err(e) => return Err(e).with_context(|| format!("checking {}", path.display())),
            Ok(meta) => meta,
        };
        let kind = meta.file_type();
        if kind.is_symlink() {
            let link = fs::read_link(&path)
                .with_context(|| format!("reading the link {}", path.display()))?;
            // A relative link is relative to the folder holding it; join keeps absolute ones.
            path = path.parent().map_or(link.clone(), |dir| dir.join(&link));
        } else if kind.is_file() {
            return Ok(path);
        } else if kind.is_dir() {
            bail!(
                "{} is a folder where this file is to be written: name another file, or move the folder away",
                describe(target, &path)
            );
        } else {
            bail!(
                "{} is not a regular file (a device, FIFO or socket); refusing to replace it: \
                 name a regular file",
                describe(target, &path)
            );
        }
    }
    bail!(
        "{} is a chain of more than {MAX_LINKS} symbolic links",
        target.display()
    )
}

/// `target`, and where its links lead when that is another path.
fn describe(target: &Path, resolved: &Path) -> String {
    if target == resolved {
        target.display().to_string()
    } else {
        format!("{} (a link to {})", target.display(), resolved.display())
    }
}

/// A fully written temp file waiting to be renamed onto its target ([`StagedFile::commit`]);
/// dropped uncommitted, it is removed. Staging several files and committing them in order
/// keeps outputs that belong together (a PLY and its class table) from being half replaced
/// when a write fails.
#[must_use = "a staged file is removed unless committed"]
pub struct StagedFile {
    tmp: PathBuf,
    target: PathBuf,
    committed: bool,
    /// The temp file, open and locked ([`fs::File::lock`]) until it is renamed or removed:
    /// how a run elsewhere tells it is in use ([`remove_stale_temps`]). Closed once the
    /// file waits in an [`OutputBatch`] (a batch of a thousand rendered views would hold a
    /// thousand descriptors); its age then keeps it for a minute.
    locked: Option<fs::File>,
}

thread_local! {
    /// The staged files of the thread's open [`OutputBatch`], in the order committed.
    static BATCH: std::cell::RefCell<Option<Vec<StagedFile>>> =
        const { std::cell::RefCell::new(None) };
    /// The folders the open batch's files created (the first that did not exist of each
    /// file's parents): a batch dropped uncommitted removes those its files leave empty.
    static BATCH_FOLDERS: std::cell::RefCell<Vec<PathBuf>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// One run's outputs, landed together: while a batch is open, every output committed
/// ([`StagedFile::commit`], [`write_atomic`]) waits, written but not renamed; the batch's
/// [`OutputBatch::commit`] renames them all in the order they were committed, and a batch
/// dropped uncommitted (an error, Ctrl-C) removes them. Without it a fusion that failed
/// writing its PLY left the membership matrix it had written just before, beside the
/// previous run's PLY. One batch a thread, holding that thread's outputs only.
#[must_use = "a batch's outputs are removed unless it is committed"]
pub struct OutputBatch(());

impl OutputBatch {
    pub fn open() -> OutputBatch {
        BATCH.with_borrow_mut(|batch| {
            assert!(batch.is_none(), "one output batch a thread");
            *batch = Some(Vec::new());
        });
        OutputBatch(())
    }

    /// Renames every output the batch holds onto its target, in order, holding the temp
    /// files' registry throughout: a signal arriving mid-way waits for the last rename (a
    /// few milliseconds for a thousand files), so the batch lands whole, or, interrupted
    /// before, not at all. A rename that fails leaves those before it in place.
    pub fn commit(self) -> Result<()> {
        let mut staged = take_batch();
        std::mem::forget(self);
        let mut temps = interrupt::temp_files();
        let outcome = match (interrupt::is_interrupted(), staged.first()) {
            (true, Some(first)) => Err(first.interrupted()),
            _ => (staged.iter_mut()).try_for_each(|file| file.rename_holding(&mut temps)),
        };
        // Before `staged` drops: each file left removes its temp file under the lock.
        drop(temps);
        outcome
    }
}

impl Drop for OutputBatch {
    fn drop(&mut self) {
        let folders = BATCH_FOLDERS.take();
        drop(take_batch()); // each staged file removes its temp file
        for folder in folders.iter().rev() {
            remove_empty_folders(folder);
        }
    }
}

fn take_batch() -> Vec<StagedFile> {
    BATCH_FOLDERS.with_borrow_mut(Vec::clear);
    BATCH.with_borrow_mut(Option::take).unwrap_or_default()
}

/// Creates `parent` and the folders above it that are missing; while a batch is open, the
/// first of them is noted for the batch to remove if it ends uncommitted.
fn create_parent(parent: &Path) -> std::io::Result<()> {
    let missing = (parent.ancestors())
        .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
        .last()
        .map(Path::to_path_buf);
    fs::create_dir_all(parent)?;
    if let Some(first) = missing.filter(|_| BATCH.with_borrow(Option::is_some)) {
        BATCH_FOLDERS.with_borrow_mut(|folders| folders.push(first));
    }
    Ok(())
}

/// Removes `folder` and the folders in it, where they hold no file.
fn remove_empty_folders(folder: &Path) {
    if let Ok(entries) = fs::read_dir(folder) {
        for entry in entries.flatten() {
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                remove_empty_folders(&entry.path());
            }
        }
    }
    let _ = fs::remove_dir(folder); // only an empty one goes
}

impl StagedFile {
    /// Renames the temp file onto the target, unless a signal arrived (then it is removed);
    /// while an [`OutputBatch`] is open, when the batch commits.
    pub fn commit(mut self) -> Result<()> {
        if BATCH.with_borrow(Option::is_none) {
            return self.rename_into_place();
        }
        self.locked = None;
        BATCH.with_borrow_mut(|batch| batch.as_mut().expect("a batch is open").push(self));
        Ok(())
    }

    fn rename_into_place(mut self) -> Result<()> {
        let mut temps = interrupt::temp_files();
        if interrupt::is_interrupted() {
            return Err(self.interrupted());
        }
        self.rename_holding(&mut temps)
    }

    /// The rename, with the temp files' registry (`temps`) locked by the caller.
    fn rename_holding(&mut self, temps: &mut Vec<PathBuf>) -> Result<()> {
        fs::rename(&self.tmp, &self.target)
            .with_context(|| format!("renaming into {}", self.target.display()))?;
        temps.retain(|t| t != &self.tmp);
        self.committed = true;
        Ok(())
    }

    fn interrupted(&self) -> anyhow::Error {
        anyhow::Error::from(interrupt::Interrupted)
            .context(format!("writing {}", self.target.display()))
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if !self.committed {
            let mut temps = interrupt::temp_files();
            let _ = fs::remove_file(&self.tmp);
            temps.retain(|t| t != &self.tmp);
        }
    }
}

/// Writes `target`'s content to a temp file beside it (parent folders are created) through a
/// buffered writer handed to `fill`; the target is untouched until [`StagedFile::commit`].
pub fn stage_atomic<F>(target: &Path, fill: F) -> Result<StagedFile>
where
    F: FnOnce(&mut BufWriter<fs::File>) -> Result<()>,
{
    let staged = (|| -> Result<StagedFile> {
        let target = resolve_output_file(target)?;
        if let Some(parent) = target.parent().filter(|p| !p.as_os_str().is_empty()) {
            create_parent(parent)
                .with_context(|| format!("creating directory {}", parent.display()))?;
        }
        remove_stale_temps(&target);
        let (file, staged) = create_temp(target)?;
        let mut w = BufWriter::new(file);
        fill(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all().ok();
        Ok(staged)
    })();
    staged.with_context(|| format!("writing {}", target.display()))
}

/// Creates the temp file of `target` under a name no file has, locked, and registered so a
/// signal handler can remove it.
fn create_temp(target: PathBuf) -> Result<(fs::File, StagedFile)> {
    let mut temps = interrupt::temp_files();
    interrupt::check()?;
    let (tmp, file) = create_new_temp(&target)?;
    temps.push(tmp.clone());
    // Locked before anything is written; a file system without locks writes unlocked.
    let _ = file.lock();
    let staged = StagedFile {
        tmp,
        target,
        committed: false,
        locked: Some(file.try_clone().context("opening the temp file twice")?),
    };
    Ok((file, staged))
}

/// A new temp file of `target`, open for reading (a scratch file is read back by its
/// writer) and writing, its name drawn again while one is taken.
fn create_new_temp(target: &Path) -> Result<(PathBuf, fs::File)> {
    const TRIES: usize = 16;
    let mut tried = 0;
    loop {
        tried += 1;
        let tmp = temp_path(target, temp_nonce());
        let created = fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&tmp);
        match created {
            Err(e) if e.kind() == ErrorKind::AlreadyExists && tried < TRIES => continue,
            created => {
                let file = created.with_context(|| format!("creating {}", tmp.display()))?;
                return Ok((tmp, file));
            }
        }
    }
}

/// A scratch file beside `target`, named and registered like a temp file (so a signal or a
/// later run removes it), open for reading and writing. It is removed when the returned
/// [`StagedFile`] drops; nothing is ever renamed onto `target`.
pub fn stage_scratch(target: &Path) -> Result<(fs::File, StagedFile)> {
    let target = resolve_output_file(target)?;
    // Apart from the temp names of outputs: an output named like `target` (`--out b.ply`
    // spilling beside `--save-membership b.evidence`) would truncate the scratch as it
    // created its own temp file.
    let mut name = target.file_name().unwrap_or_default().to_os_string();
    name.push(SCRATCH_MARKER);
    let target = target.with_file_name(name);
    if let Some(parent) = target.parent().filter(|p| !p.as_os_str().is_empty()) {
        fs::create_dir_all(parent)
            .with_context(|| format!("creating directory {}", parent.display()))?;
    }
    remove_stale_temps(&target);
    create_temp(target)
}

/// Writes `target` through a buffered writer handed to `fill`; the file appears only if
/// `fill` succeeds (and no signal arrived). Parent directories are created.
pub fn write_atomic<F>(target: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<fs::File>) -> Result<()>,
{
    stage_atomic(target, fill)?.commit()
}

/// Atomic write of a byte buffer.
pub fn write_bytes_atomic(target: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(target, |w| Ok(w.write_all(bytes)?))
}

/// Removes, once per folder and process, the temp files that runs no longer alive left in
/// `target`'s folder (killed with SIGKILL or by a power cut).
fn remove_stale_temps(target: &Path) {
    static CLEANED: Mutex<Option<HashSet<PathBuf>>> = Mutex::new(None);
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut cleaned = CLEANED.lock().unwrap_or_else(|p| p.into_inner());
    if !cleaned.get_or_insert_with(HashSet::new).insert(dir.clone()) {
        return;
    }
    let Ok(entries) = fs::read_dir(&dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(stale_temp_pid) else {
            continue;
        };
        let is_file = entry.file_type().is_ok_and(|t| t.is_file());
        if is_file && pid != std::process::id() && !process_alive(pid) {
            remove_if_unused(&entry.path());
        }
    }
}

/// Removes a temp file no writer holds: not locked (a writer in another PID namespace has
/// a PID that names no process here) and untouched for [`STALE_AFTER`].
fn remove_if_unused(path: &Path) {
    let Ok(file) = fs::File::open(path) else {
        return;
    };
    let idle = (file.metadata().and_then(|m| m.modified()).ok())
        .and_then(|modified| modified.elapsed().ok())
        .is_some_and(|age| age >= STALE_AFTER);
    if idle && file.try_lock().is_ok() {
        let _ = fs::remove_file(path);
    }
}

/// The writer's PID if `name` is one of our temp names (`.NAME.semsplat-tmpPID-NONCE`, or
/// `.NAME.semsplat-tmpPID` as earlier versions named them).
fn stale_temp_pid(name: &str) -> Option<u32> {
    let (head, tail) = name.rsplit_once(TEMP_MARKER)?;
    if !head.starts_with('.') || head.len() < 2 {
        return None;
    }
    let pid = match tail.split_once('-') {
        Some((pid, nonce)) if nonce.len() == 8 && nonce.bytes().all(|b| b.is_ascii_hexdigit()) => {
            pid
        }
        Some(_) => return None,
        None => tail,
    };
    if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    pid.parse().ok()
}

/// Whether process `pid` runs. Without /proc we cannot tell, and keep the file.
fn process_alive(pid: u32) -> bool {
    let proc_root = Path::new("/proc");
    !proc_root.join("self").exists() || proc_root.join(pid.to_string()).exists()
}

/// Checks, before any long work, that `target` can be written: not a folder or special file
/// (after following links) and inside a folder that exists or can be created and accepts
/// new files. `option` names the flag in the error.
pub fn check_output_file(option: &str, target: &Path) -> Result<()> {
    if target.as_os_str().as_encoded_bytes().last() == Some(&b'/') {
        bail!(
            "{option} {} ends in '/', which names a folder: give the file's name after it",
            target.display()
        );
    }
    let resolved = resolve_output_file(target).with_context(|| option.to_string())?;
    // Found here rather than at the write, after the run's work: the file is written under
    // a longer temp name first.
    let temp_name_len = temp_path(&resolved, 0).file_name().map_or(0, |n| n.len());
    if temp_name_len > MAX_FILE_NAME_BYTES {
        bail!(
            "{option} {}: the file's name is too long to be written safely (its temp name would \
             take {temp_name_len} bytes, over the {MAX_FILE_NAME_BYTES} a name may hold); \
             shorten it",
            target.display()
        );
    }
    // Folders are created for a path the user named, not for where a dangling link points
    // (/nonexistent/x.ply would create /nonexistent).
    let landing = folder_of(&resolved);
    if resolved != target && !landing.is_dir() {
        bail!(
            "{option} {} is a link to {}, whose folder {} does not exist: create that folder, \
             or name another file",
            target.display(),
            resolved.display(),
            landing.display()
        );
    }
    check_writable_folder(landing).with_context(|| format!("{option} {}", target.display()))
}

/// The folder a file path lies in (`.` for a bare name).
pub fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Like [`check_output_file`] for an output folder (`render --out`, `--render-views`).
pub fn check_output_folder(option: &str, dir: &Path) -> Result<()> {
    check_writable_folder(dir).with_context(|| format!("{option} {}", dir.display()))
}

/// `dir` (or, where it does not exist yet, its nearest existing ancestor, since writers
/// create folders) is a folder that accepts a new file: probed by creating and removing one.
fn check_writable_folder(dir: &Path) -> Result<()> {
    let mut existing = dir;
    loop {
        match fs::metadata(existing) {
            Ok(meta) if meta.is_dir() => break,
            Ok(_) => bail!("{} exists and is not a folder", existing.display()),
            // A dangling link: creating the folder would fail ("File exists") after the work.
            Err(e) if e.kind() == ErrorKind::NotFound => {
                if let Ok(target) = fs::read_link(existing) {
                    bail!(
                        "{} is a link to {}, which does not exist: create that folder, or name \
                         another",
                        existing.display(),
                        target.display()
                    );
                }
            }
            Err(e) => return Err(e).with_context(|| format!("checking {}", existing.display())),
        }
        existing = match existing.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ if existing != Path::new(".") => Path::new("."),
            _ => bail!("the current folder no longer exists"),
        };
    }
    let probe = existing.join(format!(".semsplat-probe{}", std::process::id()));
    fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
        .with_context(|| format!("cannot create files in {}", existing.display()))?;
    let _ = fs::remove_file(&probe);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{stale_temp_pid, write_bytes_atomic, OutputBatch};

    /// A batch's outputs land together when it commits, in order (a file written twice:
    /// the later bytes), and not at all when it is dropped (the files there before stay,
    /// no temp file is left); another thread's writes meanwhile land at once.
    #[test]
    fn a_batch_lands_its_outputs_together_or_not_at_all() {
        let tmp = tempfile::tempdir().unwrap();
        let (a, b) = (tmp.path().join("a.ply"), tmp.path().join("a.npy"));
        std::fs::write(&a, "before").unwrap();
        let listing = || {
            let mut names: Vec<String> = (std::fs::read_dir(tmp.path()).unwrap())
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            names.sort();
            names
        };
        let dropped = OutputBatch::open();
        write_bytes_atomic(&b, b"membership").unwrap();
        write_bytes_atomic(&a, b"after").unwrap();
        assert_eq!(
            std::fs::read(&a).unwrap(),
            b"before",
            "landed before the batch"
        );
        let other = tmp.path().join("other.json");
        std::thread::scope(|s| {
            s.spawn(|| write_bytes_atomic(&other, b"{}").unwrap());
        });
        assert!(
            other.exists(),
            "another thread's write waited for this thread's batch"
        );
        drop(dropped);
        assert_eq!(listing(), ["a.ply", "other.json"]);
        assert_eq!(std::fs::read(&a).unwrap(), b"before");
        let batch = OutputBatch::open();
        write_bytes_atomic(&b, b"membership").unwrap();
        write_bytes_atomic(&a, b"first").unwrap();
        write_bytes_atomic(&a, b"second").unwrap();
        batch.commit().unwrap();
        assert_eq!(listing(), ["a.npy", "a.ply", "other.json"]);
        assert_eq!(std::fs::read(&a).unwrap(), b"second");
        write_bytes_atomic(&a, b"alone").unwrap();
        assert_eq!(
            std::fs::read(&a).unwrap(),
            b"alone",
            "no batch open: at once"
        );
    }

    /// A rename that fails mid-commit (its target became a folder meanwhile) errors naming
    /// it, keeps the outputs renamed before it, and removes the temp files after it (under
    /// the registry's lock the commit held: no deadlock).
    #[test]
    fn a_failed_rename_mid_commit_removes_the_rest() {
        let tmp = tempfile::tempdir().unwrap();
        let [first, blocked, last] = ["a.npy", "b.ply", "c.json"].map(|n| tmp.path().join(n));
        let batch = OutputBatch::open();
        for path in [&first, &blocked, &last] {
            write_bytes_atomic(path, b"new").unwrap();
        }
        std::fs::create_dir(&blocked).unwrap();
        std::fs::write(blocked.join("inside"), "x").unwrap();
        let err = format!("{:#}", batch.commit().unwrap_err());
        assert!(err.contains("b.ply"), "{err}");
        assert_eq!(std::fs::read(&first).unwrap(), b"new");
        assert!(!last.exists());
        let mut names: Vec<String> = (std::fs::read_dir(tmp.path()).unwrap())
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["a.npy", "b.ply"], "no temp file left");
        let registered = crate::util::interrupt::temp_files();
        assert!(!registered.iter().any(|t| t.starts_with(tmp.path())));
    }

    #[test]
    fn only_our_temp_names_are_stale_candidates() {
        assert_eq!(stale_temp_pid(".out.ply.semsplat-tmp123"), Some(123));
        assert_eq!(
            stale_temp_pid(".out.ply.semsplat-tmp123-0a1b2c3d"),
            Some(123)
        );
        assert_eq!(stale_temp_pid(".out.ply.semsplat-tmp123-0a1b2c3"), None);
        assert_eq!(stale_temp_pid(".out.ply.semsplat-tmp123-0a1b2c3g"), None);
        assert_eq!(stale_temp_pid(".out.ply.semsplat-tmp-0a1b2c3d"), None);
        assert_eq!(stale_temp_pid("out.ply.semsplat-tmp123"), None);
        assert_eq!(stale_temp_pid(".out.ply.semsplat-tmp"), None);
        assert_eq!(stale_temp_pid(".out.ply.semsplat-tmp12x"), None);
        assert_eq!(stale_temp_pid(".out.ply.tmp123"), None);
    }
}
