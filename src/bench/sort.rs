//! Radix sort throughput: GPU (timestamps) vs Rust's stable `sort_by_key`.

use anyhow::{ensure, Result};
use serde::Serialize;

use super::{median_gpu_time, time_cpu};
use crate::gpu::timings::KernelTotal;
use crate::gpu::{Gpu, GpuCount, RadixSort};
use crate::util::Rng;

#[derive(Debug, Serialize)]
pub struct SortBench {
    pub n: u64,
    pub bits: u32,
    pub iters: usize,
    pub gpu_ms: f64,
    pub cpu_ms: f64,
    pub gpu_pairs_per_s: f64,
    pub cpu_pairs_per_s: f64,
    /// GPU throughput over CPU throughput.
    pub ratio: f64,
    pub device: String,
    /// The GPU result equalled the CPU's, pair for pair.
    pub verified: bool,
    /// Time per kernel in the last timed run.
    pub kernels: Vec<KernelTotal>,
}

pub fn bench_sort(gpu: &Gpu, n: u64, bits: u32, iters: usize, seed: u64) -> Result<SortBench> {
    ensure!(bits <= 32, "--bits must be at most 32");
    ensure!(
        gpu.caps().timestamps,
        "the device has no timestamp queries; GPU time cannot be measured"
    );
    // The device's limit is checked before the host arrays are made (gigabytes at the limit).
    let sorter = RadixSort::new(gpu, n)?;
    let mut rng = Rng::new(seed);
    let keys: Vec<u32> = (0..n).map(|_| rng.next_u32()).collect();
    let values: Vec<u32> = (0..n as u32).collect();

    let src_keys = gpu.buffer_from("bench-src-keys", &keys)?;
    let src_values = gpu.buffer_from("bench-src-values", &values)?;
    let work_keys = gpu.buffer("bench-keys", n * 4)?;
    let work_values = gpu.buffer("bench-values", n * 4)?;
    let count = gpu.buffer_from("bench-count", &[n as u32])?;

    let (gpu_ns, kernels) = median_gpu_time(
        gpu,
        iters,
        |rec| {
            rec.copy(&src_keys, 0, &work_keys, 0, n * 4);
            rec.copy(&src_values, 0, &work_values, 0, n * 4);
            Ok(())
        },
        |rec| sorter.record(rec, &work_keys, &work_values, GpuCount::at(&count, 0), bits),
    )?;

    let mask = if bits >= 32 {
        u32::MAX
    } else {
        (1u32 << bits) - 1
    };
    let pairs: Vec<(u32, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    let (cpu_ns, sorted) = time_cpu(
        iters,
        || pairs.clone(),
        |mut p| {
            p.sort_by_key(|&(k, _)| k & mask);
            p
        },
    );

    let gk: Vec<u32> = gpu.download(&work_keys, 0, n as usize)?;
    let gv: Vec<u32> = gpu.download(&work_values, 0, n as usize)?;
    let verified = sorted
        .iter()
        .zip(gk.iter().zip(&gv))
        .all(|(&(k, v), (&a, &b))| k == a && v == b);
    ensure!(
        verified,
        "GPU sort result differs from the CPU's stable sort (n={n}, bits={bits})"
    );

    let gpu_pairs_per_s = n as f64 / (gpu_ns * 1e-9);
    let cpu_pairs_per_s = n as f64 / (cpu_ns * 1e-9);
    Ok(SortBench {
        n,
        bits,
        iters,
        gpu_ms: gpu_ns * 1e-6,
        cpu_ms: cpu_ns * 1e-6,
        gpu_pairs_per_s,
        cpu_pairs_per_s,
        ratio: gpu_pairs_per_s / cpu_pairs_per_s,
        device: gpu.caps().name.clone(),
        verified,
        kernels,
    })
}
