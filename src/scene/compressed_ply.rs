//! SuperSplat / PlayCanvas "compressed PLY" (`*.compressed.ply`), read into [`Gaussians`].
//!
//! Layout followed from playcanvas/splat-transform `src/readers/decompress-ply.ts`: a `chunk`
//! element (one row per 256 splats) with float `min_/max_{x,y,z}`, `min_/max_scale_{x,y,z}`
//! (log-scales) and `min_/max_{r,g,b}` (colour); a `vertex` element with uint32
//! `packed_position` and `packed_scale` (11-10-11 bit unorms from the high bits, lerped
//! between the chunk's min and max), `packed_rotation` (2-bit index of the largest of
//! rot_0..rot_3, then three 10-bit unorms `(v / sqrt(2) + 0.5)` for the others in order) and
//! `packed_color` (8-8-8-8 unorms r g b from the high bits, opacity `a` in the low byte);
//! and optionally an `sh` element of uint8 `f_rest_*` with `(v + 0.5) / 256` (0 -> 0,
//! 255 -> 1) mapped to `(n - 0.5) * 8`. Colour c becomes `f_dc = (c - 0.5) / SH_C0`.
//! Opacity 0 or 1 is read half an 8-bit step inside (0, 1) so the logit is finite.

use anyhow::{bail, ensure, Result};

use super::gaussians::Gaussians;
use super::ply::{Columns, Header};

/// Splats per chunk row.
const CHUNK_SIZE: usize = 256;
const SH_C0: f64 = 0.282_094_791_773_878_14;

/// True when the header has SuperSplat's `chunk` element and packed vertex properties.
pub(crate) fn is_compressed(header: &Header) -> bool {
    let has_chunk = header.elements.iter().any(|e| e.name == "chunk");
    let packed = header
        .elements
        .iter()
        .find(|e| e.name == "vertex")
        .is_some_and(|v| v.props.iter().any(|p| p.name() == PACKED_WORDS[0]));
    has_chunk && packed
}

fn unorm(v: u32, shift: u32, bits: u32) -> f64 {
    let max = (1u32 << bits) - 1;
    ((v >> shift) & max) as f64 / max as f64
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a * (1.0 - t) + b * t
}

/// rot_0..rot_3 from a packed rotation.
fn unpack_rotation(v: u32) -> [f32; 4] {
    let norm = std::f64::consts::SQRT_2;
    let abc = [20, 10, 0].map(|shift| (unorm(v, shift, 10) - 0.5) * norm);
    let m = (1.0 - abc.iter().map(|x| x * x).sum::<f64>())
        .max(0.0)
        .sqrt();
    let largest = (v >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut others = abc.iter();
    for (i, slot) in q.iter_mut().enumerate() {
        *slot = if i == largest {
            m
        } else {
            *others.next().unwrap()
        } as f32;
    }
    q
}

fn logit(p: f64) -> f32 {
    let p = p.clamp(0.5 / 255.0, 1.0 - 0.5 / 255.0);
    (p / (1.0 - p)).ln() as f32
}

/// The vertex element's packed words, in the order `decode` reads them.
const PACKED_WORDS: [&str; 4] = [
    "packed_position",
    "packed_rotation",
    "packed_scale",
    "packed_color",
];

/// The vertex element's packed columns ([`PACKED_WORDS`]), each value checked to be a
/// word: they are uint32 bit fields, and a value that is not one (a float property holding
/// -5, 3.7 or NaN) must not be cast into some other word.
fn packed_columns(cols: &Columns) -> Result<Vec<&[f64]>> {
    let packed: Vec<&[f64]> = (PACKED_WORDS.iter())
        .map(|p| cols.get("vertex", p))
        .collect::<Result<_>>()?;
    for (name, col) in PACKED_WORDS.iter().zip(&packed) {
        if let Some(i) = col
            .iter()
            .position(|&v| !(v >= 0.0 && v <= u32::MAX as f64 && v.fract() == 0.0))
        {
            bail!(
                "vertex {i}: '{name}' value {} is not a 32-bit unsigned word",
                col[i]
            );
        }
    }
    Ok(packed)
}

/// Decodes the columns of a compressed PLY.
pub(crate) fn decode(cols: &Columns) -> Result<Gaussians> {
    let packed = packed_columns(cols)?;
    let n = packed[0].len();
    let chunk = |p: &str| cols.get("chunk", p);
    let bounds = |prefix: &str, axes: [&str; 3]| -> Result<Vec<(&[f64], &[f64])>> {
        axes.iter()
            .map(|a| {
                Ok((
                    chunk(&format!("min_{prefix}{a}"))?,
                    chunk(&format!("max_{prefix}{a}"))?,
                ))
            })
            .collect()
    };
    let pos = bounds("", ["x", "y", "z"])?;
    let scale = bounds("scale_", ["x", "y", "z"])?;
    let color = bounds("", ["r", "g", "b"]).map_err(|e| {
        e.context("older compressed PLYs without chunk colour bounds are not supported; re-export with SuperSplat or splat-transform")
    })?;
    let chunks = pos[0].0.len();
    ensure!(
        chunks * CHUNK_SIZE >= n,
        "{n} splats need {} chunk rows of {CHUNK_SIZE}, the file has {chunks}",
        n.div_ceil(CHUNK_SIZE)
    );
    let sh_rest = sh_columns(cols, n)?;
    let sh_degree = match sh_rest.len() {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        k => bail!("{k} f_rest properties in the 'sh' element do not match an SH degree"),
    };
    let per_channel = sh_rest.len() / 3;
    let mut g = Gaussians {
        sh_degree,
        ..Default::default()
    };
    for i in 0..n {
        let ci = i / CHUNK_SIZE;
        let word = |k: usize| packed[k][i] as u32;
        let lerp3 = |b: &[(&[f64], &[f64])], t: [f64; 3]| {
            [0, 1, 2].map(|a| lerp(b[a].0[ci], b[a].1[ci], t[a]) as f32)
        };
        let t111011 = |v: u32| [unorm(v, 21, 11), unorm(v, 11, 10), unorm(v, 0, 11)];
        g.means.push(lerp3(&pos, t111011(word(0))));
        g.quats.push(unpack_rotation(word(1)));
        g.log_scales.push(lerp3(&scale, t111011(word(2))));
        let c = word(3);
        let rgb = lerp3(&color, [unorm(c, 24, 8), unorm(c, 16, 8), unorm(c, 8, 8)]);
        g.sh.extend(rgb.map(|v| ((v as f64 - 0.5) / SH_C0) as f32));
        g.opacity_logits.push(logit(unorm(c, 0, 8)));
        // f_rest is channel-major on disk; memory is [coeff][rgb].
        for coeff in 0..per_channel {
            for ch in 0..3 {
                let q = sh_rest[ch * per_channel + coeff][i];
                let unit = match q as u32 {
                    0 => 0.0,
                    255 => 1.0,
                    v => (v as f64 + 0.5) / 256.0,
                };
                g.sh.push(((unit - 0.5) * 8.0) as f32);
            }
        }
    }
    Ok(g)
}

/// The `sh` element's `f_rest_0..` columns in index order (empty without one).
fn sh_columns(cols: &Columns, n: usize) -> Result<Vec<&[f64]>> {
    if !cols.elements.iter().any(|(name, _)| name == "sh") {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    while let Ok(c) = cols.get("sh", &format!("f_rest_{}", out.len())) {
        ensure!(
            c.len() == n,
            "the 'sh' element has {} rows for {n} splats",
            c.len()
        );
        out.push(c);
    }
    Ok(out)
}
