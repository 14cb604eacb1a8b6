//! Label maps (gray, palette, gray+alpha, RGB gray or colour-coded PNGs: see [`decode`])
//! and palette-coloured PNG output.
//!
//! A label map holds one user class id per pixel; the ignore id ([`LabelFormat`]: by default
//! 255 in 8-bit files and 65535 in 16-bit files) loads as [`LabelMap::IGNORE`]. Label folders
//! are matched to cameras by the image's relative path or, when unique, its stem
//! ([`LabelDir`]), and are read one map at a time.

mod decode;
mod folder;
mod interpolated;

use std::path::Path;

use anyhow::{bail, Context, Result};
use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder};

use super::classes::{ClassTable, IGNORE_U16, IGNORE_U8};
use crate::util::write_atomic;

pub use decode::{
    read_label_png_as, read_png_header, LabelFormat, PngHeader, JPEG_LABELS, JPEG_MAGIC,
    MAX_DECODE_BYTES, MAX_LABEL_PIXELS, PNG_SIGNATURE,
};
pub use folder::{
    binary_mask_warning, ignored_class_note, jpeg_note, label_size_fit, list_label_pngs, list_some,
    load_label_dir, match_cameras, size_mismatch_reason, stray_255_warning, LabelDir,
    MissingLabels, SizeFit,
};
pub use interpolated::StepTally;

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LabelMap {
    pub width: u32,
    pub height: u32,
    /// Row-major class ids, `width * height` entries.
    pub labels: Vec<u16>,
}

impl LabelMap {
    /// Pixels without a label: the ignore id of [`LabelFormat`] (by default 255 in 8-bit
    /// files, 65535 in 16-bit files) and transparent pixels load as this value.
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

/// Reads a label map PNG with the default [`LabelFormat`] (255 in 8-bit maps and 65535 in
/// 16-bit maps = ignore) and no class table (colour-coded maps are refused); see
/// [`read_label_png_as`] for the forms accepted.
pub fn read_label_png(path: &Path) -> Result<LabelMap> {
    read_label_png_as(path, &LabelFormat::default(), None)
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
