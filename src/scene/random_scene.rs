//! Random Gaussian scenes for tests and benchmarks: seeded, in front of a camera at the
//! origin looking down +z, with every property drawn over a wide range.

use super::gaussians::{sh_coeffs_for_degree, Gaussians, SemanticLogits};
use crate::util::Rng;

/// What to draw.
#[derive(Clone, Debug)]
pub struct RandomSceneSpec {
    pub n: usize,
    pub sh_degree: u32,
    /// Semantic channels (0: none).
    pub channels: usize,
    /// Depth range of the means.
    pub depth: (f64, f64),
    /// Half-width of the view cone at depth 1 (means fall within |x|, |y| < spread * z).
    pub spread: f64,
    /// Range of the per-axis scales (log-uniform).
    pub scale: (f64, f64),
    /// Range of the opacity logits.
    pub opacity_logit: (f64, f64),
    pub seed: u64,
}

impl Default for RandomSceneSpec {
    fn default() -> Self {
        RandomSceneSpec {
            n: 1000,
            sh_degree: 0,
            channels: 0,
            depth: (1.0, 8.0),
            spread: 0.7,
            scale: (0.005, 0.15),
            opacity_logit: (-3.0, 4.0),
            seed: 1,
        }
    }
}

pub fn random_scene(spec: &RandomSceneSpec) -> Gaussians {
    let mut rng = Rng::new(spec.seed);
    let k = sh_coeffs_for_degree(spec.sh_degree);
    let mut g = Gaussians {
        sh_degree: spec.sh_degree,
        ..Default::default()
    };
    let (ls0, ls1) = (spec.scale.0.ln(), spec.scale.1.ln());
    for _ in 0..spec.n {
        let z = rng.range_f64(spec.depth.0, spec.depth.1);
        let x = rng.range_f64(-spec.spread, spec.spread) * z;
        let y = rng.range_f64(-spec.spread, spec.spread) * z;
        g.means.push([x as f32, y as f32, z as f32]);
        g.log_scales
            .push([0; 3].map(|_: i32| rng.range_f64(ls0, ls1) as f32));
        g.quats.push([0; 4].map(|_: i32| rng.normal() as f32));
        g.opacity_logits
            .push(rng.range_f64(spec.opacity_logit.0, spec.opacity_logit.1) as f32);
        for c in 0..k {
            // DC terms spread colors over [0, 1]; higher bands are smaller, as trained.
            let sigma = if c == 0 { 1.0 } else { 0.3 };
            for _ in 0..3 {
                g.sh.push((rng.normal() * sigma) as f32);
            }
        }
    }
    if spec.channels > 0 {
        let logits = (0..spec.n * spec.channels)
            .map(|_| (rng.normal() * 2.0) as f32)
            .collect();
        g.semantics = Some(SemanticLogits {
            channels: spec.channels,
            logits,
        });
    }
    g
}
