//! Shared by the criterion benches: the device, and GPU time from timestamps as the
//! measurement (wall time would add submission overhead that is not the kernel's).
#![allow(dead_code)]

use std::time::Duration;

use semsplat::gpu::{Gpu, Recorder};

pub const SIZES: [u64; 3] = [1 << 20, 1 << 22, 1 << 24];

pub fn gpu() -> Gpu {
    Gpu::new().unwrap_or_else(|e| panic!("benchmarks need a Vulkan device: {e}"))
}

/// Sum of the GPU time of `iters` runs of `record` (each after an untimed `prepare`), as
/// criterion's iter_custom wants it.
pub fn gpu_time(
    gpu: &Gpu,
    iters: u64,
    mut prepare: impl FnMut(&mut Recorder),
    mut record: impl FnMut(&mut Recorder),
) -> Duration {
    let (samples, _) = semsplat::bench::time_gpu(
        gpu,
        iters as usize,
        |rec| {
            prepare(rec);
            Ok(())
        },
        |rec| {
            record(rec);
            Ok(())
        },
    )
    .unwrap();
    Duration::from_nanos(samples.iter().sum::<f64>() as u64)
}
