//! From per-class evidence to per-Gaussian classes: semantic argmax, and FlashSplat's
//! one-vs-rest assignment with a background bias (FlashSplat's Listing 1.1, docs/papers.md).

use super::scores::ClassScores;

/// Class per Gaussian: compact class index, or None where no view saw the Gaussian.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    pub class: Vec<Option<usize>>,
    /// The winning class's share of the Gaussian's total evidence (0 when unseen).
    pub confidence: Vec<f32>,
}

/// Semantic mode: the class with the most evidence (ties: the lower class index).
pub fn assign_semantic(a: &ClassScores) -> Assignment {
    let mut class = vec![None; a.n];
    let mut confidence = vec![0.0f32; a.n];
    for g in 0..a.n {
        let mut total = 0.0;
        let mut best: Option<(usize, f64)> = None;
        for e in 0..a.classes {
            let v = a.get(e, g);
            total += v;
            if v > 0.0 && best.is_none_or(|(_, b)| v > b) {
                best = Some((e, v));
            }
        }
        if let Some((e, v)) = best {
            class[g] = Some(e);
            confidence[g] = (v / total) as f32;
        }
    }
    Assignment { class, confidence }
}

/// Listing 1.1 of FlashSplat: for each class e, the pair (rest, e) of every Gaussian is
/// L1-normalized, `gamma` is added to the rest, and the Gaussian belongs to e when e's
/// share is strictly larger (ties go to the rest, as torch.argmax picks the first).
/// Returns S [E][N]: a Gaussian may belong to several classes (multi-instance) or none.
pub fn assign_one_vs_rest(a: &ClassScores, gamma: f64) -> Vec<Vec<bool>> {
    let mut totals = vec![0.0f64; a.n];
    for e in 0..a.classes {
        for (t, v) in totals.iter_mut().zip(a.row(e)) {
            *t += v;
        }
    }
    (0..a.classes)
        .map(|e| {
            a.row(e)
                .iter()
                .zip(&totals)
                .map(|(&obj, &total)| {
                    let rest = total - obj;
                    // F.normalize(p=1) divides by max(|rest| + |obj|, 1e-12).
                    let norm = (rest.abs() + obj.abs()).max(1e-12);
                    obj / norm > rest / norm + gamma
                })
                .collect()
        })
        .collect()
}
