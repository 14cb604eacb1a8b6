//! Prefix scan throughput: GPU (timestamps) vs a sequential CPU scan.

use anyhow::{ensure, Result};
use serde::Serialize;

use super::{median_gpu_time, time_cpu};
use crate::gpu::timings::KernelTotal;
use crate::gpu::{Gpu, GpuCount, PrefixScan};
use crate::util::Rng;

#[derive(Debug, Serialize)]
pub struct ScanBench {
    pub n: u64,
    pub iters: usize,
    pub gpu_ms: f64,
    pub cpu_ms: f64,
    pub gpu_elems_per_s: f64,
    pub cpu_elems_per_s: f64,
    pub ratio: f64,
    pub device: String,
    pub verified: bool,
    pub kernels: Vec<KernelTotal>,
}

pub fn bench_scan(gpu: &Gpu, n: u64, iters: usize, seed: u64) -> Result<ScanBench> {
    ensure!(
        gpu.caps().timestamps,
        "the device has no timestamp queries; GPU time cannot be measured"
    );
    // The device's limit is checked before the host array is made.
    let scan = PrefixScan::new(gpu, n)?;
    let mut rng = Rng::new(seed);
    let data: Vec<u32> = (0..n).map(|_| rng.next_u32() % 1024).collect();
    let input = gpu.buffer_from("bench-scan-in", &data)?;
    let output = gpu.buffer("bench-scan-out", n * 4)?;
    let count = gpu.buffer_from("bench-count", &[n as u32])?;

    let (gpu_ns, kernels) = median_gpu_time(
        gpu,
        iters,
        |_| Ok(()),
        |rec| scan.record(rec, &input, &output, GpuCount::at(&count, 0)),
    )?;
    let (cpu_ns, expected) = time_cpu(
        iters,
        || (),
        |_| {
            let mut acc = 0u32;
            data.iter()
                .map(|&x| {
                    let r = acc;
                    acc = acc.wrapping_add(x);
                    r
                })
                .collect::<Vec<u32>>()
        },
    );
    let got: Vec<u32> = gpu.download(&output, 0, n as usize)?;
    let verified = got == expected;
    ensure!(verified, "GPU scan result differs from the CPU's (n={n})");
    let gpu_elems_per_s = n as f64 / (gpu_ns * 1e-9);
    let cpu_elems_per_s = n as f64 / (cpu_ns * 1e-9);
    Ok(ScanBench {
        n,
        iters,
        gpu_ms: gpu_ns * 1e-6,
        cpu_ms: cpu_ns * 1e-6,
        gpu_elems_per_s,
        cpu_elems_per_s,
        ratio: gpu_elems_per_s / cpu_elems_per_s,
        device: gpu.caps().name.clone(),
        verified,
        kernels,
    })
}
