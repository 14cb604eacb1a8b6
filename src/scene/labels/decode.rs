//! Reading label map PNGs in the forms segmenters and mask trackers write them: gray
//! (1/2/4/8/16-bit), palette (the index is the class id: VOC, DAVIS, DEVA, XMem), gray+alpha,
//! RGB/RGBA that is gray (R = G = B) or colour-coded through the class table's colours.
//!
//! The header is read and checked (size, bit depth, colour type) before any pixel is
//! decoded, so a huge image costs 33 bytes of reading to refuse, not gigabytes.

use std::cell::RefCell;
use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};

use super::LabelMap;
use crate::scene::classes::{ClassTable, IGNORE_U16, IGNORE_U8};

/// Decoded label maps above this size are refused (a corrupt or huge header must not
/// exhaust memory): checked from the header, and again as the decoder's allocation limit.
pub const MAX_DECODE_BYTES: u64 = 1 << 30;

/// Label maps with more pixels than this (16384 x 16384) are refused from their header:
/// reading one takes its samples plus 2 bytes a pixel, and no camera needs more.
pub const MAX_LABEL_PIXELS: u64 = 1 << 28;

/// How label map files are read: the one place the reading options live, carried by the
/// dataset loader ([`LabelDir`](super::LabelDir)) to every command that reads labels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LabelFormat {
    /// The pixel value that means "no label" (`--ignore-id`); None: 255 in 8-bit (and
    /// palette, RGB) maps, 65535 in 16-bit maps. 65535 in a 16-bit map is always ignored: it
    /// cannot be a class id.
    pub ignore_id: Option<u16>,
}

impl LabelFormat {
    pub fn with_ignore_id(ignore_id: Option<u16>) -> LabelFormat {
        LabelFormat { ignore_id }
    }

    /// The raw value ignored in a map whose samples are `bit_depth` bits wide.
    pub fn ignore_for_depth(&self, bit_depth: u8) -> u16 {
        match (self.ignore_id, bit_depth) {
            (Some(id), _) => id,
            (None, 16) => IGNORE_U16 as u16,
            (None, _) => IGNORE_U8 as u16,
        }
    }

    /// "255 (8-bit maps) / 65535 (16-bit maps)" or "0 (--ignore-id)", for messages.
    pub fn describe_ignore(&self) -> String {
        match self.ignore_id {
            Some(id) => format!("{id} (--ignore-id)"),
            None => format!("{IGNORE_U8} in 8-bit maps, {IGNORE_U16} in 16-bit maps: the default"),
        }
    }
}

/// What a PNG header says, read before decoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PngHeader {
    pub width: u32,
    pub height: u32,
    pub bit_depth: u8,
    /// The PNG colour type: 0 gray, 2 RGB, 3 palette, 4 gray+alpha, 6 RGBA.
    pub color_type: u8,
}

impl PngHeader {
    fn channels(&self) -> usize {
        match self.color_type {
            2 => 3,
            4 => 2,
            6 => 4,
            _ => 1,
        }
    }

    /// Bytes the decoded samples take (sub-byte depths counted as bytes, as we expand them).
    pub fn decoded_bytes(&self) -> u64 {
        let per_sample = if self.bit_depth == 16 { 2 } else { 1 };
        self.width as u64 * self.height as u64 * self.channels() as u64 * per_sample
    }

    /// Bytes the samples take packed as stored (sub-byte depths packed), before filtering:
    /// the least the image's zlib stream inflates to.
    fn stored_bytes(&self) -> u64 {
        let bits =
            self.width as u64 * self.height as u64 * self.channels() as u64 * self.bit_depth as u64;
        bits / 8
    }

    fn kind(&self) -> &'static str {
        match self.color_type {
            0 => "a grayscale",
            2 => "an RGB",
            3 => "a palette (indexed colour)",
            4 => "a grayscale-with-alpha",
            6 => "an RGBA",
            _ => "an unknown colour type",
        }
    }

    /// Refuses colour types and depths label maps cannot be, and sizes over the limit.
    fn check(&self) -> Result<()> {
        let depth_ok = match self.color_type {
            0 => matches!(self.bit_depth, 1 | 2 | 4 | 8 | 16),
            3 => matches!(self.bit_depth, 1 | 2 | 4 | 8),
            2 | 4 | 6 => matches!(self.bit_depth, 8 | 16),
            other => bail!("has PNG colour type {other}, which is not a valid PNG"),
        };
        if !depth_ok {
            bail!(
                "is {} PNG of bit depth {}, which is not valid PNG",
                self.kind(),
                self.bit_depth
            );
        }
        let pixels = self.width as u64 * self.height as u64;
        if pixels == 0 || pixels > MAX_LABEL_PIXELS || self.decoded_bytes() > MAX_DECODE_BYTES {
            bail!(
                "is {}x{} ({} PNG): refused from its header, over the {} pixels ({} MiB \
                 decoded) a label map may have",
                self.width,
                self.height,
                self.kind(),
                MAX_LABEL_PIXELS,
                MAX_DECODE_BYTES >> 20
            );
        }
        Ok(())
    }
}

/// The eight bytes every PNG file starts with.
pub const PNG_SIGNATURE: [u8; 8] = *b"\x89PNG\r\n\x1a\n";

/// The three bytes every JPEG file starts with (start of image, then a marker).
pub const JPEG_MAGIC: [u8; 3] = [0xff, 0xd8, 0xff];

/// Why label maps must be PNG, and what to do, said wherever JPEG label maps are found.
pub const JPEG_LABELS: &str = "label maps must be PNG: JPEG's lossy compression turns the ids \
                               along every region's edge into other ids; save the segmenter's \
                               class ids as PNG";

/// Reads and checks a PNG's header (signature and IHDR) without decoding any pixel.
pub fn read_png_header(path: &Path) -> Result<PngHeader> {
    let mut head = [0u8; 33];
    let mut file = File::open(path).context("cannot open")?;
    file.read_exact(&mut head)
        .map_err(|_| anyhow!("not a PNG file (too short)"))?;
    if head.starts_with(&JPEG_MAGIC) {
        bail!("a JPEG file named .png; {JPEG_LABELS}");
    }
    if head[..8] != PNG_SIGNATURE || &head[12..16] != b"IHDR" {
        bail!("not a PNG file");
    }
    let be32 = |i: usize| u32::from_be_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]);
    let header = PngHeader {
        width: be32(16),
        height: be32(20),
        bit_depth: head[24],
        color_type: head[25],
    };
    header.check()?;
    Ok(header)
}

/// zlib inflates at most 1032 bytes from one (deflate's longest match, 258 bytes, in two
/// bits): a file that cannot hold its samples is refused before a buffer of their size is
/// filled (up to 1 GiB for a 60-byte file).
fn check_file_holds_samples(path: &Path, h: &PngHeader) -> Result<()> {
    let file_len = std::fs::metadata(path).map(|m| m.len()).unwrap_or(u64::MAX);
    if h.stored_bytes() > file_len.saturating_mul(MAX_DEFLATE_RATIO) {
        bail!(
            "cannot decode PNG: it is {}x{} ({} PNG) but its {file_len} bytes cannot hold that \
             many pixels (truncated or corrupt file)",
            h.width,
            h.height,
            h.kind()
        );
    }
    Ok(())
}

/// The most bytes zlib inflates from one byte of a stream.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// The raw samples of a PNG exactly as stored (no palette expansion: an index is a class
/// id), written over `buf`; returns the byte length of each row and the palette's colours
/// (empty for other colour types).
fn decode_samples(path: &Path, buf: &mut Vec<u8>) -> Result<(usize, Vec<[u8; 3]>)> {
    let file = BufReader::new(File::open(path).context("cannot open")?);
    let limits = png::Limits {
        bytes: MAX_DECODE_BYTES as usize,
    };
    let mut decoder = png::Decoder::new_with_limits(file, limits);
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().context("cannot decode PNG")?;
    let palette = match &reader.info().palette {
        Some(bytes) if reader.info().color_type == png::ColorType::Indexed => {
            bytes.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
        }
        _ => Vec::new(),
    };
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| anyhow!("cannot decode PNG: image too large"))?;
    buf.resize(size, 0);
    let info = reader.next_frame(buf).context("cannot decode PNG")?;
    buf.truncate(info.buffer_size());
    Ok((info.line_size, palette))
}

/// Decoded samples of up to this many bytes stay with their thread for its next map
/// (a 1080p map's RGBA is 8.3 MB); a larger buffer is freed after its map.
const KEPT_SAMPLE_BYTES: usize = 16 << 20;

thread_local! {
    /// The thread's buffer of decoded samples, reused map after map: the label readers
    /// decode a map each every few milliseconds, and a fresh buffer each time was zeroed
    /// and faulted in anew (0.77 -> 0.68 s for the 190 1080p maps of a capture on one core).
    static SAMPLES: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// Sample `channel` of pixel `x` in one decoded row.
fn sample(row: &[u8], x: usize, channel: usize, h: &PngHeader) -> u16 {
    let i = x * h.channels() + channel;
    match h.bit_depth {
        16 => u16::from_be_bytes([row[2 * i], row[2 * i + 1]]),
        8 => row[i] as u16,
        depth => {
            // Sub-byte samples (gray or palette, one channel) are packed high bits first.
            let bit = i * depth as usize;
            let shift = 8 - depth as usize - bit % 8;
            ((row[bit / 8] >> shift) & ((1u8 << depth) - 1)) as u16
        }
    }
}

/// A pixel before the class table and the ignore id are applied.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum RawPixel {
    /// A class id as stored (gray value or palette index).
    Id(u16),
    /// An RGB colour that is not gray.
    Color([u8; 3]),
    /// Alpha 0: no label.
    Transparent,
}

/// Pixel `i` (row-major) of the decoded samples.
fn raw_pixel(samples: &[u8], line: usize, h: &PngHeader, i: usize) -> RawPixel {
    let (x, y) = (i % h.width as usize, i / h.width as usize);
    raw_in_row(&samples[y * line..(y + 1) * line], x, h)
}

/// Pixel `x` of one decoded row.
fn raw_in_row(row: &[u8], x: usize, h: &PngHeader) -> RawPixel {
    let s = |c| sample(row, x, c, h);
    match h.color_type {
        4 if s(1) == 0 => RawPixel::Transparent,
        6 if s(3) == 0 => RawPixel::Transparent,
        2 | 6 if s(0) != s(1) || s(1) != s(2) => {
            // 16-bit colours keep their high byte: tables hold 8-bit colours.
            let c8 = |c| {
                if h.bit_depth == 16 {
                    (s(c) >> 8) as u8
                } else {
                    s(c) as u8
                }
            };
            RawPixel::Color([c8(0), c8(1), c8(2)])
        }
        _ => RawPixel::Id(s(0)),
    }
}

/// Reads a label map PNG (any form in the module doc) as class ids; the ignore id (see
/// [`LabelFormat`]) and transparent pixels load as [`LabelMap::IGNORE`]. `table` gives the
/// colours of colour-coded RGB maps.
pub fn read_label_png_as(
    path: &Path,
    format: &LabelFormat,
    table: Option<&ClassTable>,
) -> Result<LabelMap> {
    read_inner(path, format, table).with_context(|| format!("label map {}", path.display()))
}

fn read_inner(path: &Path, format: &LabelFormat, table: Option<&ClassTable>) -> Result<LabelMap> {
    let h = read_png_header(path)?;
    check_file_holds_samples(path, &h)?;
    SAMPLES.with_borrow_mut(|samples| {
        let map = decode_labels(path, format, table, &h, samples);
        if samples.capacity() > KEPT_SAMPLE_BYTES {
            *samples = Vec::new();
        }
        map
    })
}

/// The label map of the PNG at `path`, whose header `h` was read, its samples decoded
/// into `samples`.
fn decode_labels(
    path: &Path,
    format: &LabelFormat,
    table: Option<&ClassTable>,
    h: &PngHeader,
    samples: &mut Vec<u8>,
) -> Result<LabelMap> {
    let (line, palette) = decode_samples(path, samples)?;
    let samples = &samples[..];
    if samples.len() < line * h.height as usize {
        bail!("cannot decode PNG: fewer rows than its header says");
    }
    let n = h.width as usize * h.height as usize;
    let raw = |i| raw_pixel(samples, line, h, i);
    let ignore = format.ignore_for_depth(h.bit_depth);
    let to_label = |id: u16| if id == ignore { LabelMap::IGNORE } else { id };
    let colored =
        matches!(h.color_type, 2 | 6) && (0..n).any(|i| matches!(raw(i), RawPixel::Color(_)));
    let rows = samples.chunks(line).take(h.height as usize);
    let labels = if colored || gray_rgb_is_color_coded(n, &raw, h, table) {
        labels_by_colour(rows, h, &color_lookup(h, table)?, to_label)?
    } else if let Some(table) = table.filter(|_| !palette.is_empty()) {
        // Read once as indices; then each through its colour's class where the palette is
        // a colour-coded map's, else as the class id itself.
        let indices = labels_by_id(rows, h, |index| index);
        let class_of = palette_classes(&palette, &indices, h, table);
        let label = |index: u16| match &class_of {
            Some(class_of) if class_of[index as usize] == LabelMap::IGNORE => LabelMap::IGNORE,
            Some(class_of) => to_label(class_of[index as usize]),
            None => to_label(index),
        };
        indices.into_iter().map(label).collect()
    } else {
        labels_by_id(rows, h, to_label)
    };
    LabelMap::new(h.width, h.height, labels)
}

/// A palette map's class per index where it is a colour-coded map saved with a palette
/// (PIL's `quantize`, an editor's indexed mode): a class table is given, every index the map
/// uses has a colour of the table (or black that is no class's colour: unlabeled), and some
/// index is not the id of its colour's class. Else None: the index is the class id (VOC,
/// DAVIS and the trackers write their palettes with the class at its index, and a table
/// whose colours are that palette's reads the same either way). Read by index, such a map
/// scored a tenth of its colours' accuracy, with no warning.
fn palette_classes(
    palette: &[[u8; 3]],
    indices: &[u16],
    h: &PngHeader,
    table: &ClassTable,
) -> Option<Vec<u16>> {
    let by_color = color_lookup(h, Some(table)).ok()?; // shared colours: read by index
    let mut used = vec![false; 1 << h.bit_depth.min(8)];
    for &index in indices {
        *used.get_mut(index as usize)? = true;
    }
    let mut class_of_index = vec![LabelMap::IGNORE; used.len()];
    let mut moved = false;
    for index in (0..used.len()).filter(|&i| used[i]) {
        // A colour no class has, black aside (unlabeled): a palette of its own.
        if let Some(class) = color_id(&by_color, *palette.get(index)?, 0, h).ok()? {
            class_of_index[index] = class;
            moved |= class as usize != index;
        }
    }
    moved.then_some(class_of_index)
}

/// The ids of a map of ids (gray or palette), row by row: no division a pixel, and a map of
/// 8- or 16-bit ids alone (the common case) read straight from its bytes. A 1080p map of
/// 8-bit ids read and made compact took 20.4 ms a pixel at a time (and through an ordered
/// map of ids), 1.7-2.3 ms so (`cargo bench --bench label_maps`).
fn labels_by_id<'a>(
    rows: impl Iterator<Item = &'a [u8]>,
    h: &PngHeader,
    to_label: impl Fn(u16) -> u16,
) -> Vec<u16> {
    let width = h.width as usize;
    let mut labels = Vec::with_capacity(width * h.height as usize);
    for row in rows {
        match (h.channels(), h.bit_depth) {
            (1, 8) => labels.extend(row[..width].iter().map(|&v| to_label(u16::from(v)))),
            (1, 16) => labels.extend(
                (row[..2 * width].chunks_exact(2))
                    .map(|b| to_label(u16::from_be_bytes([b[0], b[1]]))),
            ),
            _ => labels.extend((0..width).map(|x| match raw_in_row(row, x, h) {
                RawPixel::Id(v) => to_label(v),
                _ => LabelMap::IGNORE,
            })),
        }
    }
    labels
}

/// The classes of a colour-coded map through the class table's colours, row by row. A run
/// of one colour (a segment's pixels along a row) looks its colour up once.
fn labels_by_colour<'a>(
    rows: impl Iterator<Item = &'a [u8]>,
    h: &PngHeader,
    by_color: &HashMap<[u8; 3], u16>,
    to_label: impl Fn(u16) -> u16,
) -> Result<Vec<u16>> {
    let width = h.width as usize;
    let mut labels = Vec::with_capacity(width * h.height as usize);
    let mut last: Option<([u8; 3], Option<u16>)> = None;
    // 8-bit RGB, the common form (no alpha): its bytes are the colours.
    let rgb8 = h.color_type == 2 && h.bit_depth == 8;
    for (y, row) in rows.enumerate() {
        for x in 0..width {
            let color = match rgb8 {
                true => [row[3 * x], row[3 * x + 1], row[3 * x + 2]],
                false => match raw_in_row(row, x, h) {
                    RawPixel::Transparent => {
                        labels.push(LabelMap::IGNORE);
                        continue;
                    }
                    RawPixel::Id(v) => [v as u8; 3],
                    RawPixel::Color(c) => c,
                },
            };
            let id = match last {
                Some((c, id)) if c == color => id,
                _ => color_id(by_color, color, y * width + x, h)?,
            };
            last = Some((color, id));
            labels.push(id.map_or(LabelMap::IGNORE, &to_label));
        }
    }
    Ok(labels)
}

/// An RGB map whose pixels are all gray holds gray ids, unless a class table is given and
/// every gray value but black (unlabeled in a colour-coded map) is one of its colours, and
/// some value is not black: a colour-coded map that happens to show only
/// gray classes (ADE20K's wall, 120-120-120, while id 120 is its pot; Cityscapes' building).
/// Decided map by map: an RGB map of ids whose every value but 0 is also a class's colour,
/// of another class, is the far less likely file.
fn gray_rgb_is_color_coded(
    n: usize,
    raw: &dyn Fn(usize) -> RawPixel,
    h: &PngHeader,
    table: Option<&ClassTable>,
) -> bool {
    let Some(table) = table else { return false };
    if !matches!(h.color_type, 2 | 6) || h.bit_depth != 8 {
        return false;
    }
    let mut seen = [false; 256];
    for i in 0..n {
        if let RawPixel::Id(v) = raw(i) {
            seen[v as usize] = true;
        }
    }
    let is_color = |v: u32| table.classes.iter().any(|c| c.color == [v as u8; 3]);
    // Black that is no class's colour reads as unlabeled in a colour-coded map.
    let gray_classes = (1..256u32).filter(|&v| seen[v as usize]);
    gray_classes.clone().count() > 0 && gray_classes.into_iter().all(is_color)
}

/// Colour -> class id of the table; ambiguous colours are an error.
fn color_lookup(h: &PngHeader, table: Option<&ClassTable>) -> Result<HashMap<[u8; 3], u16>> {
    let Some(table) = table else {
        bail!(
            "is {} PNG with colours that are not gray, but label maps must be single-channel class \
             ids (gray or palette PNG; {} = ignore) or colour-coded maps read through a class \
             table's colours: give the class table (--classes, or classes.json in or beside the \
             label folder)",
            h.kind(),
            IGNORE_U8
        );
    };
    if let Some((a, b, color)) = table.shared_colour() {
        bail!(
            "is a colour-coded map, but classes {a} and {b} of the class table share the colour \
             {color:?}: colours must be unique to read it"
        );
    }
    Ok((table.classes.iter())
        .map(|c| (c.color, c.id as u16))
        .collect())
}

/// The class of a colour; black that is no class's colour is unlabeled (as semsplat's own
/// palette images write it). Any other unknown colour is an error naming it and the pixel.
fn color_id(
    by_color: &HashMap<[u8; 3], u16>,
    color: [u8; 3],
    pixel: usize,
    h: &PngHeader,
) -> Result<Option<u16>> {
    if let Some(&id) = by_color.get(&color) {
        return Ok(Some(id));
    }
    if color == [0, 0, 0] {
        return Ok(None);
    }
    let (x, y) = (pixel % h.width as usize, pixel / h.width as usize);
    bail!(
        "is a colour-coded map, but the colour ({}, {}, {}) at pixel ({x}, {y}) is not the \
         colour of any class in the class table",
        color[0],
        color[1],
        color[2]
    )
}
