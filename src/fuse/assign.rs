//! From per-class evidence to per-Gaussian classes: semantic argmax, and FlashSplat's
//! one-vs-rest assignment with a background bias (FlashSplat's Listing 1.1, docs/papers.md).

use anyhow::Result;

use super::scores::{ClassScores, EvidenceRows};
use crate::contract::NO_NEIGHBOUR;

/// Class per Gaussian: compact class index, or None where no view saw the Gaussian.
#[derive(Clone, Debug, PartialEq)]
pub struct Assignment {
    pub class: Vec<Option<usize>>,
    /// The winning class's share of the Gaussian's total evidence (0 when unseen).
    pub confidence: Vec<f32>,
}

/// Semantic mode: the class with the most evidence. Ties are never broken by class index
/// (that favoured floor, wall and ceiling, the lowest ids): see [`assign_semantic_near`];
/// without neighbours, the tied class with the most evidence over the whole scene wins.
pub fn assign_semantic(a: &ClassScores) -> Assignment {
    assign_semantic_near(a, None)
}

/// Semantic mode with ties broken by neighbours: among the tied classes, the one with the
/// most evidence summed over the Gaussian's neighbours (`knn`: [n][k] rows, `NO_NEIGHBOUR` for
/// none); then the one with the most evidence over the whole scene (the scene's prior); a
/// tie that remains leaves the Gaussian undecided (None, confidence 0).
pub fn assign_semantic_near(a: &ClassScores, knn: Option<(&[u32], usize)>) -> Assignment {
    let scene_mass: Vec<f64> = (0..a.classes).map(|e| a.row(e).iter().sum()).collect();
    let mut class = vec![None; a.n];
    let mut confidence = vec![0.0f32; a.n];
    for g in 0..a.n {
        let total: f64 = (0..a.classes).map(|e| a.get(e, g)).sum();
        let top = (0..a.classes).map(|e| a.get(e, g)).fold(0.0f64, f64::max);
        if top <= 0.0 {
            continue;
        }
        let mut tied: Vec<usize> = (0..a.classes).filter(|&e| a.get(e, g) == top).collect();
        if let (Some((knn, k)), true) = (knn, tied.len() > 1) {
            tied = strongest(&tied, |e| {
                knn[g * k..(g + 1) * k]
                    .iter()
                    .filter(|&&h| h != NO_NEIGHBOUR)
                    .map(|&h| a.get(e, h as usize))
                    .sum()
            });
        }
        let prior = tied.iter().map(|&e| scene_mass[e]).fold(f64::MIN, f64::max);
        let mut winners = tied.into_iter().filter(|&e| scene_mass[e] == prior);
        if let (Some(e), None) = (winners.next(), winners.next()) {
            class[g] = Some(e);
            confidence[g] = (top / total) as f32;
        }
    }
    Assignment { class, confidence }
}

/// The classes of `among` with the largest `score`.
fn strongest(among: &[usize], score: impl Fn(usize) -> f64) -> Vec<usize> {
    let best = among.iter().map(|&e| score(e)).fold(f64::MIN, f64::max);
    among
        .iter()
        .copied()
        .filter(|&e| score(e) == best)
        .collect()
}

/// Neighbours whose evidence breaks a Gaussian's ties ([`assign_semantic_near`], and the
/// GPU's fold): `fuse`, `merge` and the experiments all use this many.
pub const TIE_NEIGHBOURS: usize = 8;

/// Listing 1.1 of FlashSplat: for each class e, the pair (rest, e) of every Gaussian is
/// L1-normalized, `gamma` is added to the rest, and the Gaussian belongs to e when e's
/// share is strictly larger (ties go to the rest, as torch.argmax picks the first).
/// Returns S [E][N]: a Gaussian may belong to several classes (multi-instance) or none.
pub fn assign_one_vs_rest(a: &ClassScores, gamma: f64) -> Vec<Vec<bool>> {
    let mut totals = vec![0.0f64; a.n];
    for e in 0..a.classes {
        add_row(&mut totals, a.row(e));
    }
    (0..a.classes)
        .map(|e| one_vs_rest_row(a.row(e), &totals, gamma))
        .collect()
}

/// Each Gaussian's evidence summed over every class (in class order), read a row at a
/// time: the denominator of [`one_vs_rest_row`].
pub fn class_totals(rows: &mut dyn EvidenceRows) -> Result<Vec<f64>> {
    let mut totals = vec![0.0f64; rows.n()];
    for e in 0..rows.classes() {
        add_row(&mut totals, &rows.row(e)?);
    }
    Ok(totals)
}

fn add_row(totals: &mut [f64], row: &[f64]) {
    for (t, v) in totals.iter_mut().zip(row) {
        *t += v;
    }
}

/// One class's row of Listing 1.1 ([`assign_one_vs_rest`]), from its evidence `row` and
/// every Gaussian's [`class_totals`].
pub fn one_vs_rest_row(row: &[f64], totals: &[f64], gamma: f64) -> Vec<bool> {
    row.iter()
        .zip(totals)
        .map(|(&obj, &total)| {
            let rest = total - obj;
            // F.normalize(p=1) divides by max(|rest| + |obj|, 1e-12).
            let norm = (rest.abs() + obj.abs()).max(1e-12);
            obj / norm > rest / norm + gamma
        })
        .collect()
}
