//! Measurements behind `semsplat bench`: GPU time from timestamp queries, against a CPU
//! baseline on the same data in the same run, with the GPU result checked against it.

pub mod render;
pub mod scan;
pub mod sort;

use std::time::Instant;

/// Median of the samples (NaN when empty).
pub fn median(samples: &mut [f64]) -> f64 {
    if samples.is_empty() {
        return f64::NAN;
    }
    samples.sort_by(f64::total_cmp);
    let m = samples.len() / 2;
    if samples.len() % 2 == 1 {
        samples[m]
    } else {
        0.5 * (samples[m - 1] + samples[m])
    }
}

/// Median wall time in ns of `iters` runs of `f`, each given fresh input from `setup`.
pub fn time_cpu<T, R>(
    iters: usize,
    mut setup: impl FnMut() -> T,
    mut f: impl FnMut(T) -> R,
) -> (f64, R) {
    let mut samples = Vec::with_capacity(iters);
    let mut last = None;
    for _ in 0..iters.max(1) {
        let input = setup();
        let start = Instant::now();
        let r = f(input);
        samples.push(start.elapsed().as_nanos() as f64);
        last = Some(r);
    }
    (median(&mut samples), last.expect("at least one run"))
}
