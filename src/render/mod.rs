//! Rendering: the GPU rasterizer and its independent CPU reference.

pub mod backward;
pub mod chunks;
pub mod frame;
pub mod gpu_scene;
pub mod rasterizer;
pub mod reference;
pub mod windows;

pub use frame::RenderedFrame;
pub use gpu_scene::GpuScene;
pub use rasterizer::{BandWork, Rasterizer};

use serde::Serialize;

use crate::gpu::{Mark, Timings};

/// The world-to-camera transform as three float32 rows (R00 R01 R02 t0, ...), as the
/// kernels take it in push constants; `cam` in the device's coordinates
/// ([`GpuScene::local_camera`]).
pub(crate) fn camera_rows_f32(cam: &crate::scene::Camera) -> [[f32; 4]; 3] {
    let (r, t) = (cam.rotation, cam.translation);
    [0, 1, 2].map(|k| {
        let row = r.row(k);
        [row.x as f32, row.y as f32, row.z as f32, t[k] as f32]
    })
}

/// Push constants of projection and its backward for `cam` over `scene`, culling center
/// depths outside (near, far).
pub(crate) fn project_params(
    cam: &crate::scene::Camera,
    scene: &GpuScene,
    near: f32,
    far: f32,
) -> crate::contract::params::ProjectParams {
    let cam = &scene.local_camera(cam);
    let c = cam.center();
    crate::contract::params::ProjectParams {
        world_to_camera: camera_rows_f32(cam),
        intrinsics: [cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32],
        camera_center: [c.x as f32, c.y as f32, c.z as f32],
        near,
        far,
        width: cam.width,
        height: cam.height,
        n: scene.n,
        sh_degree: scene.sh_degree,
        sh_coeffs: scene.sh_coeffs,
    }
}

/// What the semantic buffer blends (Gaussian Semantics and its softmax-before-blending ablation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub enum SemanticMode {
    /// Each Gaussian's raw logits.
    #[default]
    RawLogits,
    /// softmax(logits) per Gaussian, before blending.
    Softmax,
}

/// How to render a view.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub background: [f32; 3],
    /// Gaussians whose center depth is <= near or >= far are culled.
    pub near: f32,
    pub far: f32,
    /// Blend the semantic channels in this mode; None renders RGB only (and pays nothing
    /// for semantics).
    pub semantics: Option<SemanticMode>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            background: [0.0; 3],
            near: 0.01,
            far: 1e10,
            semantics: Some(SemanticMode::RawLogits),
        }
    }
}

/// GPU time per stage of one frame, in milliseconds (zero without timestamps).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StageTimes {
    /// Projection, SH, visibility compaction.
    pub project_ms: f64,
    /// Depth sort of the visible Gaussians.
    pub depth_sort_ms: f64,
    /// Tile intersections: emission, stable sort by tile, tile ranges.
    pub bin_ms: f64,
    /// Forward blending (all semantic chunks and windows).
    pub blend_ms: f64,
}

impl StageTimes {
    pub(crate) fn from_marks(t: &Timings, m: &[Option<Mark>; 5]) -> StageTimes {
        let ms = |a: usize, b: usize| t.between(m[a], m[b]).unwrap_or(0.0) * 1e-6;
        StageTimes {
            project_ms: ms(0, 1),
            depth_sort_ms: ms(1, 2),
            bin_ms: ms(2, 3),
            blend_ms: ms(3, 4),
        }
    }

    pub fn total_ms(&self) -> f64 {
        self.project_ms + self.depth_sort_ms + self.bin_ms + self.blend_ms
    }
}
