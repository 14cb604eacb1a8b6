//! Subsets of a scene's Gaussians (extracting or removing a class), and the scene in
//! another order.

use super::gaussians::{Gaussians, SemanticLogits};
use crate::util::gather;

impl Gaussians {
    /// The Gaussians whose `keep` flag is set, every per-Gaussian field carried along.
    pub fn select(&self, keep: &[bool]) -> Gaussians {
        assert_eq!(keep.len(), self.len(), "one flag per Gaussian");
        let kept: Vec<u32> = (0..self.len() as u32)
            .filter(|&g| keep[g as usize])
            .collect();
        self.gathered(&kept)
    }

    /// The Gaussians in the order `order` lists them (a permutation of their indices),
    /// every per-Gaussian field carried along: the same scene numbered otherwise.
    pub fn reordered(&self, order: &[u32]) -> Gaussians {
        assert_eq!(order.len(), self.len(), "one index per Gaussian");
        let mut seen = vec![false; self.len()];
        for &g in order {
            assert!(
                !std::mem::replace(&mut seen[g as usize], true),
                "Gaussian {g} twice"
            );
        }
        self.gathered(order)
    }

    /// The Gaussians at `indices`, in that order.
    fn gathered(&self, indices: &[u32]) -> Gaussians {
        let k = self.sh_coeffs() * 3;
        Gaussians {
            means: gather(&self.means, indices, 1),
            log_scales: gather(&self.log_scales, indices, 1),
            quats: gather(&self.quats, indices, 1),
            opacity_logits: gather(&self.opacity_logits, indices, 1),
            sh_degree: self.sh_degree,
            sh: gather(&self.sh, indices, k),
            semantics: self.semantics.as_ref().map(|s| SemanticLogits {
                channels: s.channels,
                logits: gather(&s.logits, indices, s.channels.max(1)),
            }),
            class_ids: self.class_ids.as_ref().map(|v| gather(v, indices, 1)),
            class_conf: self.class_conf.as_ref().map(|v| gather(v, indices, 1)),
            instance_ids: self.instance_ids.as_ref().map(|v| gather(v, indices, 1)),
            class_entropy: self.class_entropy.as_ref().map(|v| gather(v, indices, 1)),
            segment_ids: self.segment_ids.as_ref().map(|v| gather(v, indices, 1)),
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
