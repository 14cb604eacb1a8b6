//! Per-Gaussian count vectors over the classes, each distinct one stored once and by its
//! nonzero counts: segment consensus's evidence. A million Gaussians share a few thousand
//! rows (a segment's members share its split), and a Gaussian decided by its own views
//! holds counts for the few classes its views gave. Stored densely, a row per Gaussian
//! decided alone cost its `classes` values: 5,191 classes present (ids of label regions) on
//! a room of 68k Gaussians held 2.7 GB of such rows, nearly all zeros.

use std::borrow::Cow;
use std::sync::Arc;

use anyhow::{ensure, Result};

use super::scores::{ClassScores, EvidenceRows};

/// A row of counts by its nonzero entries: (class, count), in class order.
pub type SparseCounts = [(u32, f64)];

/// Count of `class` in `row` (0 where it has none).
pub fn count_of(row: &SparseCounts, class: usize) -> f64 {
    match row.binary_search_by_key(&(class as u32), |&(c, _)| c) {
        Ok(i) => row[i].1,
        Err(_) => 0.0,
    }
}

/// The nonzero counts of a row of every class, for tests that write rows out in full.
#[cfg(test)]
pub(crate) fn nonzero(counts: &[f64]) -> Vec<(u32, f64)> {
    let mut row = Vec::new();
    push_nonzero(counts, &mut row);
    row
}

/// Appends the nonzero counts of a dense row (`counts[c]` the count of class c) to `out`.
fn push_nonzero(counts: &[f64], out: &mut Vec<(u32, f64)>) {
    let nonzero = counts.iter().enumerate().filter(|&(_, &x)| x != 0.0);
    out.extend(nonzero.map(|(c, &x)| (c as u32, x)));
}

/// Rows of counts by their nonzero entries, one after another: a block of Gaussians' counts
/// built on one thread from a dense row it reuses.
#[derive(Clone, Debug, Default)]
pub struct SparseRowList {
    entries: Vec<(u32, f64)>,
    /// Where each row's entries end.
    ends: Vec<usize>,
}

impl SparseRowList {
    /// Appends a row given one count per class.
    pub fn push_dense(&mut self, counts: &[f64]) {
        push_nonzero(counts, &mut self.entries);
        self.ends.push(self.entries.len());
    }

    /// The rows, in the order pushed.
    pub fn iter(&self) -> impl Iterator<Item = &SparseCounts> {
        let starts = std::iter::once(0).chain(self.ends.iter().copied());
        (starts.zip(&self.ends)).map(|(start, &end)| &self.entries[start..end])
    }
}

/// Per Gaussian, sums by class kept by the classes added to it (a Gaussian's few), built
/// one addition at a time: `--relabel`'s FlashSplat sums over the relabeled views, never
/// a [classes][n] matrix. As a matrix they cost every class for every Gaussian: 5,191
/// classes present on a room of 68k Gaussians held 2.8 GB a copy, and the relabeling
/// four copies (103 s, 8.7 GB, most of it the kernel zeroing pages).
#[derive(Clone, Debug, PartialEq)]
pub struct SumsByGaussian<T> {
    /// Per Gaussian, (class, sum), in the order the classes were first added.
    rows: Vec<Vec<(u32, T)>>,
}

impl<T: Copy + std::ops::AddAssign> SumsByGaussian<T> {
    /// `n` Gaussians with no sums.
    pub fn new(n: usize) -> Self {
        SumsByGaussian {
            rows: vec![Vec::new(); n],
        }
    }

    /// Adds `x` to Gaussian `g`'s sum of `class`.
    pub fn add(&mut self, g: usize, class: u32, x: T) {
        let row = &mut self.rows[g];
        match row.iter_mut().find(|e| e.0 == class) {
            Some(e) => e.1 += x,
            None => row.push((class, x)),
        }
    }

    /// Adds every sum of `other` (of as many Gaussians) to this one's.
    pub fn add_all(&mut self, other: SumsByGaussian<T>) {
        assert_eq!(self.len(), other.len(), "sums of other Gaussians");
        for (g, row) in other.rows.into_iter().enumerate() {
            for (class, x) in row {
                self.add(g, class, x);
            }
        }
    }

    /// The same sums, each converted by `f`.
    pub fn map<U>(self, f: impl Fn(T) -> U) -> SumsByGaussian<U> {
        let rows = self.rows.into_iter();
        let rows = rows.map(|row| row.into_iter().map(|(c, x)| (c, f(x))).collect());
        SumsByGaussian {
            rows: rows.collect(),
        }
    }

    /// Gaussians.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Per Gaussian, its sums in class order (the Gaussians in order).
    pub fn into_sorted_rows(self) -> impl Iterator<Item = Vec<(u32, T)>> {
        self.rows.into_iter().map(|mut row| {
            row.sort_unstable_by_key(|e| e.0);
            row
        })
    }
}

#[derive(Clone, Debug)]
pub struct SharedCounts {
    classes: usize,
    /// Every row's nonzero counts; row r's are `entries[spans[r].0..spans[r].1]`. A row
    /// rewritten longer moves to the end, leaving its old entries unread.
    entries: Vec<(u32, f64)>,
    /// Per distinct row, its entries; row 0 is empty: the zeros.
    spans: Vec<(usize, usize)>,
    /// Per Gaussian, its row.
    row_of: Vec<u32>,
}

/// The same counts for every Gaussian, however they are stored.
impl PartialEq for SharedCounts {
    fn eq(&self, other: &SharedCounts) -> bool {
        self.classes == other.classes
            && self.len() == other.len()
            && (0..self.len()).all(|g| self.get(g) == other.get(g))
    }
}

impl SharedCounts {
    /// `n` Gaussians over `classes` classes, each at the row of zeros.
    pub fn zeros(classes: usize, n: usize) -> SharedCounts {
        SharedCounts {
            classes,
            entries: Vec::new(),
            spans: vec![(0, 0)],
            row_of: vec![0; n],
        }
    }

    /// Adds a row no Gaussian holds yet, given by its nonzero counts in class order;
    /// returns its index.
    pub fn add_row(&mut self, row: &SparseCounts) -> u32 {
        debug_assert!(row.windows(2).all(|w| w[0].0 < w[1].0), "in class order");
        debug_assert!(row
            .iter()
            .all(|&(c, x)| (c as usize) < self.classes && x != 0.0));
        let start = self.entries.len();
        self.entries.extend_from_slice(row);
        self.spans.push((start, self.entries.len()));
        (self.spans.len() - 1) as u32
    }

    /// Gaussian `g` holds row `row`.
    pub fn share(&mut self, g: usize, row: u32) {
        self.row_of[g] = row;
    }

    /// Gaussian `g` holds counts of its own, its nonzero ones in class order (none: the
    /// shared row of zeros, as for a Gaussian no view observed).
    pub fn set(&mut self, g: usize, row: &SparseCounts) {
        self.row_of[g] = match row.is_empty() {
            true => 0,
            false => self.add_row(row),
        };
    }

    /// Gaussian `g`'s counts (nonzero, in class order) rewritten in place where it holds a
    /// row of its own (from [`SharedCounts::set`]; the caller knows no other Gaussian shares
    /// it), else stored as by `set`: rounds that decide a Gaussian again do not store a row
    /// each time.
    pub fn replace_own(&mut self, g: usize, row: &SparseCounts) {
        let own = self.row_of[g] as usize;
        if own == 0 {
            return self.set(g, row);
        }
        let (start, end) = self.spans[own];
        if row.len() <= end - start {
            self.entries[start..start + row.len()].copy_from_slice(row);
            self.spans[own] = (start, start + row.len());
        } else {
            let moved = self.entries.len();
            self.entries.extend_from_slice(row);
            self.spans[own] = (moved, self.entries.len());
        }
    }

    pub fn classes(&self) -> usize {
        self.classes
    }

    /// Distinct rows stored (the row of zeros included).
    pub fn rows(&self) -> usize {
        self.spans.len()
    }

    /// Gaussians.
    pub fn len(&self) -> usize {
        self.row_of.len()
    }

    pub fn is_empty(&self) -> bool {
        self.row_of.is_empty()
    }

    /// Distinct row `row`'s nonzero counts (row 0: none).
    pub fn row(&self, row: usize) -> &SparseCounts {
        let (start, end) = self.spans[row];
        &self.entries[start..end]
    }

    /// The distinct row Gaussian `g` holds.
    pub fn row_index(&self, g: usize) -> usize {
        self.row_of[g] as usize
    }

    /// The counts with Gaussian `g` holding what Gaussian `held_by(g)` held (a
    /// renumbering of the Gaussians: the rows are kept as they are).
    pub fn reordered(self, held_by: impl Fn(usize) -> usize) -> SharedCounts {
        let row_of = (0..self.row_of.len())
            .map(|g| self.row_of[held_by(g)])
            .collect();
        SharedCounts { row_of, ..self }
    }

    /// Gaussian `g`'s nonzero counts, in class order.
    pub fn get(&self, g: usize) -> &SparseCounts {
        self.row(self.row_index(g))
    }

    /// Gaussian `g`'s counts, one per class.
    pub fn dense(&self, g: usize) -> Vec<f64> {
        let mut counts = vec![0.0; self.classes];
        for &(c, x) in self.get(g) {
            counts[c as usize] = x;
        }
        counts
    }

    /// Every Gaussian's count of `class` (< `classes`), in Gaussian order: looked up once
    /// per distinct row.
    fn class_row(&self, class: usize) -> Vec<f64> {
        let of_rows: Vec<f64> = (0..self.rows())
            .map(|r| count_of(self.row(r), class))
            .collect();
        (self.row_of.iter()).map(|&r| of_rows[r as usize]).collect()
    }

    /// As an evidence matrix [classes][n].
    pub fn to_scores(&self) -> ClassScores {
        let n = self.len();
        let mut scores = ClassScores::zeros(self.classes, n);
        for g in 0..n {
            for &(c, x) in self.get(g) {
                scores.data[c as usize * n + g] = x;
            }
        }
        scores
    }
}

/// Read a class row at a time, never as a whole matrix; shared with the consensus that holds
/// it (no copy).
impl EvidenceRows for Arc<SharedCounts> {
    fn classes(&self) -> usize {
        self.classes
    }

    fn n(&self) -> usize {
        self.len()
    }

    fn row(&mut self, class: usize) -> Result<Cow<'_, [f64]>> {
        ensure!(
            class < self.classes,
            "no class row {class} of {}",
            self.classes
        );
        Ok(Cow::Owned(self.class_row(class)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Shared rows read back per Gaussian, as a matrix and a class row at a time, all the
    /// same as the vectors they stand for; a shared row is stored once, and by its nonzero
    /// counts.
    #[test]
    fn shared_counts_read_back_as_the_vectors_they_hold() {
        let vectors = [
            vec![2.0, 1.0, 0.0],
            vec![0.5, 0.0, 3.0],
            vec![2.0, 1.0, 0.0],
            vec![0.0, 0.0, 0.0],
            vec![0.0, 4.0, 0.0],
        ];
        let mut counts = SharedCounts::zeros(3, vectors.len());
        let segment = counts.add_row(&nonzero(&vectors[0]));
        counts.share(0, segment);
        counts.share(2, segment);
        counts.set(1, &nonzero(&vectors[1]));
        counts.set(4, &[(1, 4.0)]);
        counts.set(3, &nonzero(&vectors[3])); // zeros: the shared row
        assert_eq!(counts.rows(), 4);
        assert_eq!(counts.entries.len(), 5, "the nonzero counts alone");
        for (g, v) in vectors.iter().enumerate() {
            assert_eq!(&counts.dense(g), v);
            for (c, &x) in v.iter().enumerate() {
                assert_eq!(count_of(counts.get(g), c), x);
            }
        }
        let scores = counts.to_scores();
        for (g, v) in vectors.iter().enumerate() {
            for (c, &x) in v.iter().enumerate() {
                assert_eq!(scores.get(c, g), x);
            }
        }
        // Rewritten in place where a Gaussian holds a row of its own (shorter, then
        // longer: moved); the row of zeros is never overwritten (Gaussian 3 gets a row
        // instead).
        let mut rewritten = counts.clone();
        rewritten.replace_own(1, &[(1, 7.0)]);
        assert_eq!(rewritten.dense(1), [0.0, 7.0, 0.0]);
        rewritten.replace_own(1, &[(0, 1.0), (1, 1.0), (2, 1.0)]);
        assert_eq!(rewritten.rows(), 4);
        rewritten.replace_own(3, &[(2, 2.0)]);
        assert_eq!(rewritten.rows(), 5);
        assert_eq!(rewritten.dense(1), [1.0, 1.0, 1.0]);
        assert_eq!(rewritten.dense(3), [0.0, 0.0, 2.0]);
        for g in [0, 2, 4] {
            assert_eq!(&rewritten.dense(g), &vectors[g]);
        }
        assert_ne!(rewritten, counts);
        rewritten.replace_own(1, &[(0, 0.5), (2, 3.0)]);
        rewritten.replace_own(3, &[]);
        assert_eq!(rewritten, counts, "the same counts, stored otherwise");
        let mut list = SparseRowList::default();
        for v in &vectors {
            list.push_dense(v);
        }
        let read: Vec<&SparseCounts> = list.iter().collect();
        assert_eq!(read.len(), vectors.len());
        for (g, row) in read.into_iter().enumerate() {
            assert_eq!(row, counts.get(g), "Gaussian {g}");
        }
        let mut rows = Arc::new(counts);
        for c in 0..3 {
            assert_eq!(EvidenceRows::row(&mut rows, c).unwrap(), scores.row(c));
        }
        assert!(EvidenceRows::row(&mut rows, 3).is_err());
    }

    /// Sums by Gaussian add up as a matrix of the same additions does, each class once per
    /// Gaussian, in class order when read; added to another, the two matrices' sums.
    #[test]
    fn sums_by_gaussian_add_as_a_matrix_does() {
        let (classes, n, mut rng) = (7, 50, crate::util::Rng::new(3));
        let mut matrices = [vec![0u64; classes * n], vec![0u64; classes * n]];
        let mut sums = [SumsByGaussian::new(n), SumsByGaussian::new(n)];
        for (matrix, sums) in matrices.iter_mut().zip(&mut sums) {
            for _ in 0..600 {
                let (g, c) = (rng.below(n as u64) as usize, rng.below(classes as u64));
                let x = 1 + rng.below(1 << 40);
                matrix[c as usize * n + g] += x;
                sums.add(g, c as u32, x);
            }
        }
        let [first, second] = sums;
        let mut both = first.clone();
        both.add_all(second);
        let rows: Vec<Vec<(u32, f64)>> = both.map(|x| x as f64).into_sorted_rows().collect();
        assert_eq!(rows.len(), n);
        for (g, row) in rows.iter().enumerate() {
            let column = (0..classes).map(|c| matrices[0][c * n + g] + matrices[1][c * n + g]);
            let column: Vec<f64> = column.map(|x| x as f64).collect();
            assert_eq!(row, &nonzero(&column), "Gaussian {g}");
        }
        let once: usize = first.into_sorted_rows().map(|row| row.len()).sum();
        let nonzero_once = (0..classes * n).filter(|&i| matrices[0][i] != 0).count();
        assert_eq!(once, nonzero_once, "a class once per Gaussian");
    }
}
