//! Analytic backward pass of the CPU reference renderer, in f64: the ground truth the GPU
//! backward is tested against.
//!
//! For upstream per-pixel gradients `v` ([`PixelGrads`]), the objective is
//!   L = sum_p v_rgb[p] . rgb[p] + v_alpha[p] alpha[p] + v_sem[p] . sem_norm[p]
//! and [`backward`] returns `dL/d` of every stored parameter plus the screen-space
//! intermediates ([`ParamGrads`]). It differentiates the forward exactly as computed, piece
//! by piece: clamps (alpha at 0.999, the Jacobian's x/z and y/z, the SH color at 0, the 2D
//! determinant) hold their output constant where they bind; culled, skipped and
//! non-blended (pixel, Gaussian) pairs contribute nothing.
//!
//! The stages live in `backward_*.rs`: f64 parameters ([`GaussianParams`]), an f64 twin of
//! the projection ([`project_params`]) and of compositing ([`render_screen`]), the per-pixel
//! blend backward, the projection backward and the SH backward.

pub use super::backward_params::GaussianParams;
pub use super::backward_project::project_params;
pub use super::backward_replay::{render_params, render_screen, ScreenSpace};
pub use super::backward_sh::sh_basis_grad;

use super::backward_blend::blend_backward;
use super::backward_projection::projection_backward;
use super::backward_semantics::semantic_vector_grad;
use super::{ReferenceImage, RenderSettings};
use crate::scene::{Camera, Gaussians};

/// Upstream gradients of the rendered outputs, row-major pixels like [`ReferenceImage`].
#[derive(Clone, Debug, PartialEq)]
pub struct PixelGrads {
    /// `dL/drgb` per pixel.
    pub rgb: Vec<[f64; 3]>,
    /// `dL/dalpha` per pixel (`alpha = 1 - T_final`).
    pub alpha: Vec<f64>,
    /// `dL/dsem_norm`, C per pixel, channel fastest; empty when C = 0 or semantics are off.
    pub sem_norm: Vec<f64>,
}

impl PixelGrads {
    /// All-zero gradients for `pixels` pixels and `channels` semantic channels.
    pub fn zeros(pixels: usize, channels: usize) -> PixelGrads {
        PixelGrads {
            rgb: vec![[0.0; 3]; pixels],
            alpha: vec![0.0; pixels],
            sem_norm: vec![0.0; pixels * channels],
        }
    }

    /// Panics unless these gradients fit `pixels` pixels with `channels` channels.
    fn check_shape(&self, pixels: usize, channels: usize) {
        assert_eq!(self.rgb.len(), pixels, "upstream rgb: one entry per pixel");
        assert_eq!(
            self.alpha.len(),
            pixels,
            "upstream alpha: one entry per pixel"
        );
        assert_eq!(
            self.sem_norm.len(),
            pixels * channels,
            "upstream sem_norm: {channels} channels per pixel"
        );
    }

    /// The objective `L` these gradients define, evaluated on a rendered image (summed
    /// over pixels in row-major order).
    pub fn objective(&self, img: &ReferenceImage) -> f64 {
        let channels = img.channels;
        self.check_shape(img.rgb.len(), channels);
        let mut total = 0.0;
        for p in 0..img.rgb.len() {
            let rgb: f64 = (0..3).map(|ch| self.rgb[p][ch] * img.rgb[p][ch]).sum();
            let sem: f64 = (p * channels..(p + 1) * channels)
                .map(|k| self.sem_norm[k] * img.sem_norm[k])
                .sum();
            total += rgb + self.alpha[p] * img.alpha[p] + sem;
        }
        total
    }
}

/// `dL/d` of every stored parameter (laid out like [`Gaussians`]) and of each Gaussian's
/// screen-space values (zero for Gaussians culled in this view).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParamGrads {
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    /// W.r.t. the stored, unnormalized wxyz quaternion.
    pub quats: Vec<[f64; 4]>,
    pub opacity_logits: Vec<f64>,
    /// `[n][coeff][rgb]`; zero past the evaluated SH degree.
    pub sh: Vec<f64>,
    /// `[n][C]` (through the softmax in softmax mode); zero when semantics are off, empty
    /// when the scene has none.
    pub logits: Vec<f64>,
    /// Pixel coordinates of the projected mean.
    pub mean2d: Vec<[f64; 2]>,
    /// The conic `(A, B, C)`, `sigma = 0.5 (A dx^2 + C dy^2) + B dx dy`.
    pub conic: Vec<[f64; 3]>,
    /// `sigmoid(opacity_logit)`.
    pub opacity: Vec<f64>,
    /// The clamped SH color `max(0, SH(dir) + 0.5)`.
    pub color: Vec<[f64; 3]>,
}

impl ParamGrads {
    fn zeros(params: &GaussianParams) -> ParamGrads {
        let n = params.len();
        ParamGrads {
            means: vec![[0.0; 3]; n],
            log_scales: vec![[0.0; 3]; n],
            quats: vec![[0.0; 4]; n],
            opacity_logits: vec![0.0; n],
            sh: vec![0.0; params.sh.len()],
            logits: vec![0.0; params.logits.len()],
            mean2d: vec![[0.0; 2]; n],
            conic: vec![[0.0; 3]; n],
            opacity: vec![0.0; n],
            color: vec![[0.0; 3]; n],
        }
    }
}

/// `dL/d` of the parameters of `g` for the objective defined by `upstream` (see the module
/// docs). Panics when the scene's arrays are inconsistent or `upstream` does not fit the
/// view (C = the scene's channels when `settings.semantics`, else 0).
pub fn backward(
    g: &Gaussians,
    cam: &Camera,
    settings: &RenderSettings,
    upstream: &PixelGrads,
) -> ParamGrads {
    backward_params(&GaussianParams::from_gaussians(g), cam, settings, upstream)
}

/// [`backward`] on f64 parameters.
pub fn backward_params(
    params: &GaussianParams,
    cam: &Camera,
    settings: &RenderSettings,
    upstream: &PixelGrads,
) -> ParamGrads {
    let screen = ScreenSpace::new(params, cam, settings);
    upstream.check_shape((cam.width * cam.height) as usize, screen.channels);
    let screen_grads = blend_backward(&screen, cam, settings, upstream);

    let mut out = ParamGrads::zeros(params);
    let coeffs = params.sh_coeffs();
    for (slot, (p, sg)) in screen.projected.iter().zip(&screen_grads).enumerate() {
        let i = p.id as usize;
        out.mean2d[i] = sg.mean2d;
        out.conic[i] = sg.conic;
        out.opacity[i] = sg.opacity;
        out.color[i] = sg.color;

        let stored = projection_backward(params, p, cam, settings, sg);
        out.means[i] = stored.mean;
        out.log_scales[i] = stored.log_scale;
        out.quats[i] = stored.quat;
        out.opacity_logits[i] = stored.opacity_logit;
        let sh = &mut out.sh[i * coeffs * 3..(i + 1) * coeffs * 3];
        for (dst, src) in sh.iter_mut().zip(stored.sh.iter().flatten()) {
            *dst = *src;
        }

        if screen.channels > 0 {
            let s = screen.semantic_of(slot);
            let grad = semantic_vector_grad(s, &sg.semantic, settings.semantic_mode);
            out.logits[i * screen.channels..(i + 1) * screen.channels].copy_from_slice(&grad);
        }
    }
    out
}

/// The objective `L` at f64 parameters, through the f64 twin of the forward (what the
/// finite-difference tests differentiate).
pub fn objective(
    params: &GaussianParams,
    cam: &Camera,
    settings: &RenderSettings,
    upstream: &PixelGrads,
) -> f64 {
    upstream.objective(&render_params(params, cam, settings))
}
