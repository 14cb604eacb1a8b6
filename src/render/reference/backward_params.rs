//! The stored Gaussian parameters as f64, so the reference forward can be evaluated (and
//! finite-differenced) at values a float32 [`Gaussians`] cannot hold.

use crate::scene::Gaussians;

/// A scene's differentiable parameters in f64, laid out like [`Gaussians`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianParams {
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    /// Rotation quaternions, w x y z, unnormalized (the forward normalizes).
    pub quats: Vec<[f64; 4]>,
    pub opacity_logits: Vec<f64>,
    pub sh_degree: u32,
    /// `[n][coeff][rgb]`.
    pub sh: Vec<f64>,
    /// Semantic channels C (0 when the scene has none).
    pub channels: usize,
    /// `[n][C]`.
    pub logits: Vec<f64>,
}

impl GaussianParams {
    /// Exact f64 copies of the scene's float32 parameters. Panics when the scene's arrays
    /// are inconsistent, like the reference renderer.
    pub fn from_gaussians(g: &Gaussians) -> GaussianParams {
        if let Err(e) = g.check_layout() {
            panic!("reference backward: invalid scene layout: {e}");
        }
        let (channels, logits) = match &g.semantics {
            Some(s) => (s.channels, s.logits.iter().map(|&v| f64::from(v)).collect()),
            None => (0, Vec::new()),
        };
        GaussianParams {
            means: g.means.iter().map(|v| v.map(f64::from)).collect(),
            log_scales: g.log_scales.iter().map(|v| v.map(f64::from)).collect(),
            quats: g.quats.iter().map(|v| v.map(f64::from)).collect(),
            opacity_logits: g.opacity_logits.iter().map(|&v| f64::from(v)).collect(),
            sh_degree: g.sh_degree,
            sh: g.sh.iter().map(|&v| f64::from(v)).collect(),
            channels,
            logits,
        }
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH coefficients per color channel stored for each Gaussian.
    pub fn sh_coeffs(&self) -> usize {
        ((self.sh_degree + 1) * (self.sh_degree + 1)) as usize
    }

    /// Gaussian `i`'s SH coefficients, `[coeff][rgb]`.
    pub fn sh_of(&self, i: usize) -> Vec<[f64; 3]> {
        let k = self.sh_coeffs();
        self.sh[i * k * 3..(i + 1) * k * 3]
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect()
    }

    /// Gaussian `i`'s semantic logits (empty when C = 0).
    pub fn logits_of(&self, i: usize) -> &[f64] {
        &self.logits[i * self.channels..(i + 1) * self.channels]
    }

    /// Panics unless every array has the length `len()` implies.
    pub(super) fn check_layout(&self) {
        let n = self.len();
        assert!(self.sh_degree <= 3, "SH degree {} > 3", self.sh_degree);
        assert_eq!(self.log_scales.len(), n, "log_scales length");
        assert_eq!(self.quats.len(), n, "quats length");
        assert_eq!(self.opacity_logits.len(), n, "opacity_logits length");
        assert_eq!(self.sh.len(), n * self.sh_coeffs() * 3, "sh length");
        assert_eq!(self.logits.len(), n * self.channels, "logits length");
    }
}
