//! Hand-built scenes for the CPU reference tests: one `Spec` per Gaussian.

use semsplat::scene::gaussians::SemanticLogits;
use semsplat::scene::Gaussians;

#[derive(Clone)]
pub struct Spec {
    pub mean: [f32; 3],
    pub log_scale: [f32; 3],
    pub quat: [f32; 4],
    pub logit: f32,
    /// `[coeff][rgb]`; all specs of a scene must have the same count.
    pub sh: Vec<[f32; 3]>,
    pub logits: Vec<f32>,
}

/// The scene of `specs` (SH degree and channels from the first; an empty list gives an
/// empty degree-0 scene).
pub fn scene(specs: &[Spec]) -> Gaussians {
    let coeffs = specs.first().map_or(1, |s| s.sh.len());
    let channels = specs.first().map_or(0, |s| s.logits.len());
    let mut g = Gaussians {
        sh_degree: (coeffs as f64).sqrt() as u32 - 1,
        ..Default::default()
    };
    let mut logits = Vec::new();
    for s in specs {
        assert_eq!((s.sh.len(), s.logits.len()), (coeffs, channels));
        g.means.push(s.mean);
        g.log_scales.push(s.log_scale);
        g.quats.push(s.quat);
        g.opacity_logits.push(s.logit);
        g.sh.extend(s.sh.iter().flatten());
        logits.extend_from_slice(&s.logits);
    }
    if channels > 0 {
        g.semantics = Some(SemanticLogits { channels, logits });
    }
    g.check_layout().unwrap();
    g
}
