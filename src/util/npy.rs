//! NumPy arrays (.npy, little-endian float32/float64), written atomically, so results can
//! be compared with other tools.

use std::path::Path;

use anyhow::{ensure, Result};
use npyz::WriterBuilder;

use super::atomic_write::write_atomic;

/// Writes `data` (row-major, `shape`'s product long) as a float32 .npy file.
pub fn write_npy_f32(path: &Path, shape: &[u64], data: &[f32]) -> Result<()> {
    write_npy(path, shape, data)
}

/// Writes `data` (row-major, `shape`'s product long) as a float64 .npy file.
pub fn write_npy_f64(path: &Path, shape: &[u64], data: &[f64]) -> Result<()> {
    write_npy(path, shape, data)
}

fn write_npy<T: npyz::AutoSerialize + Copy>(path: &Path, shape: &[u64], data: &[T]) -> Result<()> {
    let expected: u64 = shape.iter().product();
    ensure!(
        expected == data.len() as u64,
        "npy shape {shape:?} does not match {} values",
        data.len()
    );
    write_atomic(path, |w| {
        let mut writer = npyz::WriteOptions::<T>::new()
            .default_dtype()
            .shape(shape)
            .writer(w)
            .begin_nd()?;
        writer.extend(data.iter().copied())?;
        writer.finish()?;
        Ok(())
    })
}
