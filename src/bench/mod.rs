//! Measurements behind `semsplat bench`: GPU time from timestamp queries, against a CPU
//! baseline on the same data in the same run, with the GPU result checked against it (or,
//! for fusion, against a forward render of the same views).

pub mod export;
pub mod fuse;
pub mod render;
pub mod scan;
pub mod sort;
pub mod train;

use std::time::Instant;

use crate::gpu::timings::KernelTotal;
use crate::gpu::{Gpu, GpuResult, Recorder};

/// GPU time of `runs` submissions of `record`, each after an untimed `prepare`, from the
/// timestamps around `record` (ns per run), and each run's per-kernel split.
pub fn time_gpu(
    gpu: &Gpu,
    runs: usize,
    mut prepare: impl FnMut(&mut Recorder) -> GpuResult<()>,
    mut record: impl FnMut(&mut Recorder) -> GpuResult<()>,
) -> GpuResult<(Vec<f64>, Vec<Vec<KernelTotal>>)> {
    let mut samples = Vec::with_capacity(runs);
    let mut kernels = Vec::with_capacity(runs);
    for _ in 0..runs {
        let mut rec = Recorder::new(gpu)?;
        prepare(&mut rec)?;
        rec.barrier();
        let start = rec.mark();
        record(&mut rec)?;
        let end = rec.mark();
        let timings = rec.submit_and_wait()?;
        samples.push(timings.between(start, end).unwrap_or(f64::NAN));
        kernels.push(timings.by_kernel());
    }
    Ok((samples, kernels))
}

/// Median GPU time (ns) of `iters` timed runs after one warm-up (pipeline creation, first
/// touches), with the per-kernel split of the median run ([`median_run`]).
pub fn median_gpu_time(
    gpu: &Gpu,
    iters: usize,
    mut prepare: impl FnMut(&mut Recorder) -> GpuResult<()>,
    mut record: impl FnMut(&mut Recorder) -> GpuResult<()>,
) -> GpuResult<(f64, Vec<KernelTotal>)> {
    time_gpu(gpu, 1, &mut prepare, &mut record)?;
    let (mut samples, mut kernels) = time_gpu(gpu, iters.max(1), prepare, record)?;
    let split = std::mem::take(&mut kernels[median_run(&samples)]);
    Ok((median(&mut samples), split))
}

/// The run whose time is the median (of an even count, the faster of the middle two): the
/// one whose per-kernel split is reported, so that the split adds up to a time near the
/// median rather than to whichever run came last (a noisy machine's last of three took
/// 364 ms where the median was 250).
pub fn median_run(samples: &[f64]) -> usize {
    let mut order: Vec<usize> = (0..samples.len()).collect();
    order.sort_by(|&a, &b| samples[a].total_cmp(&samples[b]));
    order[(samples.len().max(1) - 1) / 2]
}

/// How long untimed work runs before a timed GPU benchmark: an idle GPU takes a while to
/// reach its working clocks (on an H100 the median of a 1080p frame's first ten runs after
/// start measured 20 ms, warmed up 9 ms).
pub const WARMUP: std::time::Duration = std::time::Duration::from_millis(500);

/// Runs `step` (untimed) at least three times and until [`WARMUP`] has passed.
pub fn warm_up(mut step: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut runs = 0;
    while runs < 3 || start.elapsed() < WARMUP {
        step()?;
        runs += 1;
    }
    Ok(())
}

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

/// A benchmark's scene (at least one Gaussian, fewer than 2^32), as `fuse --scene` takes it
/// (a scene folder, an INRIA run, a scene file), and the cameras of its folder's
/// `cameras.json` (at least one).
pub fn read_scene_folder(
    dir: &std::path::Path,
) -> anyhow::Result<(crate::scene::Gaussians, Vec<crate::scene::Camera>)> {
    use crate::scene::scene_file::{
        read_scene, resolve_scene_path, scene_cameras_file, CAMERAS_FILE,
    };
    use anyhow::ensure;
    let scene = resolve_scene_path(dir)?;
    let g = read_scene(&scene)?;
    ensure!(!g.is_empty(), "{} has no Gaussians", scene.display());
    ensure!(
        g.len() <= u32::MAX as usize,
        "{} has 2^32 Gaussians or more",
        scene.display()
    );
    // Where `fuse` and `render` find a scene's own cameras (an INRIA run's beside its
    // point_cloud folder too).
    let Some(json) = scene_cameras_file(dir) else {
        anyhow::bail!(
            "--scene {}: no {CAMERAS_FILE} beside the scene; bench times a scene on its own \
             cameras, as a synth room, an INRIA run or `bench --export`'s folder holds them",
            dir.display()
        );
    };
    let cams = crate::scene::cameras_json::read_cameras_json(&json)?;
    ensure!(!cams.is_empty(), "{} has no camera", json.display());
    Ok((g, cams))
}

#[cfg(test)]
mod tests {
    use super::{median, median_run};

    #[test]
    fn the_median_run_is_the_one_whose_time_is_the_median() {
        let mut odd = [364.0, 250.0, 240.0];
        assert_eq!(median_run(&odd), 1);
        assert_eq!(median(&mut odd), 250.0);
        // Of an even count, the faster of the middle two.
        assert_eq!(median_run(&[9.0, 1.0, 5.0, 7.0]), 2);
        assert_eq!(median_run(&[3.0]), 0);
    }
}
