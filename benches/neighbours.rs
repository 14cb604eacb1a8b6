//! Criterion: every Gaussian's 8 nearest neighbours on the host (the k-d tree of
//! src/fuse/neighbours.rs), wall time, on two layouts of a million centers: all on one
//! surface (a synthetic room's case), and a dense subject with 1% of the centers scattered
//! up to a hundred times its size out (a trained scene's case, which a uniform grid sized
//! by the bounding box could not search in reasonable time).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use semsplat::fuse::nearest_neighbours;
use semsplat::util::Rng;

const N: usize = 1 << 20;

/// `n` centers on the unit sphere, the last `far` of them moved out to 2..100.
fn centers(n: usize, far: usize) -> Vec<[f32; 3]> {
    let mut rng = Rng::new(1);
    (0..n)
        .map(|i| {
            let r = if i < n - far {
                1.0
            } else {
                rng.range_f64(2.0, 100.0)
            };
            rng.direction().map(|x| (x * r) as f32)
        })
        .collect()
}

fn neighbours(c: &mut Criterion) {
    let mut group = c.benchmark_group("nearest_neighbours_8");
    group.sample_size(10);
    group.throughput(Throughput::Elements(N as u64));
    for (name, far) in [("one_surface", 0), ("many_scales", N / 100)] {
        let means = centers(N, far);
        group.bench_with_input(BenchmarkId::from_parameter(name), &means, |b, means| {
            b.iter(|| nearest_neighbours(means, 8))
        });
    }
    group.finish();
}

criterion_group!(benches, neighbours);
criterion_main!(benches);
