//! From per-class evidence to per-Gaussian classes: semantic argmax, and FlashSplat's
//! one-vs-rest assignment with a background bias (FlashSplat's Listing 1.1, docs/papers.md).

use anyhow::Result;

use super::scores::{ClassScores, EvidenceRows};
use super::shared_counts::{count_of, SharedCounts};
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
    assign_near(a, knn)
}

/// [`assign_semantic_near`] over evidence kept per Gaussian by its nonzero counts (the same
/// classes and confidences as over the matrix they stand for).
pub fn assign_counts_near(a: &SharedCounts, knn: Option<(&[u32], usize)>) -> Assignment {
    assign_near(a, knn)
}

/// Evidence as the semantic assignment reads it, however it is stored.
trait GaussianEvidence {
    fn n(&self) -> usize;
    /// Gaussian `g`'s nonzero evidence in class order, into `row` (cleared first).
    fn nonzero(&self, g: usize, row: &mut Vec<(u32, f64)>);
    /// Gaussian `g`'s evidence for `class`.
    fn at(&self, class: usize, g: usize) -> f64;
    /// Per class, its evidence summed over the Gaussians in their order.
    fn class_totals(&self) -> Vec<f64>;
}

impl GaussianEvidence for ClassScores {
    fn n(&self) -> usize {
        self.n
    }

    fn nonzero(&self, g: usize, row: &mut Vec<(u32, f64)>) {
        row.clear();
        let at = (0..self.classes).map(|e| (e as u32, self.get(e, g)));
        row.extend(at.filter(|e| e.1 != 0.0));
    }

    fn at(&self, class: usize, g: usize) -> f64 {
        self.get(class, g)
    }

    fn class_totals(&self) -> Vec<f64> {
        (0..self.classes)
            .map(|e| self.row(e).iter().sum())
            .collect()
    }
}

impl GaussianEvidence for SharedCounts {
    fn n(&self) -> usize {
        self.len()
    }

    fn nonzero(&self, g: usize, row: &mut Vec<(u32, f64)>) {
        row.clear();
        row.extend_from_slice(self.get(g));
    }

    fn at(&self, class: usize, g: usize) -> f64 {
        count_of(self.get(g), class)
    }

    fn class_totals(&self) -> Vec<f64> {
        // The nonzero counts in Gaussian order: the zeros a row of the matrix would add
        // change no sum.
        let mut totals = vec![0.0; SharedCounts::classes(self)];
        for g in 0..self.len() {
            for &(c, x) in self.get(g) {
                totals[c as usize] += x;
            }
        }
        totals
    }
}

/// [`assign_semantic_near`] over evidence stored as `a` is. Each sum adds the nonzero
/// values in the matrix's order, so every storage gives the same bits.
fn assign_near(a: &impl GaussianEvidence, knn: Option<(&[u32], usize)>) -> Assignment {
    let scene_mass = a.class_totals();
    let mut class = vec![None; a.n()];
    let mut confidence = vec![0.0f32; a.n()];
    let mut row = Vec::new();
    for g in 0..a.n() {
        a.nonzero(g, &mut row);
        let total: f64 = row.iter().map(|e| e.1).sum();
        let top = row.iter().map(|e| e.1).fold(0.0f64, f64::max);
        if top <= 0.0 {
            continue;
        }
        let mut tied: Vec<usize> = (row.iter().filter(|e| e.1 == top))
            .map(|e| e.0 as usize)
            .collect();
        if let (Some((knn, k)), true) = (knn, tied.len() > 1) {
            tied = strongest(&tied, |e| {
                knn[g * k..(g + 1) * k]
                    .iter()
                    .filter(|&&h| h != NO_NEIGHBOUR)
                    .map(|&h| a.at(e, h as usize))
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
/// every Gaussian's [`class_totals`]. A Gaussian no view gave evidence is of no class at
/// any --gamma (the listing's test, 0 > 0 + gamma, would put it in every class at any
/// negative gamma, however small: a step at 0).
pub fn one_vs_rest_row(row: &[f64], totals: &[f64], gamma: f64) -> Vec<bool> {
    row.iter()
        .zip(totals)
        .map(|(&obj, &total)| {
            if total == 0.0 {
                return false;
            }
            let rest = total - obj;
            // F.normalize(p=1) divides by max(|rest| + |obj|, 1e-12).
            let norm = (rest.abs() + obj.abs()).max(1e-12);
            obj / norm > rest / norm + gamma
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Gaussian without evidence is of no class at any gamma; one with evidence is a
    /// member by the listing's test on either side of 0.
    #[test]
    fn no_evidence_is_no_membership_at_negative_gamma() {
        let (row, totals) = ([0.0, 0.0, 2.0, 1.0], [0.0, 3.0, 2.0, 2.0]);
        for gamma in [-1.0, -1e-12, 0.0, 1e-12] {
            let members = one_vs_rest_row(&row, &totals, gamma);
            assert!(!members[0], "gamma {gamma}");
            assert!(!members[1], "gamma {gamma}"); // 0 > 1 + gamma only below -1
            assert!(members[2], "gamma {gamma}");
            assert_eq!(members[3], gamma < 0.0, "gamma {gamma}");
        }
    }
    use crate::fuse::shared_counts::nonzero;
    use crate::util::Rng;

    /// The assignment over counts kept by their nonzero entries is the matrix's, classes and
    /// confidences, on evidence of small integers (many ties: some broken by the
    /// neighbours, some by the scene, some left undecided), with and without neighbours.
    #[test]
    fn counts_assign_as_the_matrix_they_stand_for() {
        let (classes, n, k, mut rng) = (6, 400, 3, Rng::new(7));
        let mut scores = ClassScores::zeros(classes, n);
        for x in scores.data.iter_mut() {
            *x = match rng.bool(0.6) {
                true => 0.0,
                false => rng.below(3) as f64,
            };
        }
        let mut counts = SharedCounts::zeros(classes, n);
        for g in 0..n {
            let column: Vec<f64> = (0..classes).map(|c| scores.get(c, g)).collect();
            counts.set(g, &nonzero(&column));
        }
        let knn: Vec<u32> = (0..n * k)
            .map(|_| match rng.bool(0.2) {
                true => NO_NEIGHBOUR,
                false => rng.below(n as u64) as u32,
            })
            .collect();
        let plain = assign_semantic(&scores);
        for neighbours in [None, Some((&knn[..], k))] {
            let want = assign_semantic_near(&scores, neighbours);
            assert_eq!(assign_counts_near(&counts, neighbours), want);
            let undecided = (0..n).filter(|&g| want.class[g].is_none()).count();
            let unseen = (0..n).filter(|&g| counts.get(g).is_empty()).count();
            assert!(undecided > unseen, "ties left undecided: {undecided}");
        }
        let by_neighbours = assign_semantic_near(&scores, Some((&knn, k)));
        assert_ne!(by_neighbours.class, plain.class, "neighbours break ties");
    }
}
