//! Per-class, per-Gaussian evidence gathered over all views: vote counts, weighted votes,
//! or FlashSplat's contribution matrix A. Rows are compact classes, columns Gaussians.

use std::borrow::Cow;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, ensure, Context, Result};

use crate::util::atomic_write::{folder_of, stage_scratch, StagedFile};
use crate::util::npy::{read_npy_f64, write_npy_rows, NpyArray};

#[derive(Clone, Debug, PartialEq)]
pub struct ClassScores {
    /// Rows E (compact classes).
    pub classes: usize,
    /// Columns N (Gaussians).
    pub n: usize,
    /// Row-major [E][N].
    pub data: Vec<f64>,
}

impl ClassScores {
    pub fn zeros(classes: usize, n: usize) -> ClassScores {
        ClassScores {
            classes,
            n,
            data: vec![0.0; classes * n],
        }
    }

    pub fn get(&self, class: usize, gaussian: usize) -> f64 {
        self.data[class * self.n + gaussian]
    }

    pub fn row(&self, class: usize) -> &[f64] {
        &self.data[class * self.n..(class + 1) * self.n]
    }

    /// Reads an [E, N] float64 (or float32) NumPy array, C or Fortran order
    /// ([`read_npy_f64`]).
    pub fn load_npy(path: &Path) -> Result<ClassScores> {
        let NpyArray { shape, data } = read_npy_f64(path)?;
        ensure!(
            shape.len() == 2,
            "{}: expected a 2-D array [classes, gaussians], got shape {shape:?}",
            path.display()
        );
        // An empty matrix holds no evidence, and its other dimension is unbounded by the
        // file's size: [0, 2^40] would have the totals below allocated at 8 TiB.
        ensure!(
            shape.iter().all(|&d| d > 0),
            "{}: an empty matrix (shape {shape:?}): no classes or no Gaussians",
            path.display()
        );
        ensure!(
            data.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{}: contributions must be finite and >= 0",
            path.display()
        );
        let n = shape[1] as usize;
        // A Gaussian's shares divide by its total: one past f64's range gave its class a
        // confidence of 0 and its one-vs-rest tests NaN.
        let mut totals = vec![0.0f64; n];
        for row in data.chunks(n.max(1)) {
            totals.iter_mut().zip(row).for_each(|(t, v)| *t += v);
        }
        if let Some(g) = totals.iter().position(|t| !t.is_finite()) {
            bail!(
                "{}: the contributions of Gaussian {g} sum past float64's range; scale the matrix down",
                path.display()
            );
        }
        Ok(ClassScores {
            classes: shape[0] as usize,
            n,
            data,
        })
    }
}

/// Per-Gaussian count vectors, each distinct one stored once: segment consensus decides most
/// Gaussians from their segment's vote split, so a million Gaussians share a few thousand
/// rows (a vector per Gaussian held n x classes values, and as many again in the matrix
/// built from them).
#[derive(Clone, Debug, PartialEq)]
pub struct SharedCounts {
    classes: usize,
    /// Row-major [rows][classes]; row 0 is zeros.
    counts: Vec<f64>,
    /// Per Gaussian, its row.
    row_of: Vec<u32>,
}

impl SharedCounts {
    /// `n` Gaussians over `classes` classes, each at the row of zeros.
    pub fn zeros(classes: usize, n: usize) -> SharedCounts {
        SharedCounts {
            classes,
            counts: vec![0.0; classes],
            row_of: vec![0; n],
        }
    }

    /// Adds a row of counts (`classes` long) no Gaussian holds yet; returns its index.
    pub fn add_row(&mut self, counts: &[f64]) -> u32 {
        assert_eq!(counts.len(), self.classes, "a row of counts per class");
        let row = (self.counts.len() / self.classes.max(1)) as u32;
        self.counts.extend_from_slice(counts);
        row
    }

    /// Gaussian `g` holds row `row`.
    pub fn share(&mut self, g: usize, row: u32) {
        self.row_of[g] = row;
    }

    /// Gaussian `g` holds counts of its own (all zeros: the shared row of zeros, as for
    /// a Gaussian no view observed).
    pub fn set(&mut self, g: usize, counts: &[f64]) {
        self.row_of[g] = match counts.iter().all(|&c| c == 0.0) {
            true => 0,
            false => self.add_row(counts),
        };
    }

    /// Gaussian `g`'s counts rewritten in place where it holds a row of its own (from
    /// [`SharedCounts::set`]; the caller knows no other Gaussian shares it), else stored as
    /// by `set`: rounds that decide a Gaussian again do not store a row each time.
    pub fn replace_own(&mut self, g: usize, counts: &[f64]) {
        match self.row_of[g] as usize {
            0 => self.set(g, counts),
            row => {
                self.counts[row * self.classes..(row + 1) * self.classes].copy_from_slice(counts)
            }
        }
    }

    pub fn classes(&self) -> usize {
        self.classes
    }

    /// Distinct rows stored (the row of zeros included).
    pub fn rows(&self) -> usize {
        self.counts.len() / self.classes.max(1)
    }

    /// Gaussians.
    pub fn len(&self) -> usize {
        self.row_of.len()
    }

    pub fn is_empty(&self) -> bool {
        self.row_of.is_empty()
    }

    /// Distinct row `row`'s counts (row 0: zeros).
    pub fn row(&self, row: usize) -> &[f64] {
        &self.counts[row * self.classes..(row + 1) * self.classes]
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

    /// Gaussian `g`'s counts.
    pub fn get(&self, g: usize) -> &[f64] {
        let at = self.row_of[g] as usize * self.classes;
        &self.counts[at..at + self.classes]
    }

    /// Every Gaussian's count of `class` (< `classes`), in Gaussian order.
    fn class_row(&self, class: usize) -> impl Iterator<Item = f64> + '_ {
        let classes = self.classes;
        (self.row_of.iter()).map(move |&r| self.counts[r as usize * classes + class])
    }

    /// As an evidence matrix [classes][n].
    pub fn to_scores(&self) -> ClassScores {
        let n = self.len();
        let mut scores = ClassScores::zeros(self.classes, n);
        for (c, row) in scores.data.chunks_exact_mut(n.max(1)).enumerate() {
            row.iter_mut()
                .zip(self.class_row(c))
                .for_each(|(x, v)| *x = v);
        }
        scores
    }
}

impl std::ops::Index<usize> for SharedCounts {
    type Output = [f64];

    fn index(&self, g: usize) -> &[f64] {
        self.get(g)
    }
}

/// The evidence matrix read one class row at a time, wherever it is: in memory
/// ([`ClassScores`]) or spilled to disk as it streamed from the GPU ([`SpilledRows`]).
pub trait EvidenceRows {
    /// Rows E (compact classes).
    fn classes(&self) -> usize;
    /// Columns N (Gaussians).
    fn n(&self) -> usize;
    /// Row `class`, N long.
    fn row(&mut self, class: usize) -> Result<Cow<'_, [f64]>>;

    /// Writes the rows as a float64 NumPy array [E, N], one row in memory at a time.
    fn save_npy(&mut self, path: &Path) -> Result<()> {
        let shape = [self.classes() as u64, self.n() as u64];
        write_npy_rows(path, &shape, |e| Ok(self.row(e)?.into_owned()))
    }
}

impl EvidenceRows for ClassScores {
    fn classes(&self) -> usize {
        self.classes
    }

    fn n(&self) -> usize {
        self.n
    }

    fn row(&mut self, class: usize) -> Result<Cow<'_, [f64]>> {
        Ok(Cow::Borrowed(ClassScores::row(self, class)))
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
        Ok(Cow::Owned(self.class_row(class).collect()))
    }
}

/// Evidence rows written to a scratch file beside an output as they stream from the GPU,
/// so the outputs that need the evidence itself (the saved matrix, the membership,
/// --extract) read it a row at a time and the host never holds all of it. The file is
/// removed when this drops, and by the interrupt handler.
pub struct SpilledRows {
    file: File,
    _scratch: StagedFile,
    /// The folder the scratch file is in, for a write's error (a full disk).
    folder: PathBuf,
    classes: usize,
    n: usize,
    /// Rows appended so far (they arrive in class order).
    written: usize,
}

impl SpilledRows {
    /// An empty spill for [classes][n] beside `output` (in its folder).
    pub fn beside(output: &Path, classes: usize, n: usize) -> Result<SpilledRows> {
        let (file, scratch) = stage_scratch(&output.with_extension("evidence"))?;
        Ok(SpilledRows {
            file,
            _scratch: scratch,
            folder: folder_of(output).to_path_buf(),
            classes,
            n,
            written: 0,
        })
    }

    /// Appends row `class`, which must be the next one.
    pub fn append(&mut self, class: usize, row: &[f64]) -> Result<()> {
        ensure!(
            class == self.written && row.len() == self.n,
            "evidence row {class} ({} values) out of order: expected row {} of {} values",
            row.len(),
            self.written,
            self.n
        );
        let bytes: Vec<u8> = row.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.file.write_all(&bytes).with_context(|| {
            format!(
                "spilling evidence rows to a scratch file in {} (all rows take {:.1} MiB there)",
                self.folder.display(),
                (self.classes * self.n * 8) as f64 / (1 << 20) as f64
            )
        })?;
        self.written += 1;
        Ok(())
    }
}

impl EvidenceRows for SpilledRows {
    fn classes(&self) -> usize {
        self.classes
    }

    fn n(&self) -> usize {
        self.n
    }

    fn row(&mut self, class: usize) -> Result<Cow<'_, [f64]>> {
        ensure!(
            self.written == self.classes && class < self.classes,
            "evidence row {class} read before all {} rows were spilled",
            self.classes
        );
        let row_bytes = self.n as u64 * 8;
        let mut bytes = vec![0u8; row_bytes as usize];
        self.file.seek(SeekFrom::Start(class as u64 * row_bytes))?;
        self.file
            .read_exact(&mut bytes)
            .context("reading spilled evidence rows")?;
        let row = bytes
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect();
        Ok(Cow::Owned(row))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Shared rows read back per Gaussian, as a matrix and a class row at a time, all the
    /// same as the vectors they stand for; a shared row is stored once.
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
        let segment = counts.add_row(&vectors[0]);
        counts.share(0, segment);
        counts.share(2, segment);
        counts.set(1, &vectors[1]);
        counts.set(4, &vectors[4]);
        counts.set(3, &vectors[3]); // zeros: the shared row
        assert_eq!(counts.rows(), 4);
        for (g, v) in vectors.iter().enumerate() {
            assert_eq!(&counts[g], v.as_slice());
        }
        let scores = counts.to_scores();
        for (g, v) in vectors.iter().enumerate() {
            for (c, &x) in v.iter().enumerate() {
                assert_eq!(scores.get(c, g), x);
            }
        }
        // Rewritten in place where a Gaussian holds a row of its own; the row of zeros is
        // never overwritten (Gaussian 3 gets a row instead).
        let mut rewritten = counts.clone();
        rewritten.replace_own(1, &[1.0, 1.0, 1.0]);
        assert_eq!(rewritten.rows(), 4);
        rewritten.replace_own(3, &[0.0, 0.0, 2.0]);
        assert_eq!(rewritten.rows(), 5);
        assert_eq!(&rewritten[1], &[1.0, 1.0, 1.0]);
        assert_eq!(&rewritten[3], &[0.0, 0.0, 2.0]);
        for g in [0, 2, 4] {
            assert_eq!(&rewritten[g], vectors[g].as_slice());
        }
        let mut rows = Arc::new(counts);
        for c in 0..3 {
            assert_eq!(EvidenceRows::row(&mut rows, c).unwrap(), scores.row(c));
        }
        assert!(EvidenceRows::row(&mut rows, 3).is_err());
    }
}
