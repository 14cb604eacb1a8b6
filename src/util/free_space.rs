//! Room on the disk for an output, checked before the work that makes it: a fusion of a
//! capture runs for minutes, and a full disk found at its write (the write fails cleanly,
//! leaving no partial file) wastes them all.

use std::path::Path;

use anyhow::{bail, Result};

use crate::gpu::error::human_bytes;

/// Bytes an unprivileged writer may still use on the file system holding `path` (or its
/// nearest existing folder above); None where that cannot be told (not Linux with glibc,
/// or `statvfs` failed).
pub fn free_bytes(path: &Path) -> Option<u64> {
    let existing = path.ancestors().find(|p| p.exists())?;
    let existing = match existing.as_os_str().is_empty() {
        true => Path::new("."),
        false => existing,
    };
    statvfs_available(existing)
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn statvfs_available(path: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c_path = std::ffi::CString::new(path.as_os_str().as_bytes()).ok()?;
    let mut stat: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: a NUL-terminated path and a struct of the size statvfs writes.
    let rc = unsafe { libc::statvfs(c_path.as_ptr(), &mut stat) };
    (rc == 0).then(|| stat.f_bavail as u64 * stat.f_frsize as u64)
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn statvfs_available(_: &Path) -> Option<u64> {
    None
}

/// Refuses `target` (of `option`) where its file system has less than `at_least` bytes
/// free ([`short_of_room`]); nothing where the free space cannot be told.
pub fn check_free_space(option: &str, target: &Path, at_least: u64, what: &str) -> Result<()> {
    match short_of_room(option, target, at_least, &format!("{what} needs at least")) {
        Some(short) => bail!("{short}: free some space or write elsewhere"),
        None => Ok(()),
    }
}

/// What to say where `target`'s file system has less than `about` bytes free: `needs`
/// names what and how surely ("the fused scene needs at least"); None where it has room,
/// or where that cannot be told.
pub fn short_of_room(option: &str, target: &Path, about: u64, needs: &str) -> Option<String> {
    let free = free_bytes(target).filter(|&free| free < about)?;
    let (mut needed, mut has) = (human_bytes(&about), human_bytes(&free));
    if needed == has {
        (needed, has) = (format!("{about} bytes"), format!("{free} bytes"));
    }
    Some(format!(
        "{option} {}: {needs} {needed}, and its file system has {has} free",
        target.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    fn free_space_is_told_from_the_nearest_existing_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let free = free_bytes(tmp.path()).expect("statvfs of a temp folder");
        let below = tmp.path().join("not/yet/made/out.ply");
        assert_eq!(
            free_bytes(&below).map(|f| f / (1 << 20)),
            Some(free / (1 << 20))
        );
        assert!(check_free_space("--out", &below, 1, "the output").is_ok());
        assert_eq!(short_of_room("--out", &below, 1, "the output needs"), None);
        let e = check_free_space("--out", &below, u64::MAX, "the fused scene").unwrap_err();
        let e = e.to_string();
        assert!(
            e.contains("the fused scene needs at least") && e.contains("free some space"),
            "{e}"
        );
    }
}
