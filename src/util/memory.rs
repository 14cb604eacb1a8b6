//! The process's own memory use, for reports, and how its allocator holds it.

/// Peak resident memory of this process in bytes (Linux `VmHWM`); None where the kernel
/// does not report it.
pub fn peak_host_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Sets glibc's allocator up for this process's threads, as the CLI does from its start
/// (before any thread): one arena for every thread, and fixed thresholds for when a block
/// gets a mapping of its own and when freed memory goes back to the system. Elsewhere than
/// glibc, nothing. Each setting given in the environment (`MALLOC_ARENA_MAX`,
/// `MALLOC_MMAP_THRESHOLD_`, `MALLOC_TRIM_THRESHOLD_`) is left to glibc.
///
/// One arena: by default each thread that allocates gets an arena of its own (up to eight
/// per core), which keeps what was freed in it: on a 16-core machine the segment consensus
/// of a million-Gaussian room peaked at 2.1 GB with them and 1.36 GB with one, no slower
/// (one run, docs/gpu.md). The parallel passes make few allocations each (a block's list,
/// not an entry at a time; the observations' are filled in place), so their threads rarely
/// wait for the one arena's lock; lavapipe's own threads allocate more (its rendering there
/// was 3-9% slower). A parallel pass that allocates per item does wait: the segment
/// clustering tried in rounds of stars (docs/robustness-log.md) took 1.9-2.2 s for its joins on
/// two cores under one arena, 1.25 s with eight.
///
/// Fixed thresholds: glibc's own move with use (a block freed from a mapping of its own
/// raises the mapping threshold to its size, and the trim threshold to twice that), which
/// one thread allocating and freeing alike settles into. The label readers are several
/// threads each decoding a map of megabytes every few milliseconds: one freeing its map at
/// the top of the heap while another's lay below left more free than the threshold, so the
/// heap was trimmed and grown again map after map, each time faulting its pages in anew
/// (two readers on two cores: 0.67-0.78 s and 360,000-380,000 faults for a capture's 190
/// 1080p maps; 0.36-0.38 s and 3,500-4,600 faults with these thresholds). A higher trim threshold holds
/// more at the peak: a consensus run of that capture peaked at 1.23 GB with 128 MiB, at
/// 1.0-1.22 GB with 64 MiB and 1.03-1.13 GB with glibc's own, runs moving by 0.1 GB
/// (docs/robustness-log.md, "The label readers' pages").
pub fn configure_malloc() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    for (variable, parameter, value) in [
        ("MALLOC_ARENA_MAX", libc::M_ARENA_MAX, 1),
        (
            "MALLOC_MMAP_THRESHOLD_",
            libc::M_MMAP_THRESHOLD,
            MMAP_THRESHOLD,
        ),
        (
            "MALLOC_TRIM_THRESHOLD_",
            libc::M_TRIM_THRESHOLD,
            TRIM_THRESHOLD,
        ),
    ] {
        if std::env::var_os(variable).is_none() {
            // SAFETY: mallopt only sets an allocator parameter (under the allocator's own
            // lock); the CLI calls this before any thread starts, so every allocation
            // follows it.
            unsafe {
                libc::mallopt(parameter, value);
            }
        }
    }
}

/// Blocks from this size get a mapping of their own ([`configure_malloc`]): above a
/// label map's class ids at 2560x1440 (4 bytes a pixel), under glibc's own ceiling (32 MiB).
const MMAP_THRESHOLD: i32 = 16 << 20;

/// Free memory at the top of the heap past this goes back to the system
/// ([`configure_malloc`]): room for several label readers' maps in flight (a 1080p map's
/// samples, ids and class ids are 14 MB).
const TRIM_THRESHOLD: i32 = 64 << 20;

#[cfg(test)]
mod tests {
    #[test]
    fn peak_grows_with_a_touched_allocation() {
        let before = super::peak_host_bytes().unwrap();
        // Twice what the peak must grow by: the peak so far may stand above the memory in
        // use now (another test's freed buffers), by less than the test process ever holds.
        let block = vec![1u8; 128 << 20];
        let after = super::peak_host_bytes().unwrap();
        assert!(block.iter().all(|&b| b == 1));
        assert!(after >= before + (64 << 20), "{before} -> {after}");
    }
}
