//! The reference forward replayed on f64 parameters: screen-space Gaussians, tile lists and
//! per-pixel compositing through the forward's own [`blend_pixel`], keeping what the
//! backward pass needs (each blended Gaussian's alpha and the transmittance in front of it).

use super::backward_params::GaussianParams;
use super::backward_project::project_params;
use super::backward_semantics::semantic_vector;
use super::{
    blend_pixel, eval_alpha, tile_grid, tile_intersections, tile_ranges, PixelOutcome,
    ProjectedGaussian, ReferenceImage, RenderSettings, TILE_SIZE,
};
use crate::scene::Camera;

/// The visible Gaussians of one view after projection, with what each one blends.
/// Fields are public so tests can perturb screen-space values directly.
#[derive(Clone, Debug, PartialEq)]
pub struct ScreenSpace {
    /// Visible Gaussians in id order (as [`project`](super::project) returns them).
    pub projected: Vec<ProjectedGaussian>,
    /// Semantic channels C blended (0 when the scene has none or semantics are off).
    pub channels: usize,
    /// Per entry of `projected`, its semantic vector `s` (`channels` values).
    pub semantics: Vec<f64>,
}

impl ScreenSpace {
    pub fn new(params: &GaussianParams, cam: &Camera, settings: &RenderSettings) -> ScreenSpace {
        params.check_layout();
        let projected: Vec<ProjectedGaussian> = (0..params.len())
            .filter_map(|i| project_params(params, i, cam, settings).ok())
            .collect();
        let channels = if settings.semantics {
            params.channels
        } else {
            0
        };
        let semantics = if channels == 0 {
            Vec::new()
        } else {
            projected
                .iter()
                .flat_map(|p| {
                    semantic_vector(params.logits_of(p.id as usize), settings.semantic_mode)
                })
                .collect()
        };
        ScreenSpace {
            projected,
            channels,
            semantics,
        }
    }

    /// The semantic vector of entry `slot` of `projected`.
    pub(super) fn semantic_of(&self, slot: usize) -> &[f64] {
        &self.semantics[slot * self.channels..(slot + 1) * self.channels]
    }
}

/// One Gaussian blended at a pixel.
#[derive(Clone, Copy, Debug)]
pub(super) struct Blended {
    /// Index into [`ScreenSpace::projected`].
    pub slot: usize,
    pub alpha: f64,
    /// Transmittance in front of this Gaussian.
    pub t: f64,
    /// `alpha * t`, exactly as the forward passes it.
    pub weight: f64,
}

/// Tile lists over a [`ScreenSpace`].
pub(super) struct Replay<'a> {
    pub screen: &'a ScreenSpace,
    /// Sorted (tile, Gaussian id).
    intersections: Vec<(u32, u32)>,
    /// Per tile, `[start, end)` into `intersections`.
    ranges: Vec<[u32; 2]>,
    /// Gaussian id -> index into `projected`.
    slot_of_id: Vec<usize>,
    tiles_x: u32,
}

impl<'a> Replay<'a> {
    pub fn new(screen: &'a ScreenSpace, cam: &Camera) -> Replay<'a> {
        let intersections = tile_intersections(&screen.projected, cam);
        let (tiles_x, tiles_y) = tile_grid(cam);
        let ranges = tile_ranges(&intersections, tiles_x * tiles_y);
        let ids = screen.projected.iter().map(|p| p.id as usize + 1).max();
        let mut slot_of_id = vec![usize::MAX; ids.unwrap_or(0)];
        for (k, p) in screen.projected.iter().enumerate() {
            slot_of_id[p.id as usize] = k;
        }
        Replay {
            screen,
            intersections,
            ranges,
            slot_of_id,
            tiles_x,
        }
    }

    /// Composites pixel `(px, py)` of `tile`, returning the blended Gaussians front to back.
    fn replay_pixel(&self, tile: u32, px: u32, py: u32) -> (Vec<Blended>, PixelOutcome) {
        let [start, end] = self.ranges[tile as usize];
        let list = self.intersections[start as usize..end as usize]
            .iter()
            .map(|&(_, id)| &self.screen.projected[self.slot_of_id[id as usize]]);
        let mut blended = Vec::new();
        // The same running product as `blend_pixel`, so `t` matches it bit for bit.
        let mut t = 1.0f64;
        let outcome = blend_pixel(list, px, py, |_, p, weight| {
            let alpha = eval_alpha(p, px, py).expect("blend_pixel only blends visible alphas");
            blended.push(Blended {
                slot: self.slot_of_id[p.id as usize],
                alpha,
                t,
                weight,
            });
            t *= 1.0 - alpha;
        });
        debug_assert_eq!(t, outcome.final_t);
        (blended, outcome)
    }

    /// Calls `pixel(px, py, blended, outcome)` for every pixel, tile by tile like the forward.
    pub fn for_each_pixel(
        &self,
        cam: &Camera,
        mut pixel: impl FnMut(u32, u32, &[Blended], &PixelOutcome),
    ) {
        for tile in 0..self.ranges.len() as u32 {
            let (tx, ty) = (tile % self.tiles_x, tile / self.tiles_x);
            let (x0, y0) = (tx * TILE_SIZE, ty * TILE_SIZE);
            for py in y0..(y0 + TILE_SIZE).min(cam.height) {
                for px in x0..(x0 + TILE_SIZE).min(cam.width) {
                    let (blended, outcome) = self.replay_pixel(tile, px, py);
                    pixel(px, py, &blended, &outcome);
                }
            }
        }
    }
}

/// The forward's image of a [`ScreenSpace`] (same sums in the same order as
/// [`render`](super::render)).
pub fn render_screen(
    screen: &ScreenSpace,
    cam: &Camera,
    settings: &RenderSettings,
) -> ReferenceImage {
    let channels = screen.channels;
    let mut img = ReferenceImage::blank(cam, channels);
    let replay = Replay::new(screen, cam);
    replay.for_each_pixel(cam, |px, py, blended, outcome| {
        let mut rgb = [0.0f64; 3];
        let mut depth_sum = 0.0f64;
        let mut sem = vec![0.0f64; channels];
        for b in blended {
            let p = &screen.projected[b.slot];
            for (acc, c) in rgb.iter_mut().zip(p.color) {
                *acc += b.weight * c;
            }
            depth_sum += b.weight * p.depth;
            for (acc, s) in sem.iter_mut().zip(screen.semantic_of(b.slot)) {
                *acc += b.weight * s;
            }
        }
        let i = (py * cam.width + px) as usize;
        img.store_pixel(i, (&rgb, depth_sum, &sem), outcome, settings.background);
    });
    img
}

/// The forward's image of f64 parameters; equals [`render`](super::render) on a scene whose
/// float32 values convert to `params`.
pub fn render_params(
    params: &GaussianParams,
    cam: &Camera,
    settings: &RenderSettings,
) -> ReferenceImage {
    render_screen(&ScreenSpace::new(params, cam, settings), cam, settings)
}
