//! Splitting per-Gaussian passes into chunks whose buffer ranges each fit one binding
//! (`maxStorageBufferRange`, 128 MiB on lavapipe): a scene's SH coefficients alone pass it
//! at ~700k Gaussians of degree 3, while the device may well hold the scene.

use std::ops::Range;

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
}
