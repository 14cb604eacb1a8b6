//! Gaussians held as structure-of-arrays, the layout every kernel uploads directly.

/// Number of SH coefficients per color channel for a degree.
pub fn sh_coeffs_for_degree(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// Per-Gaussian semantic logits, row-major `[n][channels]`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SemanticLogits {
    pub channels: usize,
    pub logits: Vec<f32>,
}

/// A 3DGS scene. All vectors have `len()` entries (SH has `len() * coeffs * 3`).
///
/// Conventions (the INRIA layout, see `docs/CONVENTIONS.md`): quaternions are wxyz and
/// normalized only at use; scales are log-scales; opacity is a logit (sigmoid at use);
/// SH is stored `[n][coeff][rgb]` with coefficient 0 the DC term.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gaussians {
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    /// Rotation quaternions, w x y z.
    pub quats: Vec<[f32; 4]>,
    pub opacity_logits: Vec<f32>,
    pub sh_degree: u32,
    /// `[n][sh_coeffs_for_degree(sh_degree)][3]`.
    pub sh: Vec<f32>,
    pub semantics: Option<SemanticLogits>,
    /// Class per Gaussian as the user's label id (-1: unseen / unknown).
    pub class_ids: Option<Vec<i32>>,
    /// Confidence of `class_ids` in [0, 1].
    pub class_conf: Option<Vec<f32>>,
    /// Instance per Gaussian (-1: none).
    pub instance_ids: Option<Vec<i32>>,
}

impl Gaussians {
    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    pub fn sh_coeffs(&self) -> usize {
        sh_coeffs_for_degree(self.sh_degree)
    }
}
