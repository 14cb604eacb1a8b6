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
    /// Entropy (nats) of the class posterior `class_conf` comes from (segment consensus).
    pub class_entropy: Option<Vec<f32>>,
    /// 3D segment per Gaussian (segment consensus; -1: none).
    pub segment_ids: Option<Vec<i32>>,
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

/// One kind of bad value found in a scene, with how many Gaussians have it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ValueProblem {
    /// What is wrong, e.g. "a non-finite opacity".
    pub what: &'static str,
    /// How many Gaussians have it.
    pub count: usize,
    /// Index of the first one.
    pub first: usize,
}

impl std::fmt::Display for ValueProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let who = if self.count == 1 {
            "Gaussian has"
        } else {
            "Gaussians have"
        };
        write!(
            f,
            "{} {who} {} (first: index {})",
            self.count, self.what, self.first
        )
    }
}

impl Gaussians {
    /// Checks that every array has the length `len()` implies (SH and semantics included)
    /// and that the SH degree is 0..=3.
    pub fn check_layout(&self) -> anyhow::Result<()> {
        let n = self.len();
        if self.sh_degree > 3 {
            anyhow::bail!("SH degree {} is not supported (0..=3)", self.sh_degree);
        }
        let mut lens = vec![
            ("log_scales", self.log_scales.len(), n),
            ("quats", self.quats.len(), n),
            ("opacity_logits", self.opacity_logits.len(), n),
            ("sh", self.sh.len(), n * self.sh_coeffs() * 3),
        ];
        if let Some(s) = &self.semantics {
            lens.push(("semantics.logits", s.logits.len(), n * s.channels));
        }
        if let Some(v) = &self.class_ids {
            lens.push(("class_ids", v.len(), n));
        }
        if let Some(v) = &self.class_conf {
            lens.push(("class_conf", v.len(), n));
        }
        if let Some(v) = &self.instance_ids {
            lens.push(("instance_ids", v.len(), n));
        }
        if let Some(v) = &self.class_entropy {
            lens.push(("class_entropy", v.len(), n));
        }
        if let Some(v) = &self.segment_ids {
            lens.push(("segment_ids", v.len(), n));
        }
        for (what, got, want) in lens {
            if got != want {
                anyhow::bail!("{what} has {got} entries, expected {want} for {n} Gaussians");
            }
        }
        Ok(())
    }

    /// Bad values (NaN/Inf, zero quaternions, out-of-range classes or confidences), one entry
    /// per kind found. Assumes [`Gaussians::check_layout`] passed.
    pub fn value_problems(&self) -> Vec<ValueProblem> {
        let mut found = Vec::new();
        let mut tally = |what: &'static str, bad: &mut dyn Iterator<Item = bool>| {
            let mut count = 0;
            let mut first = 0;
            for (i, b) in bad.enumerate() {
                if b {
                    if count == 0 {
                        first = i;
                    }
                    count += 1;
                }
            }
            if count > 0 {
                found.push(ValueProblem { what, count, first });
            }
        };
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        tally(
            "a non-finite position",
            &mut self.means.iter().map(|m| !finite(m)),
        );
        tally(
            "a non-finite scale",
            &mut self.log_scales.iter().map(|s| !finite(s)),
        );
        tally(
            "a non-finite rotation quaternion",
            &mut self.quats.iter().map(|q| !finite(q)),
        );
        tally(
            "a zero rotation quaternion",
            &mut self
                .quats
                .iter()
                .map(|q| finite(q) && q.iter().all(|&c| c == 0.0)),
        );
        tally(
            "a non-finite opacity",
            &mut self.opacity_logits.iter().map(|o| !o.is_finite()),
        );
        let k3 = (self.sh_coeffs() * 3).max(1);
        tally(
            "non-finite SH coefficients",
            &mut self.sh.chunks(k3).map(|c| !finite(c)),
        );
        if let Some(s) = &self.semantics {
            let c = s.channels.max(1);
            tally(
                "non-finite semantic logits",
                &mut s.logits.chunks(c).map(|l| !finite(l)),
            );
        }
        if let Some(v) = &self.class_conf {
            tally(
                "a class confidence outside [0, 1]",
                &mut v.iter().map(|c| !(0.0..=1.0).contains(c)),
            );
        }
        if let Some(v) = &self.class_ids {
            tally("a class id below -1", &mut v.iter().map(|&c| c < -1));
        }
        if let Some(v) = &self.instance_ids {
            tally("an instance id below -1", &mut v.iter().map(|&c| c < -1));
        }
        if let Some(v) = &self.class_entropy {
            tally(
                "a negative or non-finite class entropy",
                &mut v.iter().map(|e| !(e.is_finite() && *e >= 0.0)),
            );
        }
        if let Some(v) = &self.segment_ids {
            tally("a segment id below -1", &mut v.iter().map(|&c| c < -1));
        }
        found
    }

    /// [`Gaussians::check_layout`] plus [`Gaussians::value_problems`] as one error.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.check_layout()?;
        let problems = self.value_problems();
        if !problems.is_empty() {
            let list: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
            anyhow::bail!("invalid values: {}", list.join("; "));
        }
        Ok(())
    }
}
