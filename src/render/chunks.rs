//! Splitting passes so every buffer range they bind fits one binding
//! (`maxStorageBufferRange`, 128 MiB on lavapipe) while the device may well hold the whole
//! buffer: per-Gaussian passes run in chunks of Gaussians (a scene's SH coefficients pass
//! the limit at ~700k Gaussians of degree 3), per-tile passes in bands of tile rows (an
//! image's semantic channels pass it at 1920x1080 with 17 classes).

use std::ops::Range;

use anyhow::{bail, Result};

use crate::contract::TILE_SIZE;
use crate::gpu::{Buffer, BufferRange};

/// Chunk starts are multiples of this many Gaussians, so every chunk's byte offset (a
/// multiple of 4 bytes per Gaussian times this) meets any device's storage-offset
/// alignment (at most 256 bytes by the Vulkan spec).
pub const CHUNK_GRANULE: u32 = 256;

/// Consecutive ranges covering `0..n`, each at most `len` long (`len` a multiple of
/// [`CHUNK_GRANULE`] unless it covers everything).
pub fn chunks(n: u32, len: u32) -> impl Iterator<Item = Range<u32>> {
    let len = len.max(1);
    (0..n.div_ceil(len).max(1)).map(move |k| {
        let start = k * len;
        start..n.min(start.saturating_add(len))
    })
}

/// The longest chunk whose largest per-Gaussian range (`max_bytes_per_gaussian`, plus one
/// trailing element of `tail_bytes` some buffers carry) fits `max_range` bytes; None when
/// not even one granule fits.
pub fn chunk_len(max_bytes_per_gaussian: u64, tail_bytes: u64, max_range: u64) -> Option<u32> {
    let per = max_bytes_per_gaussian.max(1);
    let fit = max_range.saturating_sub(tail_bytes) / per;
    let granules = fit / CHUNK_GRANULE as u64;
    (granules > 0).then(|| (granules * CHUNK_GRANULE as u64).min(u32::MAX as u64) as u32)
}

/// The part of a buffer of `bytes_per_item` per item (Gaussian, slot, element) that items
/// `range` own: what one chunk of a split pass binds.
pub fn part_of<'a>(buf: &'a Buffer, range: &Range<u32>, bytes_per_item: u64) -> BufferRange<'a> {
    BufferRange::new(
        buf,
        range.start as u64 * bytes_per_item,
        range.len() as u64 * bytes_per_item,
    )
}

/// A band of whole tile rows that one per-tile dispatch covers; its per-pixel buffers are
/// bound from the band's first pixel row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Band {
    pub first_tile_row: u32,
    pub tile_rows: u32,
    /// The image's width and height in pixels.
    pub width: u32,
    pub height: u32,
}

impl Band {
    /// The part of a per-pixel buffer of `bytes_per_pixel` this band reads or writes.
    pub fn range<'a>(&self, buf: &'a Buffer, bytes_per_pixel: u64) -> BufferRange<'a> {
        let first_row = (self.first_tile_row * TILE_SIZE) as u64;
        let end_row = ((self.first_tile_row + self.tile_rows) * TILE_SIZE).min(self.height) as u64;
        let row_bytes = self.width as u64 * bytes_per_pixel;
        BufferRange::new(
            buf,
            first_row * row_bytes,
            (end_row - first_row) * row_bytes,
        )
    }

    /// [`Band::range`], or the whole buffer where `bytes_per_pixel` is 0: a placeholder the
    /// kernel never reads (the carried state of a frame walked in one window, semantic
    /// channels of an RGB-only frame).
    pub fn range_or_whole<'a>(&self, buf: &'a Buffer, bytes_per_pixel: u64) -> BufferRange<'a> {
        if bytes_per_pixel == 0 {
            BufferRange::whole(buf)
        } else {
            self.range(buf, bytes_per_pixel)
        }
    }

    /// Workgroups of a per-tile dispatch over the band: one per tile.
    pub fn groups(&self, tiles_x: u32) -> [u32; 3] {
        [tiles_x, self.tile_rows, 1]
    }
}

/// The device limits that size bands, and a test's override of the band height.
#[derive(Clone, Copy, Debug)]
pub struct BandLimits {
    pub max_binding: u64,
    pub offset_alignment: u64,
    /// Tile rows per band, when a test sets it (else as many as fit).
    pub tile_rows: Option<u32>,
}

/// Bands of as many tile rows as fit, covering tile rows `rows`, for buffers of at most
/// `bytes_per_pixel` (a multiple of 4) each; every band's offsets keep the device's
/// alignment.
pub fn bands(
    width: u32,
    height: u32,
    rows: Range<u32>,
    bytes_per_pixel: u64,
    limits: BandLimits,
) -> Result<Vec<Band>> {
    let tile_row_bytes = TILE_SIZE as u64 * width as u64 * bytes_per_pixel.max(4);
    let step = row_step(width, limits.offset_alignment) as u64;
    let fit = limits.max_binding / tile_row_bytes.max(1);
    let per_band = limits
        .tile_rows
        .map_or(fit / step * step, |r| r as u64 * step);
    if per_band == 0 || !(rows.start as u64).is_multiple_of(step) {
        bail!(
            "one row of 16-pixel tiles at width {width} needs {tile_row_bytes} bytes per buffer \
             ({bytes_per_pixel} per pixel), over the device's {}-byte binding limit: use a \
             narrower image or fewer classes",
            limits.max_binding
        );
    }
    let per_band = per_band.min(rows.len().max(1) as u64) as u32;
    Ok(rows
        .clone()
        .step_by(per_band as usize)
        .map(|first| Band {
            first_tile_row: first,
            tile_rows: per_band.min(rows.end - first),
            width,
            height,
        })
        .collect())
}

/// Band starts are multiples of this many tile rows: a band starting at tile row r starts
/// r * 16 * width * (4 k) bytes into a per-pixel buffer of 4 k bytes per pixel, a multiple
/// of 64 * width, so starts at multiples of `step` rows keep every offset aligned.
pub fn row_step(width: u32, offset_alignment: u64) -> u32 {
    let align = offset_alignment.max(1);
    (align / gcd(align, 64 * width as u64)) as u32
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_cover_the_range_once() {
        let all: Vec<Range<u32>> = chunks(1000, 256).collect();
        assert_eq!(all, vec![0..256, 256..512, 512..768, 768..1000]);
        assert_eq!(chunks(0, 256).collect::<Vec<_>>(), vec![0..0]);
        assert_eq!(chunks(256, 256).collect::<Vec<_>>(), vec![0..256]);
    }

    #[test]
    fn chunk_len_fits_the_binding() {
        // SH degree 3: 192 bytes per Gaussian, 128 MiB binding.
        let len = chunk_len(192, 4, 128 << 20).unwrap();
        assert_eq!(len % CHUNK_GRANULE, 0);
        assert!(len as u64 * 192 <= 128 << 20);
        assert!((len as u64 + CHUNK_GRANULE as u64) * 192 > (128 << 20) - 4);
        assert_eq!(chunk_len(1 << 20, 0, 128 << 20), None);
    }

    #[test]
    fn bands_cover_the_rows_and_fit() {
        let limits = BandLimits {
            max_binding: 128 << 20,
            offset_alignment: 256,
            tile_rows: None,
        };
        // 1920x1080 with 64 classes: 256 bytes per pixel, 7.5 MiB per tile row.
        let all = bands(1920, 1080, 0..68, 256, limits).unwrap();
        let rows: u32 = all.iter().map(|b| b.tile_rows).sum();
        assert_eq!(rows, 1080u32.div_ceil(16));
        assert!(all.len() > 1);
        for b in &all {
            assert!(b.tile_rows as u64 * 16 * 1920 * 256 <= 128 << 20);
            assert_eq!((b.first_tile_row as u64 * 16 * 1920 * 4) % 256, 0);
        }
        let small = bands(64, 48, 0..3, 12, limits).unwrap();
        assert_eq!(small.len(), 1);
        assert_eq!(small[0].tile_rows, 3);
        assert!(bands(1 << 20, 16, 0..1, 4096, limits).is_err());
        let part = bands(64, 48, 1..3, 12, limits).unwrap();
        assert_eq!(
            part,
            vec![Band {
                first_tile_row: 1,
                tile_rows: 2,
                width: 64,
                height: 48
            }]
        );
    }
}
