//! Label maps (8/16-bit gray PNG) and palette-colored PNG output.
//!
//! A label map holds one user class id per pixel; 255 in 8-bit files and 65535 in 16-bit
//! files both mean "ignore" and load as [`LabelMap::IGNORE`]. Label folders are matched to
//! cameras by image-name stem (`<camera.name>.png`) and are read one map at a time.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use image::codecs::png::{PngDecoder, PngEncoder};
use image::{ColorType, ExtendedColorType, ImageDecoder, ImageEncoder, Limits};

use super::camera::Camera;
use super::classes::{ClassTable, IGNORE_U16, IGNORE_U8};
use crate::util::write_atomic;

/// Decoded label maps above this size are refused (a corrupt header must not exhaust memory).
const MAX_DECODE_BYTES: u64 = 1 << 30;

/// How many missing names or bad ids an error message lists before "...".
const LIST_IN_ERRORS: usize = 5;

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LabelMap {
    pub width: u32,
    pub height: u32,
    /// Row-major class ids, `width * height` entries.
    pub labels: Vec<u16>,
}

impl LabelMap {
    /// Pixels without a label (255 in 8-bit files, 65535 in 16-bit files).
    pub const IGNORE: u16 = u16::MAX;

    /// A map from row-major labels; the length must be `width * height`.
    pub fn new(width: u32, height: u32, labels: Vec<u16>) -> Result<LabelMap> {
        let expected = width as usize * height as usize;
        if labels.len() != expected {
            bail!(
                "label map {width}x{height} needs {expected} labels, got {}",
                labels.len()
            );
        }
        Ok(LabelMap {
            width,
            height,
            labels,
        })
    }

    /// A map with every pixel set to `value`.
    pub fn filled(width: u32, height: u32, value: u16) -> LabelMap {
        LabelMap {
            width,
            height,
            labels: vec![value; width as usize * height as usize],
        }
    }

    /// The label at pixel (x, y), `None` outside the map.
    pub fn get(&self, x: u32, y: u32) -> Option<u16> {
        if x >= self.width || y >= self.height {
            return None;
        }
        self.labels
            .get(y as usize * self.width as usize + x as usize)
            .copied()
    }

    /// Adds this map's pixel count per label value to `counts` (65,536 entries, one per
    /// 16-bit value; the last one counts ignored pixels).
    pub fn count_into(&self, counts: &mut [u64]) {
        assert_eq!(
            counts.len(),
            IGNORE_U16 as usize + 1,
            "counts needs one slot per 16-bit value"
        );
        for &l in &self.labels {
            counts[l as usize] += 1;
        }
    }

    /// The distinct class ids present (ignore excluded), ascending.
    pub fn present_ids(&self) -> Vec<u32> {
        let mut seen = vec![false; IGNORE_U16 as usize + 1];
        for &l in &self.labels {
            seen[l as usize] = true;
        }
        seen[Self::IGNORE as usize] = false;
        (0..=IGNORE_U16).filter(|&id| seen[id as usize]).collect()
    }

    fn check_len(&self) -> Result<()> {
        let expected = self.width as usize * self.height as usize;
        if self.labels.len() != expected || expected == 0 {
            bail!(
                "label map claims {}x{} but holds {} labels",
                self.width,
                self.height,
                self.labels.len()
            );
        }
        Ok(())
    }
}

/// What a PNG header says about its pixel format (read before decoding, so errors can
/// name the file's real color type rather than the decoder's expanded one).
fn png_color_and_depth(reader: &mut BufReader<File>) -> Result<(u8, u8)> {
    let mut head = [0u8; 26];
    reader
        .read_exact(&mut head)
        .map_err(|_| anyhow!("not a PNG file (too short)"))?;
    if &head[..8] != b"\x89PNG\r\n\x1a\n" || &head[12..16] != b"IHDR" {
        bail!("not a PNG file");
    }
    reader.seek(SeekFrom::Start(0))?;
    Ok((head[25], head[24]))
}

fn color_type_name(color: u8) -> &'static str {
    match color {
        0 => "a grayscale",
        2 => "an RGB",
        3 => "a palette (indexed color)",
        4 => "a grayscale-with-alpha",
        6 => "an RGBA",
        _ => "an unknown color type",
    }
}

/// Reads an 8- or 16-bit single-channel PNG of class ids; 255 (8-bit) and 65535 (16-bit)
/// load as [`LabelMap::IGNORE`]. Color and palette PNGs are refused.
pub fn read_label_png(path: &Path) -> Result<LabelMap> {
    read_label_png_inner(path).with_context(|| format!("label map {}", path.display()))
}

fn read_label_png_inner(path: &Path) -> Result<LabelMap> {
    let file = File::open(path).context("cannot open")?;
    let mut reader = BufReader::new(file);
    let (color, depth) = png_color_and_depth(&mut reader)?;
    if color != 0 {
        bail!(
            "is {} PNG, but label maps must be single-channel class ids (8- or 16-bit grayscale \
             PNG, 255/65535 = ignore); a palette PNG whose indices are the class ids must be \
             re-saved as grayscale indices, and color-coded maps converted to ids",
            color_type_name(color)
        );
    }
    if depth != 8 && depth != 16 {
        bail!("is a {depth}-bit grayscale PNG: label maps must be 8- or 16-bit");
    }
    let mut limits = Limits::default();
    limits.max_alloc = Some(MAX_DECODE_BYTES);
    let decoder = PngDecoder::with_limits(reader, limits).context("cannot decode PNG")?;
    let (width, height) = decoder.dimensions();
    let color_type = decoder.color_type();
    let total = decoder.total_bytes();
    if total > MAX_DECODE_BYTES || width == 0 || height == 0 {
        bail!("unsupported size {width}x{height}");
    }
    let mut bytes = vec![0u8; total as usize];
    decoder
        .read_image(&mut bytes)
        .context("cannot decode PNG")?;
    let labels: Vec<u16> = match color_type {
        ColorType::L8 => bytes
            .iter()
            .map(|&b| {
                if b as u32 == IGNORE_U8 {
                    LabelMap::IGNORE
                } else {
                    b as u16
                }
            })
            .collect(),
        // 65535 is already LabelMap::IGNORE; the decoder hands us native-endian samples.
        ColorType::L16 => bytes
            .chunks_exact(2)
            .map(|c| u16::from_ne_bytes([c[0], c[1]]))
            .collect(),
        other => bail!("decoded as {other:?}: label maps must be 8- or 16-bit grayscale"),
    };
    LabelMap::new(width, height, labels)
}

/// Writes a label map as a grayscale PNG: 8-bit when every id is below 255, else 16-bit.
/// [`LabelMap::IGNORE`] is written as 255 or 65535 respectively.
pub fn write_label_png(path: &Path, map: &LabelMap) -> Result<()> {
    map.check_len()
        .with_context(|| format!("writing label map {}", path.display()))?;
    let fits_8bit = map
        .labels
        .iter()
        .all(|&l| l == LabelMap::IGNORE || (l as u32) < IGNORE_U8);
    let (bytes, color) = if fits_8bit {
        let bytes: Vec<u8> = map
            .labels
            .iter()
            .map(|&l| {
                if l == LabelMap::IGNORE {
                    IGNORE_U8 as u8
                } else {
                    l as u8
                }
            })
            .collect();
        (bytes, ExtendedColorType::L8)
    } else {
        let bytes: Vec<u8> = map.labels.iter().flat_map(|l| l.to_ne_bytes()).collect();
        (bytes, ExtendedColorType::L16)
    };
    write_atomic(path, |w| {
        PngEncoder::new(w).write_image(&bytes, map.width, map.height, color)?;
        Ok(())
    })
}

/// Writes a label map as an RGB PNG for viewing: table colors, a deterministic fallback
/// color for ids missing from the table, black for ignored pixels.
pub fn write_palette_png(path: &Path, map: &LabelMap, table: &ClassTable) -> Result<()> {
    map.check_len()
        .with_context(|| format!("writing palette image {}", path.display()))?;
    let lut = table.color_lut();
    let rgb: Vec<u8> = map.labels.iter().flat_map(|&l| lut[l as usize]).collect();
    write_atomic(path, |w| {
        PngEncoder::new(w).write_image(&rgb, map.width, map.height, ExtendedColorType::Rgb8)?;
        Ok(())
    })
}

/// The `.png` files of a folder keyed by file stem, sorted by stem. Subfolders and other
/// files are ignored; two files with the same stem (e.g. `a.png`, `a.PNG`) are an error.
pub fn list_label_pngs(dir: &Path) -> Result<BTreeMap<String, PathBuf>> {
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("reading label folder {}", dir.display()))?;
    let mut found = BTreeMap::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("reading label folder {}", dir.display()))?
            .path();
        let is_png = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"));
        if !is_png || !path.is_file() {
            continue;
        }
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else {
            continue;
        };
        if let Some(prev) = found.insert(stem.to_owned(), path.clone()) {
            bail!(
                "label folder {} has two maps for '{stem}': {} and {}",
                dir.display(),
                prev.display(),
                path.display()
            );
        }
    }
    Ok(found)
}

/// What to do with a camera that has no label map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MissingLabels {
    /// Fail, listing the first few missing names (the default: a silently skipped view is
    /// usually a naming mistake).
    #[default]
    Error,
    /// Leave those cameras out; [`LabelDir::skipped`] lists them.
    Skip,
}

struct LabelEntry {
    camera: usize,
    path: PathBuf,
    width: u32,
    height: u32,
}

/// A label folder matched to cameras. Maps are read one at a time by [`LabelDir::iter`] or
/// [`LabelDir::load`], so fusion can stream views without holding every map in memory.
pub struct LabelDir {
    dir: PathBuf,
    entries: Vec<LabelEntry>,
    skipped: Vec<String>,
    /// `allowed[id]`: the id is in the class table (or there is no table).
    allowed: Option<Vec<bool>>,
}

impl LabelDir {
    /// Matches `<camera.name>.png` in `dir` to every camera. With a class table, every
    /// loaded map is checked to use only the table's ids (and ignore).
    pub fn open(
        dir: &Path,
        cameras: &[Camera],
        table: Option<&ClassTable>,
        missing: MissingLabels,
    ) -> Result<LabelDir> {
        let files = list_label_pngs(dir)?;
        let mut entries = Vec::with_capacity(cameras.len());
        let mut skipped = Vec::new();
        for (i, cam) in cameras.iter().enumerate() {
            match files.get(&cam.name) {
                Some(path) => entries.push(LabelEntry {
                    camera: i,
                    path: path.clone(),
                    width: cam.width,
                    height: cam.height,
                }),
                None => skipped.push(cam.name.clone()),
            }
        }
        if missing == MissingLabels::Error && !skipped.is_empty() {
            bail!(
                "label folder {} has no label map for {} of {} cameras: {} (expected <image name>.png)",
                dir.display(),
                skipped.len(),
                cameras.len(),
                list_some(&skipped)
            );
        }
        let allowed = table.map(|t| {
            let mut allowed = vec![false; IGNORE_U16 as usize + 1];
            for c in &t.classes {
                if let Some(slot) = allowed.get_mut(c.id as usize) {
                    *slot = true;
                }
            }
            allowed[LabelMap::IGNORE as usize] = true;
            allowed
        });
        Ok(LabelDir {
            dir: dir.to_owned(),
            entries,
            skipped,
            allowed,
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Number of cameras with a label map.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Names of cameras without a label map (only with [`MissingLabels::Skip`]).
    pub fn skipped(&self) -> &[String] {
        &self.skipped
    }

    /// The camera index of the `i`-th map.
    pub fn camera_index(&self, i: usize) -> Option<usize> {
        self.entries.get(i).map(|e| e.camera)
    }

    /// The file of the `i`-th map.
    pub fn path(&self, i: usize) -> Option<&Path> {
        self.entries.get(i).map(|e| e.path.as_path())
    }

    /// Reads and checks the `i`-th map: its size must match its camera and its ids must be
    /// in the class table (when one was given).
    pub fn load(&self, i: usize) -> Result<LabelMap> {
        let e = self
            .entries
            .get(i)
            .ok_or_else(|| anyhow!("label map index {i} out of range"))?;
        let map = read_label_png(&e.path)?;
        if (map.width, map.height) != (e.width, e.height) {
            bail!(
                "label map {} is {}x{} but its camera is {}x{}",
                e.path.display(),
                map.width,
                map.height,
                e.width,
                e.height
            );
        }
        if let Some(allowed) = &self.allowed {
            check_ids_in_table(&map, allowed)
                .with_context(|| format!("label map {}", e.path.display()))?;
        }
        Ok(map)
    }

    /// Streams `(camera index, map)` pairs in camera order.
    pub fn iter(&self) -> impl Iterator<Item = Result<(usize, LabelMap)>> + '_ {
        (0..self.entries.len()).map(move |i| Ok((self.entries[i].camera, self.load(i)?)))
    }
}

fn check_ids_in_table(map: &LabelMap, allowed: &[bool]) -> Result<()> {
    let mut bad: HashMap<u16, u64> = HashMap::new();
    for &l in &map.labels {
        if !allowed[l as usize] {
            *bad.entry(l).or_default() += 1;
        }
    }
    if bad.is_empty() {
        return Ok(());
    }
    let mut ids: Vec<u16> = bad.keys().copied().collect();
    ids.sort_unstable();
    let pixels: u64 = bad.values().sum();
    let names: Vec<String> = ids.iter().map(|id| id.to_string()).collect();
    bail!(
        "{pixels} pixels use class ids that are not in the class table: {}",
        list_some(&names)
    )
}

/// "a, b, c, d, e and 3 more".
fn list_some(names: &[String]) -> String {
    let shown: Vec<&str> = names
        .iter()
        .take(LIST_IN_ERRORS)
        .map(String::as_str)
        .collect();
    let mut s = shown.join(", ");
    if names.len() > LIST_IN_ERRORS {
        s.push_str(&format!(" and {} more", names.len() - LIST_IN_ERRORS));
    }
    s
}

/// Loads every camera's label map (checked as in [`LabelDir::load`]) into memory, in camera
/// order; prefer [`LabelDir::iter`] for large scenes.
pub fn load_label_dir(
    dir: &Path,
    cameras: &[Camera],
    table: Option<&ClassTable>,
) -> Result<Vec<LabelMap>> {
    let labels = LabelDir::open(dir, cameras, table, MissingLabels::Error)?;
    labels.iter().map(|r| r.map(|(_, m)| m)).collect()
}
