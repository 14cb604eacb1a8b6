//! Forward rendering throughput: frames/s and the per-stage split, on a random scene or on
//! a scene folder (`scene.ply` + `cameras.json`, e.g. a `synth` room).

use std::path::PathBuf;

use anyhow::Result;
use glam::DVec3;
use serde::Serialize;

use super::export::export_inputs;
use super::{median, median_run, warm_up};
use crate::gpu::timings::KernelTotal;
use crate::gpu::Gpu;
use crate::render::{BandWork, GpuScene, Rasterizer, RenderOptions, SemanticMode, StageTimes};
use crate::scene::random_scene::{random_scene, RandomSceneSpec};
use crate::scene::{Camera, Gaussians, SemanticLogits};
use crate::util::Rng;

/// The scene and view a render or training benchmark works on.
#[derive(Clone, Debug, Serialize)]
pub struct BenchInput {
    /// Gaussians of the random scene (SH degree 3); none with `scene` (its count is the
    /// report's `gaussians`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub n: Option<usize>,
    /// Image size of the random scene's camera; with `scene`, its camera's.
    pub width: u32,
    pub height: u32,
    /// Semantic channels blended with RGB (0: RGB only); random logits.
    pub channels: usize,
    pub seed: u64,
    /// A folder with `scene.ply` and `cameras.json` (its first camera is used) instead of
    /// the random scene.
    pub scene: Option<PathBuf>,
    /// Write the scene and camera here first (see [`super::export`]).
    #[serde(skip)]
    pub export: Option<PathBuf>,
}

impl BenchInput {
    /// Loads or generates the scene (with `channels` random logits) and its camera, and
    /// exports them when asked.
    pub fn load(&self) -> Result<(Gaussians, Camera)> {
        let (g, cam) = match &self.scene {
            Some(dir) => self.load_folder(dir)?,
            None => self.random(),
        };
        if let Some(dir) = &self.export {
            let opts = RenderOptions::default();
            export_inputs(dir, &g, std::slice::from_ref(&cam), &opts, None)?;
        }
        Ok((g, cam))
    }

    /// The random scene, which fills the view cone of a camera at the origin looking down
    /// +z; its logits are drawn after the geometry, so every channel count sees the same
    /// Gaussians.
    fn random(&self) -> (Gaussians, Camera) {
        let g = random_scene(&RandomSceneSpec {
            n: self.n.unwrap_or_default(),
            channels: self.channels,
            sh_degree: 3,
            seed: self.seed,
            ..Default::default()
        });
        let (w, h) = (self.width, self.height);
        let cam = Camera::look_at("bench", DVec3::ZERO, DVec3::Z, -DVec3::Y, w, h, 70.0);
        (g, cam)
    }

    /// This input with the image size of the camera actually used (a folder's).
    pub fn with_size_of(&self, cam: &Camera) -> BenchInput {
        BenchInput {
            width: cam.width,
            height: cam.height,
            ..self.clone()
        }
    }

    fn load_folder(&self, dir: &std::path::Path) -> Result<(Gaussians, Camera)> {
        let (mut g, cams) = super::read_scene_folder(dir)?;
        let cam = cams
            .into_iter()
            .next()
            .expect("read_scene_folder checks for one");
        g.semantics = (self.channels > 0).then(|| {
            let mut rng = Rng::new(self.seed);
            SemanticLogits {
                channels: self.channels,
                logits: (0..g.len() * self.channels)
                    .map(|_| (rng.normal() * 2.0) as f32)
                    .collect(),
            }
        });
        Ok((g, cam))
    }
}

#[derive(Debug, Serialize)]
pub struct RenderBench {
    #[serde(flatten)]
    pub input: BenchInput,
    /// Gaussians rendered (the random scene's `n` or the folder's).
    pub gaussians: usize,
    pub iters: usize,
    pub device: String,
    /// Median GPU time of a frame (all stages), from timestamps.
    pub frame_ms: f64,
    pub frames_per_s: f64,
    /// Median of each stage.
    pub stages: StageTimes,
    pub visible: u32,
    pub intersections: u32,
    /// GPU time per kernel of the last frame.
    pub kernels: Vec<KernelTotal>,
}

pub fn bench_render(gpu: &Gpu, input: &BenchInput, iters: usize) -> Result<RenderBench> {
    let (g, cam) = input.load()?;
    let scene = GpuScene::upload(gpu, &g)?;
    let opts = RenderOptions {
        semantics: (input.channels > 0).then_some(SemanticMode::RawLogits),
        ..Default::default()
    };
    let mut raster = Rasterizer::new(gpu);
    // The frame stays on the device (downloading it is no part of rendering).
    let mut frame = || {
        raster.run_tiled_in_bands(&scene, &cam, &opts, BandWork::Overwrite, |r, t| {
            t.record_blend(r)
        })
    };
    let warm = frame()?;
    warm_up(|| frame().map(drop))?;
    let mut frames = Vec::new();
    let mut kernels = Vec::new();
    for _ in 0..iters.max(1) {
        let run = frame()?;
        frames.push(run.stages);
        kernels.push(run.timings.by_kernel());
    }
    let totals: Vec<f64> = frames.iter().map(StageTimes::total_ms).collect();
    let kernels = std::mem::take(&mut kernels[median_run(&totals)]);
    let med = |f: fn(&StageTimes) -> f64| median(&mut frames.iter().map(f).collect::<Vec<_>>());
    let stages = StageTimes {
        project_ms: med(|s| s.project_ms),
        depth_sort_ms: med(|s| s.depth_sort_ms),
        bin_ms: med(|s| s.bin_ms),
        blend_ms: med(|s| s.blend_ms),
    };
    let frame_ms = med(StageTimes::total_ms);
    Ok(RenderBench {
        input: input.with_size_of(&cam),
        gaussians: g.len(),
        iters,
        device: gpu.caps().name.clone(),
        frame_ms,
        frames_per_s: 1e3 / frame_ms,
        stages,
        visible: warm.visible,
        intersections: warm.intersections,
        kernels,
    })
}
