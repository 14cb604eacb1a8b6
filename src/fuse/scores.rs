//! Per-class, per-Gaussian evidence gathered over all views: vote counts, weighted votes,
//! or FlashSplat's contribution matrix A. Rows are compact classes, columns Gaussians.

use std::path::Path;

use anyhow::{ensure, Context, Result};

use crate::util::npy::write_npy_f64;

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

    /// Reads an [E, N] float64 (or float32) NumPy array.
    pub fn load_npy(path: &Path) -> Result<ClassScores> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let npy = npyz::NpyFile::new(&bytes[..])
            .with_context(|| format!("{} is not a .npy file", path.display()))?;
        let shape = npy.shape().to_vec();
        ensure!(
            shape.len() == 2,
            "{}: expected a 2-D array [classes, gaussians], got shape {shape:?}",
            path.display()
        );
        let data: Vec<f64> = match npy.dtype() {
            npyz::DType::Plain(t)
                if t.type_char() == npyz::TypeChar::Float && t.size_field() == 8 =>
            {
                npy.into_vec::<f64>()?
            }
            npyz::DType::Plain(t)
                if t.type_char() == npyz::TypeChar::Float && t.size_field() == 4 =>
            {
                npy.into_vec::<f32>()?.into_iter().map(f64::from).collect()
            }
            other => anyhow::bail!(
                "{}: expected float64 or float32 data, got {other:?}",
                path.display()
            ),
        };
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
