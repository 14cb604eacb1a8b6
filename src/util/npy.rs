//! NumPy arrays (.npy, little-endian float32/float64), written atomically, so results can
//! be compared with other tools.

use std::path::Path;

use anyhow::{anyhow, bail, ensure, Context, Result};
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

/// Writes a .npy file of `shape` whose first axis is filled one slice at a time by
/// `slice(i)` (each the product of the other axes long), so a large array never sits in
/// memory whole.
pub fn write_npy_rows<T: npyz::AutoSerialize + Copy, S: AsRef<[T]>>(
    path: &Path,
    shape: &[u64],
    mut slice: impl FnMut(usize) -> Result<S>,
) -> Result<()> {
    let (&rows, rest) = shape.split_first().context("npy shape has no axis")?;
    let slice_len: u64 = rest.iter().product();
    write_atomic(path, |w| {
        let mut writer = npyz::WriteOptions::<T>::new()
            .default_dtype()
            .shape(shape)
            .writer(w)
            .begin_nd()?;
        for i in 0..rows as usize {
            let values = slice(i)?;
            let values = values.as_ref();
            ensure!(
                values.len() as u64 == slice_len,
                "npy slice {i} has {} values, not {slice_len}",
                values.len()
            );
            writer.extend(values.iter().copied())?;
        }
        writer.finish()?;
        Ok(())
    })
}

/// A float array read from a .npy file, always in C (row-major) order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    pub shape: Vec<u64>,
    /// Row-major values (the last axis varies fastest), whatever order the file used.
    pub data: Vec<f64>,
}

/// Reads a float32 or float64 .npy file (either endianness). A file written in Fortran order
/// (`fortran_order: True`, e.g. `np.save(p, B.T)` or an `order='F'` array) is transposed to
/// row-major on read, so the values always mean what `shape` says. A file whose data is
/// shorter or longer than its header promises is an error naming both byte counts.
pub fn read_npy_f64(path: &Path) -> Result<NpyArray> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    parse_npy_f64(&bytes).with_context(|| format!("NumPy file {}", path.display()))
}

/// [`read_npy_f64`] from memory.
pub fn parse_npy_f64(bytes: &[u8]) -> Result<NpyArray> {
    check_npy_header(bytes)?;
    let mut data_bytes = bytes;
    let header = npyz::NpyHeader::from_reader(&mut data_bytes)
        .map_err(|e| anyhow!("not a .npy file: {e}"))?;
    let actual = data_bytes.len() as u64;
    let npy = npyz::NpyFile::with_header(header, data_bytes);
    let shape = npy.shape().to_vec();
    let order = npy.order();
    let dtype = npy.dtype();
    let item_bytes = match &dtype {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float => t.size_field(),
        other => bail!("expected float64 or float32 data, got {}", other.descr()),
    };
    ensure!(
        item_bytes == 4 || item_bytes == 8,
        "expected float64 or float32 data, got {}-byte floats",
        item_bytes
    );
    let expected = npy
        .len()
        .checked_mul(item_bytes as u64)
        .ok_or_else(|| anyhow!("shape {shape:?} is too large"))?;
    ensure!(
        actual == expected,
        "the header promises shape {shape:?} of {item_bytes}-byte floats ({expected} bytes of \
         data) but the file holds {actual} bytes of data{}",
        if actual < expected {
            " (truncated file?)"
        } else {
            ""
        }
    );
    let stored: Vec<f64> = if item_bytes == 8 {
        npy.into_vec::<f64>()?
    } else {
        npy.into_vec::<f32>()?.into_iter().map(f64::from).collect()
    };
    let data = match order {
        npyz::Order::C => stored,
        npyz::Order::Fortran => fortran_to_c_order(&shape, &stored),
    };
    Ok(NpyArray { shape, data })
}

/// Checks what npyz trusts before it parses a header: the header's length, which it
/// allocates whole (up to 4 GiB for a 12-byte file), and the shape, whose dimensions it
/// multiplies unchecked (a product past u64 panics).
fn check_npy_header(bytes: &[u8]) -> Result<()> {
    // Magic (6 bytes), version (2), then the header's length: 2 bytes in version 1, 4 in
    // versions 2 and 3. Anything else is left to npyz to name.
    let len_bytes = match bytes.get(6) {
        Some(1) => 2,
        Some(2 | 3) => 4,
        _ => return Ok(()),
    };
    let Some(len_field) = bytes.get(8..8 + len_bytes) else {
        return Ok(());
    };
    let mut le = [0u8; 4];
    le[..len_bytes].copy_from_slice(len_field);
    let header_len = u32::from_le_bytes(le) as usize;
    let rest = &bytes[8 + len_bytes..];
    ensure!(
        header_len <= rest.len(),
        "not a .npy file: its header claims {header_len} bytes but only {} follow (truncated \
         file?)",
        rest.len()
    );
    let header = String::from_utf8_lossy(&rest[..header_len]);
    let Some(dims) = header_shape(&header) else {
        return Ok(()); // no 'shape' key: npyz names it
    };
    let dims = dims.ok_or_else(|| {
        anyhow!("the header's shape is not a tuple of whole numbers (as numpy writes it)")
    })?;
    let mut nonzero = dims.iter().filter(|&&d| d != 0);
    ensure!(
        nonzero.try_fold(1u64, |p, &d| p.checked_mul(d)).is_some(),
        "shape {dims:?} is too large"
    );
    Ok(())
}

/// The dimensions of the header's `'shape': (..)` entry: None without one, Some(None) when
/// it is not a tuple or list of plain whole numbers.
fn header_shape(header: &str) -> Option<Option<Vec<u64>>> {
    let mut value = None;
    for key in ["'shape'", "\"shape\""] {
        for (at, _) in header.match_indices(key) {
            // A structured dtype's field may be named 'shape': the key is followed by ':'.
            if let Some(v) = header[at + key.len()..].trim_start().strip_prefix(':') {
                value = Some(v.trim_start());
                break;
            }
        }
        if value.is_some() {
            break;
        }
    }
    let value = value?;
    let close = match value.chars().next() {
        Some('(') => ')',
        Some('[') => ']',
        _ => return Some(None),
    };
    let Some(end) = value.find(close) else {
        return Some(None);
    };
    let dims = value[1..end]
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.bytes()
                .all(|b| b.is_ascii_digit())
                .then(|| t.parse::<u64>().ok())
                .flatten()
        })
        .collect();
    Some(dims)
}

/// Reorders values stored column-major (the first axis fastest) into row-major order.
fn fortran_to_c_order(shape: &[u64], stored: &[f64]) -> Vec<f64> {
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    // Column-major stride of each axis.
    let mut f_strides = vec![1usize; dims.len()];
    for a in 1..dims.len() {
        f_strides[a] = f_strides[a - 1] * dims[a - 1];
    }
    let mut out = Vec::with_capacity(stored.len());
    let mut index = vec![0usize; dims.len()];
    for _ in 0..stored.len() {
        let at: usize = index.iter().zip(&f_strides).map(|(i, s)| i * s).sum();
        out.push(stored[at]);
        // Advance the row-major multi-index: the last axis fastest.
        for a in (0..dims.len()).rev() {
            index[a] += 1;
            if index[a] < dims[a] {
                break;
            }
            index[a] = 0;
        }
    }
    out
}
