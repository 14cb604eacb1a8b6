//! Per-class, per-Gaussian evidence gathered over all views: vote counts, weighted votes,
//! or FlashSplat's contribution matrix A. Rows are compact classes, columns Gaussians.

use std::borrow::Cow;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

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
