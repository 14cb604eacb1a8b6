//! The process's own memory use, for reports, and how its allocator holds it.

/// Peak resident memory of this process in bytes (Linux `VmHWM`); None where the kernel
/// does not report it.
pub fn peak_host_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Has glibc's allocator serve every thread from one arena, as the CLI does from its start
/// (before any thread). By default each thread that allocates gets an arena of its own (up
/// to eight per core), which keeps what was freed in it: on a 16-core machine the segment
/// consensus of a million-Gaussian room peaked at 2.1 GB with them and 1.36 GB with one,
/// no slower (one run, docs/gpu.md). The parallel passes make few allocations each (a
/// block's list, not an entry at a time; the observations' are filled in place), so their
/// threads rarely wait for the one arena's lock; lavapipe's own threads allocate more (its
/// rendering there was 3-9% slower). A parallel pass that allocates per item does wait: the
/// segment clustering tried in rounds of stars (docs/robustness.md) took 1.9-2.2 s for its
/// joins on two cores under one arena, 1.25 s with eight.
/// A `MALLOC_ARENA_MAX` in the environment is left to glibc. Elsewhere than glibc, nothing.
pub fn use_one_malloc_arena() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    if std::env::var_os("MALLOC_ARENA_MAX").is_none() {
        // SAFETY: mallopt only sets an allocator parameter; called before any thread starts.
        unsafe {
            libc::mallopt(libc::M_ARENA_MAX, 1);
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn peak_grows_with_a_touched_allocation() {
        let before = super::peak_host_bytes().unwrap();
        let block = vec![1u8; 64 << 20];
        let after = super::peak_host_bytes().unwrap();
        assert!(block.iter().all(|&b| b == 1));
        assert!(after >= before + (60 << 20), "{before} -> {after}");
    }
}
