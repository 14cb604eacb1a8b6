//! Forward rendering throughput on a random scene: frames/s and the per-stage split.

use anyhow::Result;
use glam::DVec3;
use serde::Serialize;

use super::median;
use crate::gpu::Gpu;
use crate::render::{GpuScene, Rasterizer, RenderOptions, SemanticMode, StageTimes};
use crate::scene::random_scene::{random_scene, RandomSceneSpec};
use crate::scene::Camera;

#[derive(Debug, Serialize)]
pub struct RenderBench {
    pub n: usize,
    pub width: u32,
    pub height: u32,
    pub channels: usize,
    pub iters: usize,
    pub device: String,
    /// Median GPU time of a frame (all stages), from timestamps.
    pub frame_ms: f64,
    pub frames_per_s: f64,
    /// Median of each stage.
    pub stages: StageTimes,
    pub visible: u32,
    pub intersections: u32,
}

pub fn bench_render(
    gpu: &Gpu,
    n: usize,
    width: u32,
    height: u32,
    channels: usize,
    iters: usize,
    seed: u64,
) -> Result<RenderBench> {
    let g = random_scene(&RandomSceneSpec {
        n,
        channels,
        sh_degree: 3,
        seed,
        ..Default::default()
    });
    let scene = GpuScene::upload(gpu, &g)?;
    let cam = Camera::look_at(
        "bench",
        DVec3::ZERO,
        DVec3::Z,
        -DVec3::Y,
        width,
        height,
        70.0,
    );
    let opts = RenderOptions {
        semantics: (channels > 0).then_some(SemanticMode::RawLogits),
        ..Default::default()
    };
    let mut raster = Rasterizer::new(gpu);
    let warm = raster.render(&scene, &cam, &opts)?;
    let mut frames = Vec::new();
    for _ in 0..iters.max(1) {
        frames.push(raster.render(&scene, &cam, &opts)?.stages);
    }
    let med = |f: fn(&StageTimes) -> f64| median(&mut frames.iter().map(f).collect::<Vec<_>>());
    let stages = StageTimes {
        project_ms: med(|s| s.project_ms),
        depth_sort_ms: med(|s| s.depth_sort_ms),
        bin_ms: med(|s| s.bin_ms),
        blend_ms: med(|s| s.blend_ms),
    };
    let frame_ms = med(StageTimes::total_ms);
    Ok(RenderBench {
        n,
        width,
        height,
        channels,
        iters,
        device: gpu.caps().name.clone(),
        frame_ms,
        frames_per_s: 1e3 / frame_ms,
        stages,
        visible: warm.visible,
        intersections: warm.intersections,
    })
}
