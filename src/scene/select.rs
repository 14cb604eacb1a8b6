//! Subsets of a scene's Gaussians (extracting or removing a class).

use super::gaussians::{Gaussians, SemanticLogits};

fn pick<T: Clone>(v: &[T], keep: &[bool], stride: usize) -> Vec<T> {
    v.chunks(stride)
        .zip(keep)
        .filter(|(_, &k)| k)
        .flat_map(|(c, _)| c.iter().cloned())
        .collect()
}

impl Gaussians {
    /// The Gaussians whose `keep` flag is set, every per-Gaussian field carried along.
    pub fn select(&self, keep: &[bool]) -> Gaussians {
        assert_eq!(keep.len(), self.len(), "one flag per Gaussian");
        let k = self.sh_coeffs() * 3;
        Gaussians {
            means: pick(&self.means, keep, 1),
            log_scales: pick(&self.log_scales, keep, 1),
            quats: pick(&self.quats, keep, 1),
            opacity_logits: pick(&self.opacity_logits, keep, 1),
            sh_degree: self.sh_degree,
            sh: pick(&self.sh, keep, k),
            semantics: self.semantics.as_ref().map(|s| SemanticLogits {
                channels: s.channels,
                logits: pick(&s.logits, keep, s.channels.max(1)),
            }),
            class_ids: self.class_ids.as_ref().map(|v| pick(v, keep, 1)),
            class_conf: self.class_conf.as_ref().map(|v| pick(v, keep, 1)),
            instance_ids: self.instance_ids.as_ref().map(|v| pick(v, keep, 1)),
            class_entropy: self.class_entropy.as_ref().map(|v| pick(v, keep, 1)),
            segment_ids: self.segment_ids.as_ref().map(|v| pick(v, keep, 1)),
        }
    }

    /// A copy whose colors are flat `colors[i]` (RGB in [0, 1]): SH DC set to match, higher
    /// bands zeroed, so any 3DGS viewer shows the classes.
    pub fn with_flat_colors(&self, colors: &[[f32; 3]]) -> Gaussians {
        const SH_C0: f32 = 0.282_094_8;
        let k = self.sh_coeffs() * 3;
        let mut out = self.clone();
        for (i, c) in colors.iter().enumerate() {
            let coeffs = &mut out.sh[i * k..(i + 1) * k];
            coeffs.fill(0.0);
            for ch in 0..3 {
                coeffs[ch] = (c[ch] - 0.5) / SH_C0;
            }
        }
        out
    }
}
