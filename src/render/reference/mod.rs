//! Independent CPU reference renderer (f64), the ground truth the GPU rasterizer is tested
//! against. It implements gsplat 1.5's classic 3DGS forward pass (see `DESIGN.md`,
//! "Conventions that decide agreement with other renderers") with plain loops:
//!
//! 1. [`project`]: camera-space mean, covariance `R S S^T R^T`, clamped Jacobian, 2D
//!    covariance + 0.3 px^2, conic, opacity, SH color, opacity-aware pixel/tile extent.
//! 2. [`tile_intersections`]: (tile, Gaussian) pairs sorted by tile, depth, id.
//! 3. [`render`] / [`for_each_contribution`]: per pixel, front-to-back over the pixel's
//!    tile list with weights `alpha * T`; RGB, alpha, depth and C semantic channels, the
//!    latter also normalized by `1 - T_final` (Gaussian Semantics Eq. 2, docs/papers.md).
//!
//! Clarity over speed; it is still fast enough for test scenes (tens of thousands of
//! Gaussians at small resolutions) because each pixel only walks its tile's list.

pub mod backward;
mod backward_blend;
mod backward_params;
mod backward_project;
mod backward_projection;
mod backward_replay;
mod backward_semantics;
mod backward_sh;
mod blend;
mod project;
mod sh;
mod tiles;

pub use blend::{blend_pixel, eval_alpha, PixelOutcome, MAX_ALPHA, T_STOP};
pub use project::{
    covariance_3d, pixel_range, project, project_covariance, project_one, projection_jacobian,
    quat_to_rotation, Culled, ProjectedGaussian, TileRange, ALPHA_THRESHOLD, COV2D_DILATION,
    DET_MIN, FRUSTUM_MARGIN,
};
pub use sh::{eval_sh, sh_basis, sh_color, SH_C0, SH_C1, SH_C2, SH_C3};
pub use tiles::{tile_grid, tile_intersections, tile_ranges, TILE_SIZE};

use crate::scene::{Camera, Gaussians};

/// What a semantic channel holds per Gaussian before blending.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SemanticMode {
    /// The Gaussian's logits as stored.
    #[default]
    RawLogits,
    /// `softmax(logits)` per Gaussian, then blended.
    Softmax,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Added as `T_final * background`.
    pub background: [f64; 3],
    /// Cull when camera-space depth `<= near`.
    pub near: f64,
    /// Cull when camera-space depth `>= far`.
    pub far: f64,
    pub semantic_mode: SemanticMode,
    /// Render the semantic channels when the scene has them (`false`: RGB only, C = 0).
    pub semantics: bool,
    /// Evaluate SH up to this degree (capped at the scene's); `None`: the scene's degree.
    pub sh_degree: Option<u32>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            background: [0.0; 3],
            near: 0.01,
            far: 1e10,
            semantic_mode: SemanticMode::RawLogits,
            semantics: true,
            sh_degree: None,
        }
    }
}

/// Per-pixel outputs, row-major (`index = py * width + px`); semantic buffers hold
/// `channels` values per pixel, channel fastest.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceImage {
    pub width: u32,
    pub height: u32,
    /// Semantic channels C (0 when the scene has none or semantics were not asked for).
    pub channels: usize,
    /// `sum w color + T_final * background`.
    pub rgb: Vec<[f64; 3]>,
    /// `1 - T_final`.
    pub alpha: Vec<f64>,
    /// Expected depth `sum w z / (1 - T_final)`, 0 where nothing was blended.
    pub depth: Vec<f64>,
    /// Accumulated depth `sum w z` (not normalized).
    pub depth_sum: Vec<f64>,
    /// `sum w s` (not normalized), `H * W * C`.
    pub sem: Vec<f64>,
    /// `sum w s / (1 - T_final)` (Gaussian Semantics Eq. 2), 0 where nothing was blended.
    pub sem_norm: Vec<f64>,
    /// Transmittance left after the last blended Gaussian.
    pub final_t: Vec<f64>,
    /// Number of blended Gaussians.
    pub n_contrib: Vec<u32>,
    /// Id of the last blended Gaussian.
    pub last_contributor_id: Vec<Option<u32>>,
    /// Position of the last blended Gaussian in its tile's ordered list.
    pub last_contributor_pos: Vec<Option<u32>>,
}

impl ReferenceImage {
    pub fn index(&self, px: u32, py: u32) -> usize {
        assert!(px < self.width && py < self.height, "pixel out of range");
        (py * self.width + px) as usize
    }

    pub fn rgb_at(&self, px: u32, py: u32) -> [f64; 3] {
        self.rgb[self.index(px, py)]
    }

    pub fn alpha_at(&self, px: u32, py: u32) -> f64 {
        self.alpha[self.index(px, py)]
    }

    pub fn sem_at(&self, px: u32, py: u32) -> &[f64] {
        let i = self.index(px, py) * self.channels;
        &self.sem[i..i + self.channels]
    }

    pub fn sem_norm_at(&self, px: u32, py: u32) -> &[f64] {
        let i = self.index(px, py) * self.channels;
        &self.sem_norm[i..i + self.channels]
    }

    /// An image with nothing blended yet (T = 1 everywhere).
    pub(super) fn blank(cam: &Camera, channels: usize) -> ReferenceImage {
        let npix = (cam.width * cam.height) as usize;
        ReferenceImage {
            width: cam.width,
            height: cam.height,
            channels,
            rgb: vec![[0.0; 3]; npix],
            alpha: vec![0.0; npix],
            depth: vec![0.0; npix],
            depth_sum: vec![0.0; npix],
            sem: vec![0.0; npix * channels],
            sem_norm: vec![0.0; npix * channels],
            final_t: vec![1.0; npix],
            n_contrib: vec![0; npix],
            last_contributor_id: vec![None; npix],
            last_contributor_pos: vec![None; npix],
        }
    }

    /// Stores pixel `i`'s outputs from its blended sums (`sum w c`, `sum w z`, `sum w s`)
    /// and what compositing left: background, normalization by `1 - T_final` (Gaussian
    /// Semantics Eq. 2, docs/papers.md).
    pub(super) fn store_pixel(
        &mut self,
        i: usize,
        sums: (&[f64; 3], f64, &[f64]),
        outcome: &PixelOutcome,
        background: [f64; 3],
    ) {
        let (rgb, depth_sum, sem) = sums;
        let channels = self.channels;
        let t = outcome.final_t;
        let covered = 1.0 - t;
        for (ch, acc) in rgb.iter().enumerate() {
            self.rgb[i][ch] = acc + t * background[ch];
        }
        self.alpha[i] = covered;
        self.depth_sum[i] = depth_sum;
        self.depth[i] = if covered > 0.0 {
            depth_sum / covered
        } else {
            0.0
        };
        for (c, acc) in sem.iter().enumerate() {
            self.sem[i * channels + c] = *acc;
            self.sem_norm[i * channels + c] = if covered > 0.0 { acc / covered } else { 0.0 };
        }
        self.final_t[i] = t;
        self.n_contrib[i] = outcome.n_contrib;
        self.last_contributor_pos[i] = outcome.last.map(|(pos, _)| pos);
        self.last_contributor_id[i] = outcome.last.map(|(_, id)| id);
    }
}

/// Projection plus tile lists for one view.
struct Frame {
    projected: Vec<ProjectedGaussian>,
    /// Sorted (tile, Gaussian id).
    intersections: Vec<(u32, u32)>,
    /// Per tile, `[start, end)` into `intersections`.
    ranges: Vec<[u32; 2]>,
    /// Gaussian id -> index into `projected` (only read for visible ids).
    slot: Vec<usize>,
    tiles_x: u32,
}

impl Frame {
    fn new(g: &Gaussians, cam: &Camera, settings: &RenderSettings) -> Frame {
        let projected = project(g, cam, settings);
        let intersections = tile_intersections(&projected, cam);
        let (tiles_x, tiles_y) = tile_grid(cam);
        let ranges = tile_ranges(&intersections, tiles_x * tiles_y);
        let mut slot = vec![usize::MAX; g.len()];
        for (k, p) in projected.iter().enumerate() {
            slot[p.id as usize] = k;
        }
        Frame {
            projected,
            intersections,
            ranges,
            slot,
            tiles_x,
        }
    }

    /// The tile's Gaussians, front to back.
    fn tile_list(&self, tile: u32) -> impl Iterator<Item = &ProjectedGaussian> + '_ {
        let [start, end] = self.ranges[tile as usize];
        self.intersections[start as usize..end as usize]
            .iter()
            .map(|&(_, id)| &self.projected[self.slot[id as usize]])
    }

    /// Calls `pixel(px, py, tile)` for every pixel of the image, tile by tile.
    fn for_each_pixel(&self, cam: &Camera, mut pixel: impl FnMut(u32, u32, u32)) {
        for tile in 0..self.ranges.len() as u32 {
            let (tx, ty) = (tile % self.tiles_x, tile / self.tiles_x);
            let x0 = tx * TILE_SIZE;
            let y0 = ty * TILE_SIZE;
            for py in y0..(y0 + TILE_SIZE).min(cam.height) {
                for px in x0..(x0 + TILE_SIZE).min(cam.width) {
                    pixel(px, py, tile);
                }
            }
        }
    }
}

/// The semantic vector `s` of each projected Gaussian (`projected.len() * channels`).
fn semantic_vectors(
    g: &Gaussians,
    projected: &[ProjectedGaussian],
    channels: usize,
    mode: SemanticMode,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(projected.len() * channels);
    let Some(sem) = &g.semantics else {
        return out;
    };
    for p in projected {
        let i = p.id as usize * channels;
        let logits: Vec<f64> = sem.logits[i..i + channels]
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        match mode {
            SemanticMode::RawLogits => out.extend_from_slice(&logits),
            SemanticMode::Softmax => {
                let max = logits.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let exps: Vec<f64> = logits.iter().map(|v| (v - max).exp()).collect();
                let total: f64 = exps.iter().sum();
                out.extend(exps.iter().map(|e| e / total));
            }
        }
    }
    out
}

/// Renders one view. Panics when the scene's arrays are inconsistent.
pub fn render(g: &Gaussians, cam: &Camera, settings: &RenderSettings) -> ReferenceImage {
    let frame = Frame::new(g, cam, settings);
    let channels = match &g.semantics {
        Some(s) if settings.semantics => s.channels,
        _ => 0,
    };
    let svec = semantic_vectors(g, &frame.projected, channels, settings.semantic_mode);
    // Per Gaussian id, its row in `svec` (= its index in `projected`).
    let slot = &frame.slot;

    let mut img = ReferenceImage::blank(cam, channels);

    let mut sem_acc = vec![0.0f64; channels];
    frame.for_each_pixel(cam, |px, py, tile| {
        let mut rgb = [0.0f64; 3];
        let mut depth_sum = 0.0f64;
        sem_acc.iter_mut().for_each(|v| *v = 0.0);
        let outcome = blend_pixel(frame.tile_list(tile), px, py, |_, p, w| {
            for (acc, c) in rgb.iter_mut().zip(p.color) {
                *acc += w * c;
            }
            depth_sum += w * p.depth;
            let row = slot[p.id as usize] * channels;
            for (acc, s) in sem_acc.iter_mut().zip(&svec[row..row + channels]) {
                *acc += w * s;
            }
        });

        let i = (py * cam.width + px) as usize;
        img.store_pixel(
            i,
            (&rgb, depth_sum, &sem_acc),
            &outcome,
            settings.background,
        );
    });
    img
}

/// Visits, front to back, every Gaussian a pixel meets as `f(px, py, gaussian_id, t, alpha)`
/// (`t` the transmittance in front of it), up to and including the one that saturates the
/// pixel, which blending stops at without blending it: the occlusion tests' depths (the
/// Gaussian that takes the transmittance below a threshold) count it, as it hides what lies
/// behind it. Panics when the scene's arrays are inconsistent.
pub fn for_each_step(
    g: &Gaussians,
    cam: &Camera,
    settings: &RenderSettings,
    mut f: impl FnMut(u32, u32, u32, f64, f64),
) {
    let frame = Frame::new(g, cam, settings);
    frame.for_each_pixel(cam, |px, py, tile| {
        let mut t = 1.0f64;
        for p in frame.tile_list(tile) {
            let Some(alpha) = eval_alpha(p, px, py) else {
                continue;
            };
            f(px, py, p.id, t, alpha);
            t *= 1.0 - alpha;
            if t <= T_STOP {
                break;
            }
        }
    });
}

/// Visits every blended (pixel, Gaussian) pair as `f(px, py, gaussian_id, weight)` with
/// `weight = alpha * T`, pixels tile by tile and, within a pixel, front to back: the CPU
/// reference for FlashSplat's contribution matrix. Panics when the scene's arrays are
/// inconsistent.
pub fn for_each_contribution(
    g: &Gaussians,
    cam: &Camera,
    settings: &RenderSettings,
    mut f: impl FnMut(u32, u32, u32, f64),
) {
    let frame = Frame::new(g, cam, settings);
    frame.for_each_pixel(cam, |px, py, tile| {
        blend_pixel(frame.tile_list(tile), px, py, |_, p, w| f(px, py, p.id, w));
    });
}
