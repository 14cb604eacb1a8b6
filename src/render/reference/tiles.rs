//! Tile binning: every (tile, Gaussian) pair whose covered pixel range touches the tile,
//! ordered by tile, then depth, then Gaussian id.

use super::project::ProjectedGaussian;
use crate::scene::Camera;

/// Tiles are `TILE_SIZE x TILE_SIZE` pixels.
pub const TILE_SIZE: u32 = 16;

/// `(tiles_x, tiles_y)` for a camera: `ceil(width / 16)`, `ceil(height / 16)`.
pub fn tile_grid(cam: &Camera) -> (u32, u32) {
    (
        cam.width.div_ceil(TILE_SIZE),
        cam.height.div_ceil(TILE_SIZE),
    )
}

/// All `(tile id, Gaussian id)` intersections, tile id `ty * tiles_x + tx`, sorted by tile,
/// then depth ascending, then Gaussian id ascending.
pub fn tile_intersections(projected: &[ProjectedGaussian], cam: &Camera) -> Vec<(u32, u32)> {
    let (tiles_x, _) = tile_grid(cam);
    let mut keyed: Vec<(u32, f64, u32)> = Vec::new();
    for p in projected {
        for tile in p.tile_range.tile_ids(tiles_x) {
            keyed.push((tile, p.depth, p.id));
        }
    }
    keyed.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)).then(a.2.cmp(&b.2)));
    keyed.into_iter().map(|(t, _, id)| (t, id)).collect()
}

/// For each of `num_tiles` tiles, the half-open range `[start, end)` of its entries in
/// `intersections` (which must be sorted by tile); empty tiles get `start == end`.
pub fn tile_ranges(intersections: &[(u32, u32)], num_tiles: u32) -> Vec<[u32; 2]> {
    let mut ranges = vec![[0u32; 2]; num_tiles as usize];
    let mut start = 0usize;
    for tile in 0..num_tiles {
        let mut end = start;
        while end < intersections.len() && intersections[end].0 == tile {
            end += 1;
        }
        ranges[tile as usize] = [start as u32, end as u32];
        start = end;
    }
    assert_eq!(
        start,
        intersections.len(),
        "intersections are not sorted by tile, or name a tile >= {num_tiles}"
    );
    ranges
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_cover_sorted_lists() {
        let isect = [(0, 5), (0, 2), (2, 1), (3, 0), (3, 4)];
        assert_eq!(
            tile_ranges(&isect, 5),
            vec![[0, 2], [2, 2], [2, 3], [3, 5], [5, 5]]
        );
        assert_eq!(tile_ranges(&[], 2), vec![[0, 0], [0, 0]]);
    }

    #[test]
    #[should_panic]
    fn ranges_reject_unsorted() {
        tile_ranges(&[(1, 0), (0, 0)], 2);
    }
}
