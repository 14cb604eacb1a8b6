//! PLY read/write in the INRIA 3DGS layout, plus semantic properties.
//!
//! Vertex properties, in the order we write them (viewers need the standard ones first):
//! `x y z nx ny nz f_dc_0..2 f_rest_0..(3*(K-1)-1) opacity scale_0..2 rot_0..3`, then the
//! optional semantic ones `class` (int), `class_conf` (float), `instance` (int),
//! `class_entropy` (float), `segment` (int), `sem_0..sem_{C-1}` (float). INRIA stores
//! `f_rest` channel-major (all red coefficients 1..K-1, then green, then blue);
//! [`Gaussians::sh`] is `[n][coeff][rgb]`.
//!
//! The reader is hand-written and streaming: it parses the header, then decodes vertex
//! records straight into the structure-of-arrays vectors, so a 5M-Gaussian scene costs the
//! scene itself plus one record buffer. It reads binary little/big-endian and ASCII, converts
//! any scalar type, and skips unknown properties.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};

use super::classes::{read_class_table, write_class_table, ClassTable};
use super::gaussians::{sh_coeffs_for_degree, Gaussians, SemanticLogits};
use super::labels::{JPEG_MAGIC, PNG_SIGNATURE};
use crate::util::write_atomic;

/// A header longer than this is not a 3DGS PLY (and must not be read into memory whole).
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Bytes of vertex records reserved up front when the data size is unknown (reading from a
/// stream): the vectors then grow with the data actually present, so a bogus count cannot
/// exhaust memory.
const STREAM_PREALLOC_BYTES: usize = 16 << 20;

/// Most `sem_*` channels we accept (a bound on the record size, not a modelling limit).
const MAX_SEM_CHANNELS: usize = 65_535;

// ---------------------------------------------------------------------------------------
// Header

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyFormat {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// Decodes one value; `b` holds exactly `size()` bytes.
    fn decode(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:literal) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big_endian {
                    <$t>::from_be_bytes(a) as f64
                } else {
                    <$t>::from_le_bytes(a) as f64
                }
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => num!(i16, 2),
            Scalar::U16 => num!(u16, 2),
            Scalar::I32 => num!(i32, 4),
            Scalar::U32 => num!(u32, 4),
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8),
        }
    }
}

#[derive(Clone, Debug)]
pub(crate) enum PropertyDef {
    Scalar { name: String, ty: Scalar },
    List { name: String },
}

impl PropertyDef {
    pub(crate) fn name(&self) -> &str {
        match self {
            PropertyDef::Scalar { name, .. } | PropertyDef::List { name } => name,
        }
    }
}

#[derive(Clone, Debug)]
pub(crate) struct ElementDef {
    pub(crate) name: String,
    pub(crate) count: u64,
    pub(crate) props: Vec<PropertyDef>,
}

#[derive(Debug)]
pub(crate) struct Header {
    pub(crate) format: PlyFormat,
    pub(crate) elements: Vec<ElementDef>,
    /// Bytes the header took, `end_header` line included.
    len: u64,
}

/// Reads header lines, counting their bytes against MAX_HEADER_BYTES.
struct HeaderLines<'a, R> {
    r: &'a mut R,
    /// Bytes read so far.
    len: usize,
    line: Vec<u8>,
}

impl<R: BufRead> HeaderLines<'_, R> {
    /// The next line without its line ending.
    fn next_line(&mut self) -> Result<String> {
        self.line.clear();
        let n = self
            .r
            .by_ref()
            .take((MAX_HEADER_BYTES - self.len) as u64 + 1)
            .read_until(b'\n', &mut self.line)?;
        self.len += n;
        if n == 0 || (self.line.last() != Some(&b'\n') && self.len <= MAX_HEADER_BYTES) {
            bail!("truncated header: the file ends before its end_header line");
        }
        if self.len > MAX_HEADER_BYTES {
            bail!("header is longer than {MAX_HEADER_BYTES} bytes");
        }
        let text =
            std::str::from_utf8(&self.line).map_err(|_| anyhow!("header is not ASCII text"))?;
        Ok(text.trim_end_matches(['\n', '\r']).to_owned())
    }
}

fn parse_header(r: &mut impl BufRead) -> Result<Header> {
    let mut lines = HeaderLines {
        r,
        len: 0,
        line: Vec::new(),
    };
    let magic = match lines.next_line() {
        Ok(magic) => magic,
        // The first line of an image: the PNG signature up to its line feed.
        Err(_) if lines.line.starts_with(&PNG_SIGNATURE[..6]) => {
            bail!("not a PLY file: a PNG image")
        }
        Err(_) if lines.line.starts_with(&JPEG_MAGIC) => bail!("not a PLY file: a JPEG image"),
        Err(e) => return Err(e),
    };
    if magic.trim() != "ply" {
        bail!("not a PLY file (first line is not 'ply')");
    }
    let mut format = None;
    let mut elements: Vec<ElementDef> = Vec::new();
    while !parse_header_line(&lines.next_line()?, &mut format, &mut elements)? {}
    let format = format.ok_or_else(|| anyhow!("header has no format line"))?;
    Ok(Header {
        format,
        elements,
        len: lines.len as u64,
    })
}

/// Applies one header line after the magic to `format` and `elements`; true at
/// `end_header`.
fn parse_header_line(
    text: &str,
    format: &mut Option<PlyFormat>,
    elements: &mut Vec<ElementDef>,
) -> Result<bool> {
    let toks: Vec<&str> = text.split_whitespace().collect();
    match toks.as_slice() {
        [] => {}
        ["comment", ..] | ["obj_info", ..] => {}
        ["format", f, _version] => {
            *format = Some(match *f {
                "ascii" => PlyFormat::Ascii,
                "binary_little_endian" => PlyFormat::BinaryLittleEndian,
                "binary_big_endian" => PlyFormat::BinaryBigEndian,
                other => bail!("unknown PLY format '{other}'"),
            })
        }
        ["element", name, count] => {
            let count = count
                .parse::<u64>()
                .map_err(|_| anyhow!("element '{name}' has an invalid count '{count}'"))?;
            elements.push(ElementDef {
                name: name.to_string(),
                count,
                props: Vec::new(),
            });
        }
        ["property", "list", _count_ty, _item_ty, name] => {
            last_element(elements)?.props.push(PropertyDef::List {
                name: name.to_string(),
            });
        }
        ["property", ty, name] => {
            let el = last_element(elements)?;
            let ty = Scalar::parse(ty)
                .ok_or_else(|| anyhow!("property '{name}' has unknown type '{ty}'"))?;
            el.props.push(PropertyDef::Scalar {
                name: name.to_string(),
                ty,
            });
        }
        ["end_header"] => return Ok(true),
        _ => bail!(
            "malformed header line '{}'",
            text.chars().take(80).collect::<String>()
        ),
    }
    Ok(false)
}

/// The element a property line belongs to.
fn last_element(elements: &mut [ElementDef]) -> Result<&mut ElementDef> {
    elements
        .last_mut()
        .ok_or_else(|| anyhow!("property before any element"))
}

// ---------------------------------------------------------------------------------------
// Mapping vertex properties to the Gaussians

/// Where one vertex property goes.
#[derive(Clone, Copy, Debug)]
enum Slot {
    Mean(usize),
    /// Offset inside this vertex's `[coeff][rgb]` SH block.
    Sh(usize),
    Opacity,
    Scale(usize),
    Rot(usize),
    Class,
    ClassConf,
    Instance,
    ClassEntropy,
    Segment,
    Sem(usize),
    Skip,
}

struct Layout {
    /// One slot and scalar type per vertex property, in file order.
    slots: Vec<(Slot, Scalar)>,
    sh_degree: u32,
    sem_channels: Option<usize>,
    has_class: bool,
    has_conf: bool,
    has_instance: bool,
    has_entropy: bool,
    has_segment: bool,
}

/// `prefix<N>` -> N.
fn indexed(name: &str, prefix: &str) -> Option<usize> {
    let rest = name.strip_prefix(prefix)?;
    if rest.is_empty()
        || !rest.bytes().all(|b| b.is_ascii_digit())
        || (rest.len() > 1 && rest.starts_with('0'))
    {
        return None;
    }
    rest.parse().ok()
}

fn plan_layout(props: &[PropertyDef]) -> Result<Layout> {
    let mut seen = std::collections::HashSet::new();
    for p in props {
        if !seen.insert(p.name()) {
            bail!("vertex property '{}' appears twice", p.name());
        }
    }
    let rest_count = props
        .iter()
        .filter(|p| indexed(p.name(), "f_rest_").is_some())
        .count();
    let sh_degree = sh_degree_of_rest_count(rest_count)?;
    let sem_count = props
        .iter()
        .filter(|p| indexed(p.name(), "sem_").is_some())
        .count();
    if sem_count > MAX_SEM_CHANNELS {
        bail!("{sem_count} sem_* properties (at most {MAX_SEM_CHANNELS})");
    }
    let counts = IndexedCounts {
        rest: rest_count,
        rest_per_channel: sh_coeffs_for_degree(sh_degree) - 1,
        sem: sem_count,
    };

    let mut slots = Vec::with_capacity(props.len());
    for p in props {
        let slot = slot_of(p.name(), &counts)?;
        let ty = match p {
            PropertyDef::Scalar { ty, .. } => *ty,
            PropertyDef::List { name } => {
                bail!("vertex property '{name}' is a list; a Gaussian PLY has only scalar vertex properties")
            }
        };
        slots.push((slot, ty));
    }

    check_required(&seen)?;
    Ok(Layout {
        slots,
        sh_degree,
        sem_channels: (sem_count > 0).then_some(sem_count),
        has_class: seen.contains("class"),
        has_conf: seen.contains("class_conf"),
        has_instance: seen.contains("instance"),
        has_entropy: seen.contains("class_entropy"),
        has_segment: seen.contains("segment"),
    })
}

/// Refuses a vertex layout without the 3DGS properties, naming what it is instead where
/// that is recognisable (a 2DGS scene, a point cloud).
fn check_required(seen: &std::collections::HashSet<&str>) -> Result<()> {
    const REQUIRED: [&str; 14] = [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ];
    let missing: Vec<&str> = REQUIRED
        .iter()
        .copied()
        .filter(|r| !seen.contains(r))
        .collect();
    if missing == ["scale_2"] {
        bail!(
            "this is a 2DGS scene (scale_0 and scale_1 but no scale_2: flat surfels); 2DGS \
             scenes are not supported, semsplat renders 3D Gaussians"
        );
    }
    if is_point_cloud(seen) {
        bail!(
            "this is a point cloud (x y z{} without Gaussian properties, e.g. an SfM \
             input.ply), not Gaussians: use a trained scene (an INRIA run's \
             point_cloud/iteration_*/point_cloud.ply, a .splat or an .spz); a point cloud can \
             only seed training (`semsplat train --init`)",
            if seen.contains("red") {
                " red green blue"
            } else {
                ""
            }
        );
    }
    if !missing.is_empty() {
        bail!(
            "missing required vertex properties: {} (a 3DGS PLY needs x y z f_dc_0..2 opacity \
             scale_0..2 rot_0..3)",
            missing.join(", ")
        );
    }
    Ok(())
}

/// A plain point cloud: positions (maybe colours and normals) but none of the Gaussian
/// properties.
pub(crate) fn is_point_cloud(seen: &std::collections::HashSet<&str>) -> bool {
    let gaussian = ["f_dc_0", "opacity", "scale_0", "rot_0"];
    ["x", "y", "z"].iter().all(|p| seen.contains(p)) && !gaussian.iter().any(|p| seen.contains(p))
}

/// The SH degree whose rest coefficients (3 channels) number `rest_count`.
fn sh_degree_of_rest_count(rest_count: usize) -> Result<u32> {
    Ok(match rest_count {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => bail!("{n} f_rest properties do not match an SH degree (expected 0, 9, 24 or 45 for degree 0..3)"),
    })
}

/// How many `f_rest_<N>` and `sem_<N>` properties the vertex has.
struct IndexedCounts {
    rest: usize,
    /// SH coefficients past the DC term, per color channel.
    rest_per_channel: usize,
    sem: usize,
}

/// Where the vertex property `name` goes.
fn slot_of(name: &str, counts: &IndexedCounts) -> Result<Slot> {
    if let Some(i) = indexed(name, "f_rest_") {
        if i >= counts.rest {
            bail!(
                "f_rest indices must run 0..{} without gaps; found f_rest_{i}",
                counts.rest - 1
            );
        }
        // Channel-major on disk: f_rest_i is channel i / (K-1), coefficient 1 + i % (K-1).
        let (channel, coeff) = (i / counts.rest_per_channel, 1 + i % counts.rest_per_channel);
        return Ok(Slot::Sh(coeff * 3 + channel));
    }
    if let Some(i) = indexed(name, "sem_") {
        if i >= counts.sem {
            bail!(
                "sem indices must run 0..{} without gaps; found sem_{i}",
                counts.sem - 1
            );
        }
        return Ok(Slot::Sem(i));
    }
    Ok(match name {
        "x" => Slot::Mean(0),
        "y" => Slot::Mean(1),
        "z" => Slot::Mean(2),
        "f_dc_0" => Slot::Sh(0),
        "f_dc_1" => Slot::Sh(1),
        "f_dc_2" => Slot::Sh(2),
        "opacity" => Slot::Opacity,
        "scale_0" => Slot::Scale(0),
        "scale_1" => Slot::Scale(1),
        "scale_2" => Slot::Scale(2),
        "rot_0" => Slot::Rot(0),
        "rot_1" => Slot::Rot(1),
        "rot_2" => Slot::Rot(2),
        "rot_3" => Slot::Rot(3),
        "class" => Slot::Class,
        "class_conf" => Slot::ClassConf,
        "instance" => Slot::Instance,
        "class_entropy" => Slot::ClassEntropy,
        "segment" => Slot::Segment,
        _ => Slot::Skip,
    })
}

// ---------------------------------------------------------------------------------------
// Reading

/// Reads a 3DGS PLY and rejects bad values (NaN/Inf, zero quaternions, ...).
pub fn read_ply(path: &Path) -> Result<Gaussians> {
    let g = read_ply_unchecked(path)?;
    g.validate()
        .with_context(|| format!("PLY {}", path.display()))?;
    Ok(g)
}

/// Reads a 3DGS PLY checking its structure but not its values (for `inspect`, which reports
/// bad values instead of stopping at them).
pub fn read_ply_unchecked(path: &Path) -> Result<Gaussians> {
    let file = File::open(path).with_context(|| format!("opening PLY {}", path.display()))?;
    let file_len = file.metadata().ok().map(|m| m.len());
    read_ply_from(BufReader::with_capacity(1 << 20, file), file_len)
        .with_context(|| format!("PLY {}", path.display()))
}

/// Reads a 3DGS PLY from any reader without checking values. `total_len` (the stream's full
/// length, when known) lets a vertex count the data cannot hold fail before allocating.
pub fn read_ply_from(mut r: impl BufRead, total_len: Option<u64>) -> Result<Gaussians> {
    let header = parse_header(&mut r)?;
    if super::compressed_ply::is_compressed(&header) {
        let columns = read_columns(&mut r, &header)?;
        return super::compressed_ply::decode(&columns);
    }
    let vi = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| anyhow!("no 'vertex' element in the header"))?;
    let layout = plan_layout(&header.elements[vi].props)?;
    for el in &header.elements[..vi] {
        skip_element(&mut r, header.format, el)?;
    }
    let vertex = &header.elements[vi];
    let count = vertex.count;
    let record_len: usize = layout.slots.iter().map(|(_, ty)| ty.size()).sum();
    let data_len = total_len.map(|t| t.saturating_sub(header.len));
    // Smallest possible encoding of one vertex: its binary record, or "0" plus a separator
    // per value in ASCII.
    let min_vertex_bytes = match header.format {
        PlyFormat::Ascii => 2 * layout.slots.len() as u64,
        _ => record_len as u64,
    };
    let fits = count
        .checked_mul(min_vertex_bytes)
        .zip(data_len)
        .map(|(need, have)| need <= have.saturating_add(1));
    let n = usize::try_from(count).map_err(|_| anyhow!("vertex count {count} is too large"))?;
    let reserve = match fits {
        Some(true) => n,
        Some(false) => bail!(
            "header claims {count} vertices but only {} bytes of data follow (truncated file?)",
            data_len.unwrap_or(0)
        ),
        None if count.checked_mul(min_vertex_bytes).is_none() => {
            bail!("vertex count {count} is too large")
        }
        None => n.min(STREAM_PREALLOC_BYTES / record_len.max(1)),
    };

    let mut g = empty_gaussians(&layout, reserve);
    let last = vi + 1 == header.elements.len();
    match header.format {
        PlyFormat::Ascii => read_ascii_vertices(&mut r, &layout, n, last, &mut g)?,
        f => {
            let big_endian = f == PlyFormat::BinaryBigEndian;
            read_binary_vertices(&mut r, &layout, record_len, n, big_endian, &mut g)?;
            if last {
                refuse_binary_trailer(&mut r, n, record_len)?;
            }
        }
    }
    Ok(g)
}

/// Every element of a binary PLY as named columns of values (for small packed layouts such
/// as SuperSplat's compressed PLY, whose data is a few integers per splat).
pub(crate) struct Columns {
    /// (element name, its properties in file order).
    pub(crate) elements: Vec<(String, Vec<NamedColumn>)>,
}

/// One property of an element: its name and one value per row.
pub(crate) type NamedColumn = (String, Vec<f64>);

impl Columns {
    /// The column `prop` of element `element`.
    pub(crate) fn get(&self, element: &str, prop: &str) -> Result<&[f64]> {
        let (_, props) = self
            .elements
            .iter()
            .find(|(name, _)| name == element)
            .ok_or_else(|| anyhow!("no '{element}' element"))?;
        props
            .iter()
            .find(|(name, _)| name == prop)
            .map(|(_, v)| v.as_slice())
            .ok_or_else(|| anyhow!("element '{element}' has no property '{prop}'"))
    }
}

fn read_columns(r: &mut impl BufRead, header: &Header) -> Result<Columns> {
    if header.format == PlyFormat::Ascii {
        return read_ascii_columns(r, header);
    }
    let big_endian = header.format == PlyFormat::BinaryBigEndian;
    let mut elements = Vec::new();
    let mut last_record_len = 0;
    for el in &header.elements {
        let types = scalar_types(el)?;
        let record_len: usize = types.iter().map(|t| t.size()).sum();
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); types.len()];
        let mut record = vec![0u8; record_len];
        // Rows without properties hold no bytes: a count of 2^64 - 1 must not loop.
        let rows = if types.is_empty() { 0 } else { el.count };
        for row in 0..rows {
            r.read_exact(&mut record).map_err(|_| {
                anyhow!(
                    "truncated file: element '{}' ends in row {row} of {}",
                    el.name,
                    el.count
                )
            })?;
            let mut at = 0;
            for (col, ty) in cols.iter_mut().zip(&types) {
                col.push(ty.decode(&record[at..at + ty.size()], big_endian));
                at += ty.size();
            }
        }
        let names = el.props.iter().map(|p| p.name().to_owned());
        elements.push((el.name.clone(), names.zip(cols).collect()));
        last_record_len = record_len;
    }
    // As for the vertices of a Gaussian PLY: a whole row more of the last element means the
    // header's counts are wrong (and every later column would be read shifted).
    let mut rest = Vec::new();
    r.take(last_record_len as u64).read_to_end(&mut rest)?;
    if last_record_len > 0 && rest.len() == last_record_len {
        bail!(
            "data continues past the header's last element (at least one more row of {} \
             bytes): the header's counts are wrong, or the file holds more than it declares",
            last_record_len
        );
    }
    Ok(Columns { elements })
}

/// The scalar types of an element's properties (list properties refused).
fn scalar_types(el: &ElementDef) -> Result<Vec<Scalar>> {
    (el.props.iter())
        .map(|p| match *p {
            PropertyDef::Scalar { ty, .. } => Ok(ty),
            PropertyDef::List { ref name } => {
                bail!("element '{}' has a list property '{name}'", el.name)
            }
        })
        .collect()
}

/// [`read_columns`] of an ASCII PLY: a row a line.
fn read_ascii_columns(r: &mut impl BufRead, header: &Header) -> Result<Columns> {
    let mut tokens = Tokens::new(r);
    let mut elements = Vec::new();
    for el in &header.elements {
        let props = scalar_types(el)?.len();
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); props];
        if props == 0 {
            // Rows without properties hold no values: a count of 2^64 - 1 must not loop.
            if el.count > 0 {
                tokens.finish_line()?;
            }
            elements.push((el.name.clone(), Vec::new()));
            continue;
        }
        for row in 0..el.count {
            for col in cols.iter_mut() {
                let v = tokens.next_value()?.ok_or_else(|| {
                    anyhow!(
                        "truncated file: element '{}' ends in row {row} of {}",
                        el.name,
                        el.count
                    )
                })?;
                col.push(v);
            }
            tokens.finish_line()?;
        }
        let names = el.props.iter().map(|p| p.name().to_owned());
        elements.push((el.name.clone(), names.zip(cols).collect()));
    }
    if tokens.next_value()?.is_some() {
        bail!(
            "data line {}: values continue past the header's last element: the header's \
             counts are wrong, or the file holds more than it declares",
            tokens.line_no
        );
    }
    Ok(Columns { elements })
}

/// Points (and colours in [0, 1], when the file has `red green blue`) of a plain point-cloud
/// PLY such as INRIA's `input.ply` (x y z, normals, uchar colours). `None` when the PLY is
/// not a point cloud (it has Gaussian properties).
pub fn read_point_cloud_ply(path: &Path) -> Result<Option<PointCloud>> {
    let file = File::open(path).with_context(|| format!("opening PLY {}", path.display()))?;
    let mut r = BufReader::new(file);
    let header = parse_header(&mut r).with_context(|| format!("PLY {}", path.display()))?;
    let Some(vertex) = header.elements.iter().find(|e| e.name == "vertex") else {
        return Ok(None);
    };
    let names: std::collections::HashSet<&str> = vertex.props.iter().map(|p| p.name()).collect();
    if !is_point_cloud(&names) {
        return Ok(None);
    }
    // uchar colours are 0..255; float ones 0..1.
    let colour_scale = match vertex.props.iter().find(|p| p.name() == "red") {
        Some(PropertyDef::Scalar {
            ty: Scalar::F32 | Scalar::F64,
            ..
        }) => 1.0,
        Some(PropertyDef::Scalar {
            ty: Scalar::U16, ..
        }) => 1.0 / 65535.0,
        _ => 1.0 / 255.0,
    };
    let cols = read_columns(&mut r, &header).with_context(|| format!("PLY {}", path.display()))?;
    let xyz = ["x", "y", "z"].map(|a| cols.get("vertex", a));
    let [x, y, z] = [&xyz[0], &xyz[1], &xyz[2]].map(|c| c.as_ref().map_err(|e| anyhow!("{e}")));
    let (x, y, z) = (x?, y?, z?);
    let points = (0..x.len())
        .map(|i| [x[i] as f32, y[i] as f32, z[i] as f32])
        .collect();
    let colours = match ["red", "green", "blue"].map(|c| cols.get("vertex", c).ok()) {
        [Some(r), Some(g), Some(b)] => Some(
            (0..r.len())
                .map(|i| [r[i], g[i], b[i]].map(|v| (v * colour_scale) as f32))
                .collect(),
        ),
        _ => None,
    };
    Ok(Some(PointCloud { points, colours }))
}

/// A plain point cloud read from a PLY.
pub struct PointCloud {
    pub points: Vec<[f32; 3]>,
    /// RGB in [0, 1] per point, when the file has colours.
    pub colours: Option<Vec<[f32; 3]>>,
}

/// Empty Gaussians shaped by the layout, with room for `reserve` vertices.
fn empty_gaussians(layout: &Layout, reserve: usize) -> Gaussians {
    let k = sh_coeffs_for_degree(layout.sh_degree);
    Gaussians {
        means: Vec::with_capacity(reserve),
        log_scales: Vec::with_capacity(reserve),
        quats: Vec::with_capacity(reserve),
        opacity_logits: Vec::with_capacity(reserve),
        sh_degree: layout.sh_degree,
        sh: Vec::with_capacity(reserve * k * 3),
        semantics: layout.sem_channels.map(|c| SemanticLogits {
            channels: c,
            logits: Vec::with_capacity(reserve * c),
        }),
        class_ids: layout.has_class.then(|| Vec::with_capacity(reserve)),
        class_conf: layout.has_conf.then(|| Vec::with_capacity(reserve)),
        instance_ids: layout.has_instance.then(|| Vec::with_capacity(reserve)),
        class_entropy: layout.has_entropy.then(|| Vec::with_capacity(reserve)),
        segment_ids: layout.has_segment.then(|| Vec::with_capacity(reserve)),
    }
}

fn skip_element(r: &mut impl BufRead, format: PlyFormat, el: &ElementDef) -> Result<()> {
    let mut scalar_bytes = 0u64;
    for p in &el.props {
        match p {
            PropertyDef::Scalar { ty, .. } => scalar_bytes += ty.size() as u64,
            PropertyDef::List { name } => bail!(
                "element '{}' before 'vertex' has a list property '{name}'; put the vertex element first",
                el.name
            ),
        }
    }
    let truncated = || {
        anyhow!(
            "truncated file (in element '{}' before the vertices)",
            el.name
        )
    };
    match format {
        PlyFormat::Ascii => {
            let values = el
                .count
                .checked_mul(el.props.len() as u64)
                .ok_or_else(truncated)?;
            let mut tokens = Tokens::new(r);
            for _ in 0..values {
                tokens.next_value()?.ok_or_else(truncated)?;
            }
            tokens.finish_line()
        }
        _ => {
            let bytes = el.count.checked_mul(scalar_bytes).ok_or_else(truncated)?;
            let copied = std::io::copy(&mut r.by_ref().take(bytes), &mut std::io::sink())?;
            if copied != bytes {
                return Err(truncated());
            }
            Ok(())
        }
    }
}

/// The values of one vertex before they are pushed (semantic logits go straight in).
struct VertexValues {
    mean: [f32; 3],
    scale: [f32; 3],
    rot: [f32; 4],
    opacity: f32,
    class: i32,
    conf: f32,
    instance: i32,
    entropy: f32,
    segment: i32,
}

impl VertexValues {
    fn new() -> Self {
        VertexValues {
            mean: [0.0; 3],
            scale: [0.0; 3],
            rot: [0.0; 4],
            opacity: 0.0,
            class: -1,
            conf: 0.0,
            instance: -1,
            entropy: 0.0,
            segment: -1,
        }
    }
}

/// `-1` (unseen / none) as it comes back from tools that read `class` and `instance` as
/// unsigned 32-bit (PlayCanvas splat-transform rewrites our `int` as `uint`): 2^32 - 1.
const UNSEEN_AS_U32: f64 = u32::MAX as f64;

/// An id property as a 32-bit signed integer. 4294967295 is taken as -1 (see
/// [`UNSEEN_AS_U32`]): no real class or instance id comes near it, and a file that went
/// through an unsigned reader must still load. Other values above i32::MAX are refused.
fn to_i32(v: f64, what: &str, vertex: usize) -> Result<i32> {
    if v == UNSEEN_AS_U32 {
        return Ok(-1);
    }
    if v.fract() != 0.0 || v < i32::MIN as f64 || v > i32::MAX as f64 {
        bail!("vertex {vertex}: '{what}' value {v} is not a 32-bit integer");
    }
    Ok(v as i32)
}

/// A `class` stored as an unsigned 8- or 16-bit property: its type's largest value is how
/// -1 (unseen) comes back from a tool that narrowed our `int` classes, as 2^32 - 1 is for
/// 32 bits; 255 is also the 8-bit label maps' "no label". (Instance and segment ids keep
/// their values: other tools number those past 255.)
fn unsigned_minus_one(ty: Scalar, v: f64) -> f64 {
    let largest = match ty {
        Scalar::U8 => f64::from(u8::MAX),
        Scalar::U16 => f64::from(u16::MAX),
        _ => return v,
    };
    if v == largest {
        -1.0
    } else {
        v
    }
}

/// Puts one decoded value of type `ty` where its slot says. `sh` and `sem` are this
/// vertex's blocks.
#[inline]
fn store(
    (slot, ty): (Slot, Scalar),
    v: f64,
    vals: &mut VertexValues,
    sh: &mut [f32],
    sem: &mut [f32],
    vertex: usize,
) -> Result<()> {
    match slot {
        Slot::Mean(i) => vals.mean[i] = v as f32,
        Slot::Sh(i) => sh[i] = v as f32,
        Slot::Opacity => vals.opacity = v as f32,
        Slot::Scale(i) => vals.scale[i] = v as f32,
        Slot::Rot(i) => vals.rot[i] = v as f32,
        Slot::Class => vals.class = to_i32(unsigned_minus_one(ty, v), "class", vertex)?,
        Slot::ClassConf => vals.conf = v as f32,
        Slot::Instance => vals.instance = to_i32(v, "instance", vertex)?,
        Slot::ClassEntropy => vals.entropy = v as f32,
        Slot::Segment => vals.segment = to_i32(v, "segment", vertex)?,
        Slot::Sem(i) => sem[i] = v as f32,
        Slot::Skip => {}
    }
    Ok(())
}

/// Appends one vertex: extends SH and semantics by a zeroed block, fills it through `fill`,
/// then pushes the per-vertex scalars.
fn push_vertex(
    g: &mut Gaussians,
    fill: impl FnOnce(&mut VertexValues, &mut [f32], &mut [f32]) -> Result<()>,
) -> Result<()> {
    let k3 = g.sh_coeffs() * 3;
    let sh_start = g.sh.len();
    g.sh.resize(sh_start + k3, 0.0);
    let mut no_sem: [f32; 0] = [];
    let sem: &mut [f32] = match &mut g.semantics {
        Some(s) => {
            let start = s.logits.len();
            s.logits.resize(start + s.channels, 0.0);
            &mut s.logits[start..]
        }
        None => &mut no_sem,
    };
    let mut vals = VertexValues::new();
    fill(&mut vals, &mut g.sh[sh_start..], sem)?;
    g.means.push(vals.mean);
    g.log_scales.push(vals.scale);
    g.quats.push(vals.rot);
    g.opacity_logits.push(vals.opacity);
    if let Some(v) = &mut g.class_ids {
        v.push(vals.class);
    }
    if let Some(v) = &mut g.class_conf {
        v.push(vals.conf);
    }
    if let Some(v) = &mut g.instance_ids {
        v.push(vals.instance);
    }
    if let Some(v) = &mut g.class_entropy {
        v.push(vals.entropy);
    }
    if let Some(v) = &mut g.segment_ids {
        v.push(vals.segment);
    }
    Ok(())
}

fn read_binary_vertices(
    r: &mut impl Read,
    layout: &Layout,
    record_len: usize,
    n: usize,
    big_endian: bool,
    g: &mut Gaussians,
) -> Result<()> {
    let mut record = vec![0u8; record_len];
    for vertex in 0..n {
        r.read_exact(&mut record).map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => {
                anyhow!("truncated file: the header claims {n} vertices, the data ends in vertex {vertex}")
            }
            _ => anyhow!("read error in vertex {vertex}: {e}"),
        })?;
        push_vertex(g, |vals, sh, sem| {
            let mut at = 0;
            for &(slot, ty) in &layout.slots {
                let size = ty.size();
                let v = ty.decode(&record[at..at + size], big_endian);
                at += size;
                store((slot, ty), v, vals, sh, sem, vertex)?;
            }
            Ok(())
        })?;
    }
    Ok(())
}

/// A whole vertex's bytes or more past the last vertex mean the header's count is wrong (a
/// count left from an earlier write, files joined): reading `n` would silently drop the
/// rest. Less than one vertex is let pass (a newline, a writer's padding).
fn refuse_binary_trailer(r: &mut impl Read, n: usize, record_len: usize) -> Result<()> {
    let mut rest = Vec::new();
    r.take(record_len as u64).read_to_end(&mut rest)?;
    if rest.len() == record_len && record_len > 0 {
        bail!(
            "data continues past the header's {n} vertices (at least one more vertex's \
             {record_len} bytes): the header's vertex count is wrong, or the file holds more \
             than it declares"
        );
    }
    Ok(())
}

/// ASCII vertices, one line each (as the format writes them): a line with more or fewer
/// values than the header's properties is an error, where reading the values as one stream
/// would shift every later vertex's fields silently. With `last` (no element follows),
/// anything past the last vertex is an error too.
fn read_ascii_vertices(
    r: &mut impl BufRead,
    layout: &Layout,
    n: usize,
    last: bool,
    g: &mut Gaussians,
) -> Result<()> {
    let mut tokens = Tokens::new(r);
    let per_line = layout.slots.len();
    for vertex in 0..n {
        push_vertex(g, |vals, sh, sem| {
            let mut first_line = 0;
            for (k, &(slot, ty)) in layout.slots.iter().enumerate() {
                let v = tokens.next_value()?.ok_or_else(|| {
                    anyhow!("truncated file: the header claims {n} vertices, the data ends in vertex {vertex}")
                })?;
                if k == 0 {
                    first_line = tokens.line_no;
                } else if tokens.line_no != first_line {
                    bail!(
                        "data line {first_line}: vertex {vertex} ends after {k} values, but the \
                         header declares {per_line} properties a vertex"
                    );
                }
                store((slot, ty), v, vals, sh, sem, vertex)?;
            }
            Ok(())
        })?;
        if !tokens.line_done() {
            bail!(
                "data line {}: vertex {vertex}'s line holds more than the header's {per_line} \
                 properties a vertex",
                tokens.line_no
            );
        }
    }
    if last && tokens.next_value()?.is_some() {
        bail!(
            "data line {}: values continue past the header's {n} vertices: the header's vertex \
             count is wrong, or the file holds more than it declares",
            tokens.line_no
        );
    }
    Ok(())
}

/// Whitespace-separated ASCII values, read line by line.
struct Tokens<'a, R: BufRead> {
    r: &'a mut R,
    line: String,
    pos: usize,
    line_no: usize,
}

impl<'a, R: BufRead> Tokens<'a, R> {
    fn new(r: &'a mut R) -> Self {
        Tokens {
            r,
            line: String::new(),
            pos: 0,
            line_no: 0,
        }
    }

    /// The next value, `None` at end of input.
    fn next_value(&mut self) -> Result<Option<f64>> {
        loop {
            let rest = &self.line[self.pos..];
            let trimmed = rest.trim_start();
            if !trimmed.is_empty() {
                let start = self.pos + (rest.len() - trimmed.len());
                let end = trimmed
                    .find(char::is_whitespace)
                    .map_or(self.line.len(), |e| start + e);
                self.pos = end;
                let tok = &self.line[start..end];
                let v = tok.parse::<f64>().map_err(|_| {
                    anyhow!(
                        "data line {}: '{}' is not a number",
                        self.line_no,
                        tok.chars().take(40).collect::<String>()
                    )
                })?;
                return Ok(Some(v));
            }
            self.line.clear();
            self.pos = 0;
            self.line_no += 1;
            let read = self
                .r
                .read_line(&mut self.line)
                .map_err(|e| anyhow!("data line {}: {e}", self.line_no))?;
            if read == 0 {
                return Ok(None);
            }
        }
    }

    /// Whether the current line holds no more values.
    fn line_done(&self) -> bool {
        self.line[self.pos..].trim().is_empty()
    }

    /// Elements end at a line end: anything left on the current line is an error.
    fn finish_line(&mut self) -> Result<()> {
        if !self.line_done() {
            bail!(
                "data line {}: more values than the header declares",
                self.line_no
            );
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------
// Writing

/// The floats every written scene starts with, before its higher SH bands.
const FIRST_PROPERTIES: [&str; 9] = [
    "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
];
/// The floats every written scene holds after its higher SH bands.
const LAST_PROPERTIES: [&str; 8] = [
    "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
];

/// Bytes of the properties every Gaussian of a written scene of `sh_coeffs` SH
/// coefficients holds (each property is 4 bytes: [`property_names`]), before its optional
/// fields (class, confidence, semantics, ...): what an output needs at least.
pub fn every_scenes_vertex_bytes(sh_coeffs: usize) -> usize {
    4 * (FIRST_PROPERTIES.len() + (sh_coeffs - 1) * 3 + LAST_PROPERTIES.len())
}

/// The property names we write, in order (standard 3DGS first, then semantics); each 4
/// bytes (float or int).
fn property_names(g: &Gaussians) -> Vec<(String, &'static str)> {
    let mut names: Vec<(String, &'static str)> = Vec::new();
    let float = |n: &str| (n.to_owned(), "float");
    names.extend(FIRST_PROPERTIES.map(float));
    for i in 0..(g.sh_coeffs() - 1) * 3 {
        names.push(float(&format!("f_rest_{i}")));
    }
    names.extend(LAST_PROPERTIES.map(float));
    if g.class_ids.is_some() {
        names.push(("class".into(), "int"));
    }
    if g.class_conf.is_some() {
        names.push(float("class_conf"));
    }
    if g.instance_ids.is_some() {
        names.push(("instance".into(), "int"));
    }
    if g.class_entropy.is_some() {
        names.push(float("class_entropy"));
    }
    if g.segment_ids.is_some() {
        names.push(("segment".into(), "int"));
    }
    if let Some(s) = &g.semantics {
        for i in 0..s.channels {
            names.push(float(&format!("sem_{i}")));
        }
    }
    names
}

/// Writes a binary little-endian 3DGS PLY atomically, with the semantic fields that are set.
pub fn write_ply(path: &Path, g: &Gaussians) -> Result<()> {
    refuse_other_splat_extension(path)?;
    g.check_layout()
        .and_then(|()| check_finite(g))
        .with_context(|| format!("refusing to write PLY {}", path.display()))?;
    write_atomic(path, |w| write_ply_to(w, g))
}

/// semsplat writes only the standard PLY: a name promising another splat format would
/// hold bytes its readers cannot parse.
fn refuse_other_splat_extension(path: &Path) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default();
    if ["splat", "spz", "ksplat", "sog"]
        .iter()
        .any(|e| e.eq_ignore_ascii_case(ext))
    {
        bail!(
            "refusing to write {}: semsplat writes the standard 3DGS PLY only (name it .ply; \
             convert afterwards with e.g. PlayCanvas splat-transform)",
            path.display()
        );
    }
    Ok(())
}

/// The first non-finite float a PLY would hold, named by property and Gaussian index (a NaN
/// model must never be written as if it were a result).
pub fn check_finite(g: &Gaussians) -> Result<()> {
    let bad = |v: &[f32]| v.iter().position(|x| !x.is_finite());
    let k3 = g.sh_coeffs() * 3;
    for i in 0..g.len() {
        let fields: [(&str, &[f32]); 4] = [
            ("x y z", &g.means[i]),
            ("scale_*", &g.log_scales[i]),
            ("rot_*", &g.quats[i]),
            ("opacity", std::slice::from_ref(&g.opacity_logits[i])),
        ];
        for (name, v) in fields {
            if let Some(k) = bad(v) {
                bail!(
                    "Gaussian {i} has a non-finite {name} value ({}, component {k})",
                    v[k]
                );
            }
        }
        if let Some(k) = bad(&g.sh[i * k3..(i + 1) * k3]) {
            let what = if k < 3 {
                format!("f_dc_{k}")
            } else {
                format!("SH coefficient {} channel {}", k / 3, k % 3)
            };
            bail!("Gaussian {i} has a non-finite {what}");
        }
        if let Some(s) = &g.semantics {
            if let Some(k) = bad(&s.logits[i * s.channels..(i + 1) * s.channels]) {
                bail!("Gaussian {i} has a non-finite sem_{k}");
            }
        }
        if let Some(k) = g.class_conf.as_ref().filter(|c| !c[i].is_finite()) {
            bail!("Gaussian {i} has a non-finite class_conf ({})", k[i]);
        }
        if let Some(k) = g.class_entropy.as_ref().filter(|c| !c[i].is_finite()) {
            bail!("Gaussian {i} has a non-finite class_entropy ({})", k[i]);
        }
    }
    Ok(())
}

/// Writes a binary little-endian 3DGS PLY to any writer (non-finite values refused).
pub fn write_ply_to(w: &mut impl Write, g: &Gaussians) -> Result<()> {
    g.check_layout()?;
    check_finite(g)?;
    let names = property_names(g);
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by semsplat {}\nelement vertex {}\n",
        env!("CARGO_PKG_VERSION"),
        g.len()
    );
    for (name, ty) in &names {
        header.push_str(&format!("property {ty} {name}\n"));
    }
    header.push_str("end_header\n");
    w.write_all(header.as_bytes())?;

    let k = g.sh_coeffs();
    let mut record: Vec<u8> = Vec::with_capacity(names.len() * 4);
    for i in 0..g.len() {
        record.clear();
        let mut f = |v: f32| record.extend_from_slice(&v.to_le_bytes());
        g.means[i].iter().for_each(|&v| f(v));
        [0.0; 3].iter().for_each(|&v| f(v)); // normals: unused by 3DGS, expected by viewers
        let sh = &g.sh[i * k * 3..(i + 1) * k * 3];
        (0..3).for_each(|c| f(sh[c]));
        // f_rest channel-major: all red coefficients, then green, then blue.
        for c in 0..3 {
            for coeff in 1..k {
                f(sh[coeff * 3 + c]);
            }
        }
        f(g.opacity_logits[i]);
        g.log_scales[i].iter().for_each(|&v| f(v));
        g.quats[i].iter().for_each(|&v| f(v));
        if let Some(v) = &g.class_ids {
            record.extend_from_slice(&v[i].to_le_bytes());
        }
        if let Some(v) = &g.class_conf {
            record.extend_from_slice(&v[i].to_le_bytes());
        }
        if let Some(v) = &g.instance_ids {
            record.extend_from_slice(&v[i].to_le_bytes());
        }
        if let Some(v) = &g.class_entropy {
            record.extend_from_slice(&v[i].to_le_bytes());
        }
        if let Some(v) = &g.segment_ids {
            record.extend_from_slice(&v[i].to_le_bytes());
        }
        if let Some(s) = &g.semantics {
            for v in &s.logits[i * s.channels..(i + 1) * s.channels] {
                record.extend_from_slice(&v.to_le_bytes());
            }
        }
        w.write_all(&record)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Class table sidecar

/// `<ply path without .ply>.classes.json`: where the class table of a PLY's `class` ids lives.
/// Beside the file the path names, through any symbolic links: a PLY written through a
/// link lands in its target, and its table must land beside it (a table beside the link
/// would leave the target with its old one).
pub fn classes_sidecar_path(ply_path: &Path) -> PathBuf {
    let resolved = crate::util::resolve_output_file(ply_path);
    let ply_path = resolved.as_deref().unwrap_or(ply_path);
    let is_ply = ply_path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    let base = if is_ply {
        ply_path.with_extension("")
    } else {
        ply_path.to_path_buf()
    };
    let mut name = base
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".classes.json");
    base.with_file_name(name)
}

/// Writes the class table beside a PLY (see [`classes_sidecar_path`]).
pub fn write_classes_sidecar(ply_path: &Path, table: &ClassTable) -> Result<()> {
    write_class_table(&classes_sidecar_path(ply_path), table)
}

/// Reads the class table beside a PLY, `None` if there is none.
pub fn read_classes_sidecar(ply_path: &Path) -> Result<Option<ClassTable>> {
    let path = classes_sidecar_path(ply_path);
    if !path.exists() {
        return Ok(None);
    }
    read_class_table(&path).map(Some)
}
