//! Splat files other tools write, read into [`Gaussians`] (semsplat always writes the
//! standard INRIA PLY):
//!
//! - `.splat` (antimatter15/splat, `convert.py`): 32 bytes per splat, little-endian: position
//!   3 x f32, scale 3 x f32 (linear, not log), colour RGBA u8 (`rgb = 0.5 + SH_C0 * f_dc`,
//!   `a = sigmoid(opacity)`), rotation 4 x u8 `w x y z` as `q / |q| * 128 + 128`.
//! - `.spz` (nianticlabs/spz, layout followed from its `README.md` "File Format" and
//!   `src/cc/load-spz.cc` / `src/cc/splat-types.h`): a gzip stream of a 16-byte header
//!   (magic 0x5053474e "NGSP", version, count, SH degree, fractional bits, flags, reserved)
//!   then the attribute streams positions (24-bit signed fixed point), alphas, colours
//!   (`(c / 255 - 0.5) / 0.15`), scales (`s / 16 - 10`, log), rotations (version 2: x y z as
//!   `(v + 1) * 127.5`, w >= 0 derived; version 3: "smallest three", 2-bit index of the
//!   largest component and three 10-bit sign + magnitude values scaled by sqrt(1/2)), SH
//!   (`(v - 128) / 128`, coefficient-major with the colour inner). spz stores the RUB (OpenGL)
//!   frame; like `loadSpz` with `to = RDF` we convert to the RDF (OpenCV) frame of PLY
//!   scenes and our cameras: y and z negated, quaternion x y z multiplied by (1, -1, -1),
//!   SH coefficients by spz's `flipSh` signs. Versions 1 (float16 positions, never released)
//!   and 4+ (zstd streams) are refused by name.
//!
//! Opacity bytes 0 and 255 would give infinite logits: they are read half a quantization
//! step inside (0, 1), which renders identically at 8-bit precision.

use std::io::Read;

use anyhow::{anyhow, bail, ensure, Result};

use super::gaussians::{sh_coeffs_for_degree, Gaussians};

/// The SH degree-0 constant, as in 3DGS.
const SH_C0: f32 = 0.282_094_8;
/// Bytes per splat in a `.splat` file.
const SPLAT_RECORD: usize = 32;
/// `NGSP` read as a little-endian u32.
pub const SPZ_MAGIC: u32 = 0x5053_474e;
/// spz's DC colour scale (`colorScale` in load-spz.cc).
const SPZ_COLOR_SCALE: f32 = 0.15;
/// Largest decompressed .spz we accept (a gzip bomb must not exhaust memory).
const MAX_SPZ_BYTES: u64 = 8 << 30;

/// Logit of an 8-bit opacity, kept finite (see the module docs).
fn logit_of_u8(a: u8) -> f32 {
    let p = (a as f32 / 255.0).clamp(0.5 / 255.0, 1.0 - 0.5 / 255.0);
    (p / (1.0 - p)).ln()
}

/// Reads an antimatter15 `.splat` file's bytes.
pub fn parse_splat(bytes: &[u8]) -> Result<Gaussians> {
    ensure!(
        bytes.len().is_multiple_of(SPLAT_RECORD),
        "a .splat file holds 32-byte records, but its size {} is not a multiple of 32 \
         (truncated, or not a .splat file)",
        bytes.len()
    );
    let n = bytes.len() / SPLAT_RECORD;
    let mut g = Gaussians {
        sh_degree: 0,
        ..Default::default()
    };
    for (i, rec) in bytes.chunks_exact(SPLAT_RECORD).enumerate() {
        let f = |k: usize| f32::from_le_bytes(rec[4 * k..4 * k + 4].try_into().unwrap());
        g.means.push([f(0), f(1), f(2)]);
        let scales = [f(3), f(4), f(5)];
        if scales.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            bail!("splat {i} of {n} has a scale {scales:?} that is not positive and finite");
        }
        g.log_scales.push(scales.map(f32::ln));
        for c in 0..3 {
            g.sh.push((rec[24 + c] as f32 / 255.0 - 0.5) / SH_C0);
        }
        g.opacity_logits.push(logit_of_u8(rec[27]));
        g.quats
            .push([0, 1, 2, 3].map(|k| (rec[28 + k] as f32 - 128.0) / 128.0));
    }
    Ok(g)
}

/// spz's `FlagHasExtensions`: extension records follow the attribute streams.
const SPZ_FLAG_HAS_EXTENSIONS: u8 = 0x2;

/// The fixed header of a gzip-era .spz (versions 1..=3).
struct SpzHeader {
    version: u32,
    count: usize,
    sh_degree: u32,
    fractional_bits: u32,
    flags: u8,
}

fn parse_spz_header(b: &[u8]) -> Result<SpzHeader> {
    ensure!(
        b.len() >= 16,
        "the .spz stream ends inside its 16-byte header"
    );
    let u = |k: usize| u32::from_le_bytes(b[k..k + 4].try_into().unwrap());
    ensure!(
        u(0) == SPZ_MAGIC,
        "not an .spz stream (magic {:#010x}, expected {SPZ_MAGIC:#010x} 'NGSP')",
        u(0)
    );
    let version = u(4);
    match version {
        2 | 3 => {}
        1 => bail!(".spz version 1 (float16 positions, never released by Niantic) is not supported; re-export as version 2 or 3"),
        v => bail!(".spz version {v} is not supported (this build reads versions 2 and 3, the gzip ones)"),
    }
    let sh_degree = b[12] as u32;
    ensure!(
        sh_degree <= 3,
        ".spz SH degree {sh_degree} is not supported (0..=3)"
    );
    // spz scales positions by 1 / (1 << fractionalBits), a 32-bit shift.
    let fractional_bits = b[13] as u32;
    ensure!(
        fractional_bits < 32,
        ".spz fractional bits {fractional_bits} are not supported (0..=31)"
    );
    Ok(SpzHeader {
        version,
        count: u(8) as usize,
        sh_degree,
        fractional_bits,
        flags: b[14],
    })
}

/// The byte lengths of an `.spz` file's attribute streams: positions, alphas, colours,
/// scales, rotations, SH (the order load-spz.cc reads them).
fn spz_stream_sizes(h: &SpzHeader) -> [usize; 6] {
    let n = h.count;
    let rest = sh_coeffs_for_degree(h.sh_degree) - 1;
    let rot_bytes = if h.version >= 3 { 4 } else { 3 };
    [9 * n, n, 3 * n, 3 * n, rot_bytes * n, 3 * rest * n]
}

/// Inflates a Niantic `.spz` file's (gzip-compressed) bytes: its header, and the stream
/// (header included) holding exactly the splats it declares (or more, where extensions
/// follow).
fn inflate_spz(compressed: &[u8]) -> Result<(SpzHeader, Vec<u8>)> {
    match compressed {
        [] => bail!("the .spz file is empty"),
        // Versions 4 and later store their header uncompressed ("NGSP", then the version).
        [b'N', b'G', b'S', b'P', version, ..] => bail!(
            "an .spz file of version {version} with an uncompressed header (as splat-transform \
             2 writes) is not supported (versions 2 and 3 are): convert it to PLY first, e.g. \
             `splat-transform scene.spz scene.ply`"
        ),
        [0x1f, 0x8b, ..] => {}
        _ => bail!("not an .spz file: it starts with neither a gzip header nor \"NGSP\""),
    }
    let corrupt =
        |e: std::io::Error| anyhow!("the .spz file's gzip stream is truncated or corrupt ({e})");
    // The header first: a stream that is no .spz (or a gzip bomb) is refused before its
    // data is inflated, and no more is inflated than the header's count needs.
    let mut gz = flate2::read::GzDecoder::new(compressed);
    let mut raw = Vec::new();
    (&mut gz).take(16).read_to_end(&mut raw).map_err(corrupt)?;
    let h = parse_spz_header(&raw)?;
    let n = h.count;
    let need: usize = 16 + spz_stream_sizes(&h).iter().sum::<usize>();
    ensure!(
        need as u64 <= MAX_SPZ_BYTES,
        "the .spz header claims {n} splats ({need} bytes of data), more than the \
         {MAX_SPZ_BYTES} bytes this reader accepts"
    );
    // One byte past the splats tells a stream holding more than its count says.
    gz.take((need + 1 - raw.len()) as u64)
        .read_to_end(&mut raw)
        .map_err(corrupt)?;
    ensure!(
        raw.len() >= need,
        "the .spz data is truncated: {n} splats need {need} bytes, the stream holds {}",
        raw.len()
    );
    // Reading `n` of more splats would take the start of each attribute stream as the
    // previous one's end (alphas read from positions, ...). Extensions may follow the SH.
    ensure!(
        raw.len() == need || h.flags & SPZ_FLAG_HAS_EXTENSIONS != 0,
        "data continues past the .spz header's {n} splats (and the header announces no \
         extensions): the count is wrong, or the file holds more than it declares"
    );
    Ok((h, raw))
}

/// Reads a Niantic `.spz` file's (gzip-compressed) bytes.
pub fn parse_spz(compressed: &[u8]) -> Result<Gaussians> {
    let (h, raw) = inflate_spz(compressed)?;
    let (n, sizes) = (h.count, spz_stream_sizes(&h));
    let rest = sh_coeffs_for_degree(h.sh_degree) - 1;
    let mut at = 16;
    let mut next = |len: usize| {
        let s = &raw[at..at + len];
        at += len;
        s
    };
    let (pos, alpha, color, scale, rot, sh) = (
        next(sizes[0]),
        next(sizes[1]),
        next(sizes[2]),
        next(sizes[3]),
        next(sizes[4]),
        next(sizes[5]),
    );
    let fixed_scale = 1.0 / (1u64 << h.fractional_bits) as f32;
    let flip_p = [1.0f32, -1.0, -1.0];
    let mut g = Gaussians {
        sh_degree: h.sh_degree,
        ..Default::default()
    };
    for i in 0..n {
        g.means.push([0, 1, 2].map(|c| {
            let b = &pos[9 * i + 3 * c..9 * i + 3 * c + 3];
            // 24-bit two's complement, sign-extended through the top byte.
            let v = i32::from_le_bytes([b[0], b[1], b[2], 0]) << 8 >> 8;
            flip_p[c] * v as f32 * fixed_scale
        }));
        g.opacity_logits.push(logit_of_u8(alpha[i]));
        g.log_scales
            .push([0, 1, 2].map(|c| scale[3 * i + c] as f32 / 16.0 - 10.0));
        let xyzw = if h.version >= 3 {
            spz_quat_smallest_three(rot[4 * i..4 * i + 4].try_into().unwrap())
        } else {
            spz_quat_first_three(&rot[3 * i..3 * i + 3])
        };
        // RUB -> RDF: x y z of the quaternion times (y z, x z, x y) flips = (1, -1, -1).
        g.quats.push([xyzw[3], xyzw[0], -xyzw[1], -xyzw[2]]);
        for c in 0..3 {
            g.sh.push((color[3 * i + c] as f32 / 255.0 - 0.5) / SPZ_COLOR_SCALE);
        }
        for k in 0..rest {
            for c in 0..3 {
                let v = (sh[(i * rest + k) * 3 + c] as f32 - 128.0) / 128.0;
                g.sh.push(SPZ_RUB_TO_RDF_SH[k] * v);
            }
        }
    }
    Ok(g)
}

/// spz's `flipSh` for x = 1, y = -1, z = -1 (RUB -> RDF), per SH coefficient past DC.
const SPZ_RUB_TO_RDF_SH: [f32; 15] = [
    -1.0, -1.0, 1.0, // degree 1: y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // degree 2: xy, yz, 1, xz, 1
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0, 1.0, // degree 3: y, xyz, y, z, x, z, x
];

/// Version 2: x y z as `(v + 1) * 127.5` bytes, w = sqrt(1 - |xyz|^2) >= 0.
fn spz_quat_first_three(r: &[u8]) -> [f32; 4] {
    let xyz = [0, 1, 2].map(|k| r[k] as f32 / 127.5 - 1.0);
    let w = (1.0 - xyz.iter().map(|v| v * v).sum::<f32>())
        .max(0.0)
        .sqrt();
    [xyz[0], xyz[1], xyz[2], w]
}

/// Version 3: bits 30..31 name the largest of x y z w (stored positive); the other three,
/// last first from the low bits, are 9-bit magnitudes of |v| / sqrt(1/2) with a sign bit.
fn spz_quat_smallest_three(r: [u8; 4]) -> [f32; 4] {
    const MASK: u32 = (1 << 9) - 1;
    let mut comp = u32::from_le_bytes(r);
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i == largest {
            continue;
        }
        let mag = (comp & MASK) as f32 / MASK as f32 * std::f32::consts::FRAC_1_SQRT_2;
        let negative = (comp >> 9) & 1 == 1;
        comp >>= 10;
        q[i] = if negative { -mag } else { mag };
        sum += q[i] * q[i];
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    q
}
