//! Per-pixel front-to-back compositing over a tile's depth-ordered list.

use super::project::{ProjectedGaussian, ALPHA_THRESHOLD};

/// Alpha is clamped to this before blending.
pub const MAX_ALPHA: f64 = 0.999;
/// A pixel stops (without blending the Gaussian) once `next_T <= T_STOP`.
pub const T_STOP: f64 = 1e-4;

/// The Gaussian's alpha at the center of pixel `(px, py)`, or `None` when the pixel skips
/// it (`sigma < 0` or `alpha < 1/255`).
pub fn eval_alpha(p: &ProjectedGaussian, px: u32, py: u32) -> Option<f64> {
    let dx = p.mean2d.x - (px as f64 + 0.5);
    let dy = p.mean2d.y - (py as f64 + 0.5);
    let [a, b, c] = p.conic;
    let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
    if sigma < 0.0 {
        return None;
    }
    let alpha = (p.opacity * (-sigma).exp()).min(MAX_ALPHA);
    if alpha < ALPHA_THRESHOLD {
        return None;
    }
    Some(alpha)
}

/// What is left at a pixel after compositing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelOutcome {
    /// Transmittance after the last blended Gaussian.
    pub final_t: f64,
    /// How many Gaussians were blended.
    pub n_contrib: u32,
    /// The last blended Gaussian: (position in the tile's ordered list, Gaussian id).
    pub last: Option<(u32, u32)>,
}

/// Composites pixel `(px, py)` over `list` (the tile's Gaussians, front to back), calling
/// `blend(position_in_list, gaussian, weight = alpha * T)` for each blended Gaussian.
pub fn blend_pixel<'a>(
    list: impl IntoIterator<Item = &'a ProjectedGaussian>,
    px: u32,
    py: u32,
    mut blend: impl FnMut(u32, &'a ProjectedGaussian, f64),
) -> PixelOutcome {
    let mut t = 1.0f64;
    let mut n_contrib = 0u32;
    let mut last = None;
    for (pos, p) in list.into_iter().enumerate() {
        let Some(alpha) = eval_alpha(p, px, py) else {
            continue;
        };
        let next_t = t * (1.0 - alpha);
        if next_t <= T_STOP {
            break;
        }
        blend(pos as u32, p, alpha * t);
        t = next_t;
        n_contrib += 1;
        last = Some((pos as u32, p.id));
    }
    PixelOutcome {
        final_t: t,
        n_contrib,
        last,
    }
}
