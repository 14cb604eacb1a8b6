//! Backward of per-pixel compositing: from the gradients of a pixel's outputs (RGB, alpha,
//! normalized semantics) to each blended Gaussian's screen-space values.
//!
//! At one pixel, with the blended Gaussians `i = 0..N` front to back, `T_i = prod_{j<i}
//! (1 - alpha_j)` and `T_N` the final transmittance, the forward computes
//!   rgb = sum_i alpha_i T_i c_i + T_N bg,   alpha = 1 - T_N,
//!   sem = sum_i alpha_i T_i s_i,            sem_norm = sem / (1 - T_N)  (Gaussian Semantics Eq. 2).
//! With upstream gradients `v_rgb, v_alpha, v_sem`, the pixel's objective has the partials
//!   dL/dsem = v_sem / (1 - T_N) =: g_sem,
//!   dL/dT_N = v_rgb . bg - v_alpha + v_sem . sem / (1 - T_N)^2 =: g_T,
//! so, to first order, L = sum_i alpha_i T_i f_i + g_T T_N with `f_i = v_rgb . c_i + g_sem .
//! s_i`. Only `T_j` for `j > i` and `T_N` depend on `alpha_i` (each through the factor
//! `1 - alpha_i`), hence
//!   dL/dalpha_i = T_i f_i - (sum_{j>i} alpha_j T_j f_j + g_T T_N) / (1 - alpha_i),
//! accumulated back to front. Then `alpha = min(0.999, o exp(-sigma))`.

use super::backward::PixelGrads;
use super::backward_replay::{Replay, ScreenSpace};
use super::{RenderSettings, MAX_ALPHA};
use crate::scene::Camera;

/// `dL/d` of one visible Gaussian's screen-space values, summed over the pixels it is
/// blended at.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct ScreenGrads {
    /// Pixel coordinates of the mean.
    pub mean2d: [f64; 2],
    /// The conic `(A, B, C)`, `sigma = 0.5 (A dx^2 + C dy^2) + B dx dy`.
    pub conic: [f64; 3],
    /// `sigmoid(logit)`.
    pub opacity: f64,
    /// The clamped SH color.
    pub color: [f64; 3],
    /// The blended semantic vector `s` (C values).
    pub semantic: Vec<f64>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Screen-space gradients for every entry of `screen.projected`.
pub(super) fn blend_backward(
    screen: &ScreenSpace,
    cam: &Camera,
    settings: &RenderSettings,
    upstream: &PixelGrads,
) -> Vec<ScreenGrads> {
    let channels = screen.channels;
    let mut grads = vec![
        ScreenGrads {
            semantic: vec![0.0; channels],
            ..Default::default()
        };
        screen.projected.len()
    ];
    let replay = Replay::new(screen, cam);
    replay.for_each_pixel(cam, |px, py, blended, outcome| {
        if blended.is_empty() {
            // Nothing blended: the pixel does not depend on any Gaussian.
            return;
        }
        let i = (py * cam.width + px) as usize;
        let v_rgb = upstream.rgb[i];
        let v_alpha = upstream.alpha[i];
        let v_sem = &upstream.sem_norm[i * channels..(i + 1) * channels];

        let t_final = outcome.final_t;
        let covered = 1.0 - t_final;
        let mut sem = vec![0.0; channels];
        for b in blended {
            for (acc, s) in sem.iter_mut().zip(screen.semantic_of(b.slot)) {
                *acc += b.weight * s;
            }
        }
        let g_sem: Vec<f64> = v_sem.iter().map(|v| v / covered).collect();
        let g_t_final =
            dot(&v_rgb, &settings.background) - v_alpha + dot(v_sem, &sem) / (covered * covered);

        // What the Gaussians behind the current one (and the background terms) add to L.
        let mut behind = g_t_final * t_final;
        for b in blended.iter().rev() {
            let p = &screen.projected[b.slot];
            let s = screen.semantic_of(b.slot);
            let feature = dot(&v_rgb, &p.color) + dot(&g_sem, s);
            let grad_alpha = b.t * feature - behind / (1.0 - b.alpha);
            behind += b.weight * feature;

            let g = &mut grads[b.slot];
            for (acc, v) in g.color.iter_mut().zip(v_rgb) {
                *acc += b.weight * v;
            }
            for (acc, gs) in g.semantic.iter_mut().zip(&g_sem) {
                *acc += b.weight * gs;
            }

            // The same sigma and unclamped alpha as `eval_alpha`.
            let dx = p.mean2d.x - (px as f64 + 0.5);
            let dy = p.mean2d.y - (py as f64 + 0.5);
            let [a, bb, c] = p.conic;
            let sigma = 0.5 * (a * dx * dx + c * dy * dy) + bb * dx * dy;
            let gauss = (-sigma).exp();
            if p.opacity * gauss > MAX_ALPHA {
                // alpha is the constant 0.999 here.
                continue;
            }
            g.opacity += grad_alpha * gauss;
            let grad_sigma = -grad_alpha * p.opacity * gauss;
            g.conic[0] += grad_sigma * 0.5 * dx * dx;
            g.conic[1] += grad_sigma * dx * dy;
            g.conic[2] += grad_sigma * 0.5 * dy * dy;
            // d(dx)/d(mean2d.x) = 1, d(dy)/d(mean2d.y) = 1.
            g.mean2d[0] += grad_sigma * (a * dx + bb * dy);
            g.mean2d[1] += grad_sigma * (c * dy + bb * dx);
        }
    });
    grads
}
