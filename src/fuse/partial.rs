//! Partial evidence of a shard of the views, kept exactly as the GPU summed it (64-bit fixed
//! point or 32-bit vote counts), with a manifest naming what it was fused from. Integer sums
//! add up in any order, so the parts of disjoint shards summed on one machine give the very
//! integers a single run over every view gives, and from them the same f64 evidence and the
//! same classes bit for bit (`semsplat fuse --shard`, `semsplat merge`, docs/sharded-fusion.md).
//!
//! On disk a part is a NumPy array [classes, Gaussians] of little-endian uint64 (fixed point,
//! units of 2^-32) or uint32 (vote counts), and `<part>.manifest.json` beside it.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use npyz::WriterBuilder;
use serde::{Deserialize, Serialize};

use super::accumulate::Accumulation;
use super::method::Method;
use crate::scene::classes::ClassTable;
use crate::scene::Camera;
use crate::util::atomic_write::write_atomic;

/// One unit of the GPU's fixed-point evidence: 2^-32.
pub const FIXED_POINT_SCALE: f64 = 1.0 / 4_294_967_296.0;

/// The f64 value of a fixed-point sum: how `fuse` and `merge` both convert (one rounding of
/// the integer to f64, then an exact scaling by a power of two).
pub fn fixed_to_f64(v: u64) -> f64 {
    v as f64 * FIXED_POINT_SCALE
}

/// What integers a method's evidence is summed in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EvidenceKind {
    /// uint64 fixed point, units of 2^-32 (FlashSplat and the weighted vote).
    FixedU64,
    /// uint32 counts (the plain and occlusion-checked votes).
    CountU32,
}

impl EvidenceKind {
    /// The kind `method` sums in with `acc`; None where it sums floats (no exact parts).
    pub fn of(method: Method, acc: Accumulation) -> Option<EvidenceKind> {
        match (method, acc) {
            (Method::Vote | Method::VoteOcclusion, _) => Some(EvidenceKind::CountU32),
            (_, Accumulation::FixedPoint) => Some(EvidenceKind::FixedU64),
            (_, Accumulation::Float) => None,
        }
    }

    pub fn bytes(self) -> usize {
        match self {
            EvidenceKind::FixedU64 => 8,
            EvidenceKind::CountU32 => 4,
        }
    }

    /// The f64 value of one entry summed in this kind (a count, or fixed point as
    /// [`fixed_to_f64`] converts it).
    pub fn widen(self, v: u64) -> f64 {
        match self {
            EvidenceKind::FixedU64 => fixed_to_f64(v),
            EvidenceKind::CountU32 => v as f64,
        }
    }
}

/// Evidence [classes][n] (or a chunk of it) as the GPU's integers.
#[derive(Clone, Debug, PartialEq)]
pub enum RawEvidence {
    Fixed(Vec<u64>),
    Counts(Vec<u32>),
}

impl RawEvidence {
    pub fn zeros(kind: EvidenceKind, len: usize) -> RawEvidence {
        match kind {
            EvidenceKind::FixedU64 => RawEvidence::Fixed(vec![0; len]),
            EvidenceKind::CountU32 => RawEvidence::Counts(vec![0; len]),
        }
    }

    pub fn kind(&self) -> EvidenceKind {
        match self {
            RawEvidence::Fixed(_) => EvidenceKind::FixedU64,
            RawEvidence::Counts(_) => EvidenceKind::CountU32,
        }
    }

    pub fn len(&self) -> usize {
        match self {
            RawEvidence::Fixed(v) => v.len(),
            RawEvidence::Counts(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Adds `other` entry by entry with the GPU atomics' wrapping arithmetic, so a merge
    /// gives exactly what one run's atomics give.
    pub fn add(&mut self, other: &RawEvidence) -> Result<()> {
        ensure!(self.len() == other.len(), "evidence lengths differ");
        match (self, other) {
            (RawEvidence::Fixed(a), RawEvidence::Fixed(b)) => a
                .iter_mut()
                .zip(b)
                .for_each(|(x, y)| *x = x.wrapping_add(*y)),
            (RawEvidence::Counts(a), RawEvidence::Counts(b)) => a
                .iter_mut()
                .zip(b)
                .for_each(|(x, y)| *x = x.wrapping_add(*y)),
            _ => bail!("cannot add fixed-point evidence to vote counts"),
        }
        Ok(())
    }

    /// The f64 evidence, converted as `fuse` converts what it downloads.
    pub fn to_f64(&self) -> Vec<f64> {
        let kind = self.kind();
        match self {
            RawEvidence::Fixed(v) => v.iter().map(|&x| kind.widen(x)).collect(),
            RawEvidence::Counts(v) => v.iter().map(|&x| kind.widen(x.into())).collect(),
        }
    }

    /// Writes [classes, len / classes] as a uint64/uint32 .npy file.
    pub fn save_npy(&self, path: &Path, classes: usize) -> Result<()> {
        let n = self.len().checked_div(classes).unwrap_or(0);
        ensure!(classes * n == self.len(), "evidence is not [classes, n]");
        let shape = [classes as u64, n as u64];
        write_atomic(path, |w| {
            match self {
                RawEvidence::Fixed(v) => write_npy_ints(w, &shape, v)?,
                RawEvidence::Counts(v) => write_npy_ints(w, &shape, v)?,
            }
            Ok(())
        })
    }
}

fn write_npy_ints<T: npyz::AutoSerialize + Copy>(
    w: &mut impl std::io::Write,
    shape: &[u64],
    data: &[T],
) -> Result<()> {
    let mut writer = npyz::WriteOptions::<T>::new()
        .default_dtype()
        .shape(shape)
        .writer(w)
        .begin_nd()?;
    writer.extend(data.iter().copied())?;
    writer.finish()?;
    Ok(())
}

/// Reads column ranges (chunks of Gaussians) of a part's .npy without loading all of it.
pub struct PartReader {
    path: PathBuf,
    file: BufReader<File>,
    data_offset: u64,
    pub classes: usize,
    pub n: usize,
    pub kind: EvidenceKind,
}

impl PartReader {
    pub fn open(path: &Path) -> Result<PartReader> {
        let mut file =
            File::open(path).with_context(|| format!("opening part {}", path.display()))?;
        let header = read_npy_header(&mut file)
            .with_context(|| format!("{} is not a partial-evidence .npy file", path.display()))?;
        let npy = npyz::NpyFile::new(&header[..])
            .with_context(|| format!("{}: unreadable .npy header", path.display()))?;
        let shape = npy.shape().to_vec();
        ensure!(
            shape.len() == 2,
            "{}: expected [classes, gaussians], got shape {shape:?}",
            path.display()
        );
        let kind = match npy.dtype() {
            npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Uint => {
                match t.size_field() {
                    8 => EvidenceKind::FixedU64,
                    4 => EvidenceKind::CountU32,
                    _ => bail!(
                        "{}: expected uint64 or uint32 data, got {}",
                        path.display(),
                        t
                    ),
                }
            }
            other => bail!(
                "{}: expected uint64 or uint32 data (a `fuse --shard` part as written), got {} \
                 (a part saved again with another dtype?)",
                path.display(),
                other.descr()
            ),
        };
        let (classes, n) = (shape[0] as usize, shape[1] as usize);
        let data_offset = header.len() as u64;
        let expected = data_offset + (classes * n * kind.bytes()) as u64;
        let actual = file.metadata()?.len();
        ensure!(
            actual == expected,
            "{}: {actual} bytes, but [{classes}, {n}] needs {expected} (truncated copy?)",
            path.display()
        );
        Ok(PartReader {
            path: path.to_owned(),
            file: BufReader::new(file),
            data_offset,
            classes,
            n,
            kind,
        })
    }

    /// Columns `begin..begin + len` of every class row, as [classes][len].
    pub fn read_columns(&mut self, begin: usize, len: usize) -> Result<RawEvidence> {
        ensure!(begin + len <= self.n, "columns past the end of the part");
        if len == 0 {
            return Ok(RawEvidence::zeros(self.kind, 0));
        }
        let width = self.kind.bytes();
        let mut bytes = vec![0u8; self.classes * len * width];
        for (row, out) in bytes.chunks_mut(len * width).enumerate() {
            let at = self.data_offset + ((row * self.n + begin) * width) as u64;
            self.file.seek(SeekFrom::Start(at))?;
            self.file
                .read_exact(out)
                .with_context(|| format!("reading {}", self.path.display()))?;
        }
        Ok(match self.kind {
            EvidenceKind::FixedU64 => RawEvidence::Fixed(
                bytes
                    .chunks_exact(8)
                    .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
                    .collect(),
            ),
            EvidenceKind::CountU32 => RawEvidence::Counts(
                bytes
                    .chunks_exact(4)
                    .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
                    .collect(),
            ),
        })
    }
}

/// The bytes of a .npy file up to its data (magic, version, header length, header).
fn read_npy_header(file: &mut File) -> Result<Vec<u8>> {
    let mut prefix = vec![0u8; 8];
    file.read_exact(&mut prefix)?;
    ensure!(&prefix[..6] == b"\x93NUMPY", "no NumPy magic");
    let len_bytes = if prefix[6] == 1 { 2 } else { 4 };
    let mut len_buf = vec![0u8; len_bytes];
    file.read_exact(&mut len_buf)?;
    let header_len = len_buf
        .iter()
        .rev()
        .fold(0usize, |acc, &b| (acc << 8) | b as usize);
    ensure!(header_len < 1 << 20, "implausible .npy header length");
    let mut header = vec![0u8; header_len];
    file.read_exact(&mut header)?;
    Ok([prefix, len_buf, header].concat())
}

/// FNV-1a, 64 bit: a fast fingerprint (not a cryptographic one) of what a part was fused
/// from, so parts of different inputs are told apart.
#[derive(Clone, Copy)]
pub struct Fnv64(u64);

impl Default for Fnv64 {
    fn default() -> Self {
        Fnv64(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv64 {
    pub fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    pub fn hex(self) -> String {
        format!("{:016x}", self.0)
    }
}

/// A file's size and FNV-1a 64 of its bytes.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileDigest {
    pub bytes: u64,
    pub fnv1a64: String,
}

impl FileDigest {
    pub fn of_file(path: &Path) -> Result<FileDigest> {
        let mut file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
        let mut hash = Fnv64::default();
        let mut buf = vec![0u8; 1 << 20];
        let mut bytes = 0u64;
        loop {
            let got = file
                .read(&mut buf)
                .with_context(|| format!("reading {}", path.display()))?;
            if got == 0 {
                break;
            }
            hash.update(&buf[..got]);
            bytes += got as u64;
        }
        Ok(FileDigest {
            bytes,
            fnv1a64: hash.hex(),
        })
    }
}

/// FNV-1a 64 of the cameras as loaded (order, names, sizes, intrinsics and poses as f64
/// bits): the same views in any camera format and at any path give the same digest.
pub fn cameras_digest(cams: &[Camera]) -> String {
    let mut hash = Fnv64::default();
    for c in cams {
        hash.update(c.name.as_bytes());
        hash.update(&[0]);
        hash.update(&c.width.to_le_bytes());
        hash.update(&c.height.to_le_bytes());
        let pose = c.rotation.to_cols_array().into_iter();
        for v in [c.fx, c.fy, c.cx, c.cy]
            .into_iter()
            .chain(pose)
            .chain(c.translation.to_array())
        {
            hash.update(&v.to_bits().to_le_bytes());
        }
    }
    hash.hex()
}

/// Shard `index` of `count`: the labeled views (in camera order) whose position modulo
/// `count` is `index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Parses "K/N" with 0 <= K < N.
    pub fn parse(s: &str) -> Result<Shard, String> {
        let err = || format!("'{s}' is not a shard K/N with 0 <= K < N (e.g. 0/4)");
        let (k, n) = s.split_once('/').ok_or_else(err)?;
        let index: usize = k.trim().parse().map_err(|_| err())?;
        let count: usize = n.trim().parse().map_err(|_| err())?;
        if count == 0 || index >= count {
            return Err(err());
        }
        Ok(Shard { index, count })
    }

    /// The items of `labeled` (views with labels, in camera order) this shard covers.
    pub fn select<T: Copy>(&self, labeled: &[T]) -> Vec<T> {
        labeled
            .iter()
            .enumerate()
            .filter(|(i, _)| i % self.count == self.index)
            .map(|(_, &v)| v)
            .collect()
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// What must be the same for parts to be merged.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FusionKey {
    /// The scene PLY's size and digest, and its Gaussian count (the evidence's columns).
    pub scene: FileDigest,
    pub gaussians: usize,
    /// Digest and count of the cameras fused from (after --train-only).
    pub cameras: String,
    pub camera_count: usize,
    /// FNV-1a 64 of the matched label files (camera name, byte size and bytes of each, in
    /// order).
    pub labels: String,
    pub label_files: usize,
    /// The class table of the evidence's rows, in row order.
    pub classes: ClassTable,
    /// `--methods` key of the method ("vote-occlusion"); it always sums in fixed point or
    /// counts (`evidence`), float atomics have no exact parts.
    pub method: String,
    /// `--depth-tol`, where the method reads it (none for plain vote and FlashSplat, so
    /// their parts merge whatever a shard was given).
    pub depth_tolerance: Option<f32>,
    pub train_only: bool,
    pub evidence: EvidenceKind,
}

/// The JSON beside a part: what it was fused from, and which views it covers.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PartManifest {
    pub format: String,
    pub version: u32,
    pub key: FusionKey,
    pub shard: Shard,
    /// Names of the cameras whose labels this part summed.
    pub views: Vec<String>,
    /// The part's own bytes: a part edited, or another shard's put in its place (same
    /// shape, other sums), is refused rather than merged into a wrong result.
    pub data: FileDigest,
}

/// `format` of every manifest.
pub const MANIFEST_FORMAT: &str = "semsplat partial evidence";
/// 3: the part's digest (`data`). 2: the label files' contents in `labels` (1: their
/// sizes), the cameras as their file holds them, `depth_tolerance` only for the methods
/// that read it.
pub const MANIFEST_VERSION: u32 = 3;

/// `<part without .npy>.manifest.json`.
pub fn manifest_path(part: &Path) -> PathBuf {
    // Only `.npy` is replaced: parts named `part.0`, `part.1` would share one manifest.
    if part.extension().is_some_and(|e| e == "npy") {
        return part.with_extension("manifest.json");
    }
    let mut name = part.file_name().unwrap_or_default().to_os_string();
    name.push(".manifest.json");
    part.with_file_name(name)
}

impl PartManifest {
    pub fn read(part: &Path) -> Result<PartManifest> {
        ensure!(
            part.is_file(),
            "part {}: no such file (the parts are what `fuse --shard K/N --out PART.npy` wrote)",
            part.display()
        );
        let path = manifest_path(part);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!(
                "part {} needs its manifest {}",
                part.display(),
                path.display()
            )
        })?;
        let m: PartManifest = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a partial-evidence manifest", path.display()))?;
        ensure!(
            m.format == MANIFEST_FORMAT && m.version == MANIFEST_VERSION,
            "{}: format '{}' version {}, expected '{MANIFEST_FORMAT}' version {MANIFEST_VERSION}",
            path.display(),
            m.format,
            m.version
        );
        Ok(m)
    }

    /// Refuses a part whose bytes are not those this manifest was written for.
    pub fn check_data(&self, part: &Path) -> Result<()> {
        let data = FileDigest::of_file(part)?;
        ensure!(
            data == self.data,
            "{} is not the part its manifest {} describes ({} bytes, FNV-1a {} vs {} bytes, \
             {}): it changed since `fuse --shard {}` wrote it, or another part's file was put \
             in its place",
            part.display(),
            manifest_path(part).display(),
            data.bytes,
            data.fnv1a64,
            self.data.bytes,
            self.data.fnv1a64,
            self.shard
        );
        Ok(())
    }

    pub fn write(&self, part: &Path) -> Result<()> {
        let json = serde_json::to_string_pretty(self)?;
        crate::util::write_bytes_atomic(&manifest_path(part), json.as_bytes())
    }
}

/// Every field in which two fusion keys differ, as "field is A vs B" (empty if none).
pub fn key_differences(a: &FusionKey, b: &FusionKey) -> Vec<String> {
    let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) =
        (serde_json::to_value(a), serde_json::to_value(b))
    else {
        return vec!["the manifests could not be compared".into()];
    };
    a.iter()
        .filter_map(|(field, va)| {
            let vb = b.get(field).cloned().unwrap_or_default();
            (*va != vb).then(|| format!("{field} is {va} vs {vb}"))
        })
        .collect()
}

/// Checks that `parts` (path, manifest) agree on what they fused and cover shards
/// 0..N-1 exactly once each; returns the common key.
pub fn check_parts(parts: &[(PathBuf, PartManifest)]) -> Result<FusionKey> {
    let Some((first_path, first)) = parts.first() else {
        bail!("no parts to merge");
    };
    for (path, m) in &parts[1..] {
        let differences = key_differences(&first.key, &m.key);
        ensure!(
            differences.is_empty(),
            "{} and {} were fused from different inputs: {}",
            first_path.display(),
            path.display(),
            differences.join("; ")
        );
        ensure!(
            m.shard.count == first.shard.count,
            "{} is shard {} but {} is shard {}: parts of different splits",
            first_path.display(),
            first.shard,
            path.display(),
            m.shard
        );
    }
    let count = first.shard.count;
    let mut owner: Vec<Option<&Path>> = vec![None; count];
    for (path, m) in parts {
        if let Some(prev) = owner[m.shard.index] {
            bail!(
                "shard {} is given twice: {} and {}",
                m.shard,
                prev.display(),
                path.display()
            );
        }
        owner[m.shard.index] = Some(path);
    }
    let missing: Vec<String> = (0..count)
        .filter(|&i| owner[i].is_none())
        .map(|i| format!("{i}/{count}"))
        .collect();
    ensure!(
        missing.is_empty(),
        "missing shard(s) {} of {count}: every shard 0/{count} to {}/{count} must be merged \
         exactly once",
        missing.join(", "),
        count - 1
    );
    check_views_once(parts, first.key.label_files)?;
    Ok(first.key.clone())
}

/// Every labeled view in exactly one part (a part copied under another shard's index
/// holds its views twice, and other views in none).
fn check_views_once(parts: &[(PathBuf, PartManifest)], labeled: usize) -> Result<()> {
    let mut part_of: std::collections::HashMap<&str, &Path> = std::collections::HashMap::new();
    for (path, m) in parts {
        for view in &m.views {
            if let Some(other) = part_of.insert(view, path) {
                bail!(
                    "view {view} is in two parts, {} and {}: a part copied, or its manifest's \
                     shard edited; fuse that shard again",
                    other.display(),
                    path.display()
                );
            }
        }
    }
    ensure!(
        part_of.len() == labeled,
        "the parts hold {} views, the labels {labeled}: fuse every shard again",
        part_of.len()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parts told apart only by an extension of their own keep their manifests apart.
    #[test]
    fn every_part_has_its_own_manifest() {
        let manifest = |p: &str| manifest_path(Path::new(p)).display().to_string();
        assert_eq!(manifest("d/part0.npy"), "d/part0.manifest.json");
        assert_eq!(manifest("d/part.0"), "d/part.0.manifest.json");
        assert_eq!(manifest("d/part.1"), "d/part.1.manifest.json");
        assert_eq!(manifest("part"), "part.manifest.json");
    }

    #[test]
    fn shard_split_is_round_robin_and_covers_every_view_once() {
        let views: Vec<usize> = (0..10).collect();
        let mut seen = [0; 10];
        for k in 0..3 {
            let shard = Shard::parse(&format!("{k}/3")).unwrap();
            for v in shard.select(&views) {
                assert_eq!(v % 3, k);
                seen[v] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        for bad in ["3/3", "1", "a/2", "0/0", "-1/2"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn adding_wraps_like_the_gpu_atomics() {
        let mut a = RawEvidence::Fixed(vec![u64::MAX, 5]);
        a.add(&RawEvidence::Fixed(vec![2, 7])).unwrap();
        assert_eq!(a, RawEvidence::Fixed(vec![1, 12]));
        assert!(a.add(&RawEvidence::Counts(vec![1, 2])).is_err());
        assert_eq!(fixed_to_f64(3 << 31), 1.5);
    }

    #[test]
    fn columns_read_back_from_npy() {
        let dir = std::env::temp_dir().join(format!("semsplat-partial-{}", std::process::id()));
        let path = dir.join("p.npy");
        let data: Vec<u64> = (0..12).map(|v| v * 1_000_000_007).collect();
        RawEvidence::Fixed(data.clone()).save_npy(&path, 3).unwrap();
        let mut r = PartReader::open(&path).unwrap();
        assert_eq!((r.classes, r.n, r.kind), (3, 4, EvidenceKind::FixedU64));
        let cols = r.read_columns(1, 2).unwrap();
        assert_eq!(
            cols,
            RawEvidence::Fixed(vec![data[1], data[2], data[5], data[6], data[9], data[10]])
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
