//! Shared by the criterion benches: the device, and GPU time from timestamps as the
//! measurement (wall time would add submission overhead that is not the kernel's).
#![allow(dead_code)]

use std::time::Duration;

use semsplat::gpu::{Gpu, Recorder};

pub const SIZES: [u64; 3] = [1 << 20, 1 << 22, 1 << 24];

pub fn gpu() -> Gpu {
    Gpu::new().unwrap_or_else(|e| panic!("benchmarks need a Vulkan device: {e}"))
}

/// Runs `prepare` (untimed) then `record` `iters` times, each in its own submission, and
/// sums the GPU time between the marks around `record`.
pub fn gpu_time(
    gpu: &Gpu,
    iters: u64,
    mut prepare: impl FnMut(&mut Recorder),
    mut record: impl FnMut(&mut Recorder),
) -> Duration {
    let mut total_ns = 0.0;
    for _ in 0..iters {
        let mut rec = Recorder::new(gpu).unwrap();
        prepare(&mut rec);
        rec.barrier();
        let start = rec.mark();
        record(&mut rec);
        let end = rec.mark();
        let t = rec.submit_and_wait().unwrap();
        total_ns += t.between(start, end).expect("device has timestamps");
    }
    Duration::from_nanos(total_ns as u64)
}
