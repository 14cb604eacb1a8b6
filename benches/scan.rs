//! Criterion: GPU exclusive prefix scan of u32, GPU time per scan.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use semsplat::gpu::{GpuCount, PrefixScan};

#[path = "gpu_bench.rs"]
mod gpu_bench;

fn scan(c: &mut Criterion) {
    let gpu = gpu_bench::gpu();
    let mut group = c.benchmark_group("prefix_scan");
    group.sample_size(10);
    for &n in &gpu_bench::SIZES {
        let data: Vec<u32> = (0..n as u32).map(|i| i % 7).collect();
        let scan = PrefixScan::new(&gpu, n).unwrap();
        let input = gpu.buffer_from("in", &data).unwrap();
        let output = gpu.buffer("out", n * 4).unwrap();
        let count = gpu.buffer_from("count", &[n as u32]).unwrap();
        group.throughput(Throughput::Elements(n));
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter_custom(|iters| {
                gpu_bench::gpu_time(
                    &gpu,
                    iters,
                    |_| {},
                    |rec| {
                        scan.record(rec, &input, &output, GpuCount::at(&count, 0))
                            .unwrap()
                    },
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, scan);
criterion_main!(benches);
