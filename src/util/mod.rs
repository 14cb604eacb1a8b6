//! Small shared utilities.

pub mod atomic_write;
pub mod free_space;
pub mod interrupt;
pub mod memory;
pub mod npy;
pub mod parallel;
mod pool;
pub mod quad_heap;
pub mod rng;
pub mod scaling;

pub use atomic_write::{
    check_output_file, check_output_folder, folder_of, resolve_output_file, stage_atomic,
    write_atomic, write_bytes_atomic, OutputBatch, StagedFile,
};
pub use parallel::{
    collect_parts, cores, map_in_blocks, merge_sorted_into, merge_sorted_runs, parallel_map,
    parallel_map_on, partition_point_near, prefetch_ordered, runs_of_weight, split_parts,
    take_part, BusyTime,
};
pub use rng::Rng;

/// Host seconds since the last lap (or the start): the split of a step's wall time that
/// a profile reports.
pub struct Laps(std::time::Instant);

impl Laps {
    pub fn start() -> Laps {
        Laps(std::time::Instant::now())
    }

    /// Seconds since the last call (or the start); the next lap starts now.
    pub fn lap(&mut self) -> f64 {
        std::mem::replace(&mut self.0, std::time::Instant::now())
            .elapsed()
            .as_secs_f64()
    }
}

/// `values`' items of `stride` values at `indices`, in that order (a subset of a scene's
/// per-Gaussian arrays, or all of them renumbered). No values (an attribute of no
/// channels) gather to none.
pub fn gather<T: Clone>(values: &[T], indices: &[u32], stride: usize) -> Vec<T> {
    if values.is_empty() {
        return Vec::new();
    }
    let item = |i: &u32| &values[*i as usize * stride..(*i as usize + 1) * stride];
    indices.iter().flat_map(item).cloned().collect()
}

/// Asks the CPU to bring `value`'s cache line in ahead of its use (a hint: no effect on
/// results, none where the target has no prefetch instruction). For loops whose next
/// reads are known ahead and would each miss the cache.
#[inline(always)]
pub fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads nothing the program sees and cannot fault; SSE, which it
    // needs, is part of every x86-64 CPU.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(value as *const T as *const i8);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}
