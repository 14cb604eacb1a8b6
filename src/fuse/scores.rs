//! Per-class, per-Gaussian evidence gathered over all views: vote counts, weighted votes,
//! or FlashSplat's contribution matrix A. Rows are compact classes, columns Gaussians.

use std::path::Path;

use anyhow::{ensure, Result};

use crate::util::npy::{read_npy_f64, write_npy_f64, NpyArray};

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

    /// Writes A as a float64 NumPy array [E, N].
    pub fn save_npy(&self, path: &Path) -> Result<()> {
        write_npy_f64(path, &[self.classes as u64, self.n as u64], &self.data)
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
        ensure!(
            data.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{}: contributions must be finite and >= 0",
            path.display()
        );
        Ok(ClassScores {
            classes: shape[0] as usize,
            n: shape[1] as usize,
            data,
        })
    }
}
