//! Criterion: GPU radix sort of u32 pairs (32-bit and 13-bit keys), GPU time per sort.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use semsplat::gpu::{GpuCount, RadixSort};
use semsplat::util::Rng;

#[path = "gpu_bench.rs"]
mod gpu_bench;

fn sort(c: &mut Criterion) {
    let gpu = gpu_bench::gpu();
    let mut group = c.benchmark_group("radix_sort");
    group.sample_size(10);
    for &n in &gpu_bench::SIZES {
        let mut rng = Rng::new(n);
        let keys: Vec<u32> = (0..n).map(|_| rng.next_u32()).collect();
        let values: Vec<u32> = (0..n as u32).collect();
        let sorter = RadixSort::new(&gpu, n).unwrap();
        let src = gpu.buffer_from("src", &keys).unwrap();
        let k = gpu.buffer("k", n * 4).unwrap();
        let v = gpu.buffer_from("v", &values).unwrap();
        let count = gpu.buffer_from("count", &[n as u32]).unwrap();
        group.throughput(Throughput::Elements(n));
        for bits in [32u32, 13] {
            group.bench_with_input(BenchmarkId::new(format!("{bits}bit"), n), &n, |b, _| {
                b.iter_custom(|iters| {
                    gpu_bench::gpu_time(
                        &gpu,
                        iters,
                        // Restore the unsorted keys (untimed): re-sorting sorted keys would be
                        // a different workload.
                        |rec| rec.copy(&src, 0, &k, 0, n * 4),
                        |rec| {
                            sorter
                                .record(rec, &k, &v, GpuCount::at(&count, 0), bits)
                                .unwrap()
                        },
                    )
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, sort);
criterion_main!(benches);
