//! Segment consensus numbers the Gaussians in space for its host work, and gives its
//! results back in the scene's numbering.
//!
//! Why: the clustering and the decision read each Gaussian's neighbours (their observation
//! rows, segment ids, adjacency lists, region counts). A trained 3DGS scene lists its
//! Gaussians in no spatial order (its SfM points, then each densification's clones and
//! splits appended), so those reads miss the cache: with a room's Gaussians in random order
//! the consensus's host work took twice as long (docs/robustness-log.md, "The Gaussians'
//! order" and "The Gaussians numbered in space"). Numbered cell by cell of a grid, a
//! Gaussian's neighbours have nearby numbers whatever the scene's order. Within a cell the
//! Gaussians go by position, so the numbering, and with it every tie the consensus breaks by
//! number, does not depend on the scene's order (except between Gaussians at the same
//! position). (The k-d tree of the neighbour search, src/fuse/neighbours.rs, would number
//! them at any density, but a new numbering is a new set of ties: docs/robustness-log.md,
//! "Neighbours in scenes of many scales".)

use std::sync::Arc;

use anyhow::Result;

use super::assign::Assignment;
use super::consensus_decide::Consensus;
use crate::contract::NO_NEIGHBOUR;
use crate::gpu::{Buffer, Gpu};
use crate::util::{gather, map_in_blocks, merge_sorted_runs, parallel_map};

/// A numbering of the scene's Gaussians in space, and its inverse.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SpatialOrder {
    /// Per Gaussian of the scene, its number in space.
    spatial_of_scene: Vec<u32>,
    /// Per number in space, the scene's Gaussian.
    scene_of_spatial: Vec<u32>,
}

impl SpatialOrder {
    /// The Gaussians centered at `means` numbered cell by cell of a grid (cells in scan
    /// order), within a cell by position (x, then y, then z), then by their index in the
    /// scene.
    ///
    /// On every core: the Gaussians sorted by (cell, index) in blocks and merged, then each
    /// cell sorted by position in runs of whole cells. It runs before the views, on the
    /// path of every consensus: on one core it took 63 ms of a million Gaussians on an
    /// H200, most of it a counting sort over the grid's 3.9M cells.
    pub fn of(means: &[[f32; 3]]) -> SpatialOrder {
        let by_position = |&a: &u32, &b: &u32| {
            let (pa, pb) = (means[a as usize], means[b as usize]);
            (0..3)
                .map(|i| pa[i].total_cmp(&pb[i]))
                .fold(std::cmp::Ordering::Equal, std::cmp::Ordering::then)
                .then(a.cmp(&b))
        };
        let cell = cells(means);
        let n = means.len();
        let blocks = parallel_map(n.div_ceil(BLOCK), |b| {
            let mut keys: Vec<u64> = (b * BLOCK..n.min((b + 1) * BLOCK))
                .map(|g| (cell[g] as u64) << 32 | g as u64)
                .collect();
            keys.sort_unstable();
            keys
        });
        let by_cell: Vec<u32> = merge_sorted_runs(blocks)
            .iter()
            .map(|&k| k as u32)
            .collect();
        // Runs of about BLOCK Gaussians, each ending with a cell.
        let mut ends = Vec::new();
        let mut end = 0;
        while end < n {
            end = (end + BLOCK).min(n);
            while end < n && cell[by_cell[end] as usize] == cell[by_cell[end - 1] as usize] {
                end += 1;
            }
            ends.push(end);
        }
        let runs = parallel_map(ends.len(), |r| {
            let start = if r == 0 { 0 } else { ends[r - 1] };
            let mut run = by_cell[start..ends[r]].to_vec();
            let same_cell = |a: &u32, b: &u32| cell[*a as usize] == cell[*b as usize];
            for in_cell in run.chunk_by_mut(same_cell) {
                in_cell.sort_unstable_by(by_position);
            }
            run
        });
        SpatialOrder::from_scene_of_spatial(runs.concat())
    }

    /// The numbering that lists `scene_of_spatial[i]` as number `i` (a permutation of
    /// `0..n`).
    pub fn from_scene_of_spatial(scene_of_spatial: Vec<u32>) -> SpatialOrder {
        let mut spatial_of_scene = vec![u32::MAX; scene_of_spatial.len()];
        for (spatial, &scene) in scene_of_spatial.iter().enumerate() {
            assert_eq!(
                spatial_of_scene[scene as usize],
                u32::MAX,
                "Gaussian {scene} numbered twice"
            );
            spatial_of_scene[scene as usize] = spatial as u32;
        }
        SpatialOrder {
            spatial_of_scene,
            scene_of_spatial,
        }
    }

    pub fn len(&self) -> usize {
        self.scene_of_spatial.len()
    }

    pub fn is_empty(&self) -> bool {
        self.scene_of_spatial.is_empty()
    }

    /// The number in space of the scene's Gaussian `g`.
    pub fn spatial(&self, g: u32) -> u32 {
        self.spatial_of_scene[g as usize]
    }

    /// The scene's Gaussian numbered `s` in space.
    pub fn scene(&self, s: u32) -> u32 {
        self.scene_of_spatial[s as usize]
    }

    /// Each Gaussian's number in space on the GPU ([n] u32): where the observation pass
    /// writes its center pixel, so the observations come numbered in space.
    pub fn upload(&self, gpu: &Gpu) -> Result<Buffer> {
        Ok(gpu.buffer_from("spatial-order", &self.spatial_of_scene)?)
    }

    /// Per-Gaussian values of the scene, listed in space.
    pub fn to_spatial<T: Copy>(&self, scene: &[T]) -> Vec<T> {
        renumbered(scene, &self.scene_of_spatial)
    }

    /// Per-Gaussian values listed in space, in the scene's order.
    pub fn to_scene<T: Copy>(&self, spatial: &[T]) -> Vec<T> {
        renumbered(spatial, &self.spatial_of_scene)
    }

    /// A neighbour graph ([n][k], neighbours by number in space) in the scene's numbering.
    pub fn neighbours_to_scene(&self, knn: &[u32], k: usize) -> Vec<u32> {
        assert_eq!(knn.len(), self.len() * k, "k neighbours per Gaussian");
        let mut out = Vec::with_capacity(knn.len());
        for &s in &self.spatial_of_scene {
            let row = &knn[s as usize * k..(s as usize + 1) * k];
            out.extend(row.iter().map(|&h| match h {
                NO_NEIGHBOUR => NO_NEIGHBOUR,
                h => self.scene_of_spatial[h as usize],
            }));
        }
        out
    }

    /// A consensus decided on the Gaussians numbered in space, in the scene's numbering:
    /// the per-Gaussian results reordered; the segments (numbered by their members in
    /// space) and the totals as they are.
    pub fn consensus_to_scene(&self, spatial: Consensus) -> Consensus {
        let evidence = Arc::unwrap_or_clone(spatial.evidence);
        Consensus {
            assignment: Assignment {
                class: self.to_scene(&spatial.assignment.class),
                confidence: self.to_scene(&spatial.assignment.confidence),
            },
            entropy: self.to_scene(&spatial.entropy),
            segment: self.to_scene(&spatial.segment),
            evidence: Arc::new(evidence.reordered(|g| self.spatial(g as u32) as usize)),
            ..spatial
        }
    }
}

/// `values[at[i]]` for each i: a value per Gaussian, renumbered.
fn renumbered<T: Copy>(values: &[T], at: &[u32]) -> Vec<T> {
    assert_eq!(values.len(), at.len(), "a value per Gaussian");
    gather(values, at, 1)
}

/// Cells per Gaussian at most in [`cells`] (a bound from when each cell cost a 4-byte
/// start; kept, since the cells set the numbering and with it the consensus's ties).
const MAX_CELLS_PER_GAUSSIAN: f64 = 4.0;

/// Gaussians a block of [`SpatialOrder::of`]'s passes on every core holds.
const BLOCK: usize = 1 << 16;

/// Each Gaussian's cubic cell, cells numbered in scan order: the numbering's coarse order.
fn cells(means: &[[f32; 3]]) -> Vec<u32> {
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    for m in means {
        for i in 0..3 {
            lo[i] = lo[i].min(m[i] as f64);
            hi[i] = hi[i].max(m[i] as f64);
        }
    }
    // The cell sizes the neighbour search's grid had (the numbering, and with it the
    // consensus's ties, unchanged since the search moved to a k-d tree). Surfaces
    // dominate: about 4 Gaussians per occupied cell when spread over the bounding box's
    // largest face. But at most `MAX_CELLS_PER_GAUSSIAN` cells per Gaussian: Gaussians
    // filling a volume (a random scene) would otherwise get far more cells than
    // Gaussians, mostly empty, each a 4-byte start.
    let ext: Vec<f64> = (0..3).map(|i| (hi[i] - lo[i]).max(1e-6)).collect();
    let mut faces = [ext[0] * ext[1], ext[1] * ext[2], ext[0] * ext[2]];
    faces.sort_by(f64::total_cmp);
    let n = means.len() as f64;
    let surface_cell = (faces[2] * 4.0 / n).sqrt();
    let volume_cell = (ext[0] * ext[1] * ext[2] / (n * MAX_CELLS_PER_GAUSSIAN)).cbrt();
    // Gaussians along a line (a flat box's extent is ~0 in two axes) would get cells far
    // finer than their spacing.
    let line_cell = ext.iter().copied().fold(0.0, f64::max) * 4.0 / n;
    let cell = surface_cell.max(volume_cell).max(line_cell).max(1e-6);
    let dims = [0, 1, 2].map(|i| ((ext[i] / cell).floor() as i64 + 1).min(1 << 20));
    let cell_of = |m: [f32; 3]| {
        let c = [0, 1, 2]
            .map(|i| (((m[i] as f64 - lo[i]) / cell).floor() as i64).clamp(0, dims[i] - 1));
        ((c[2] * dims[1] + c[1]) * dims[0] + c[0]) as u32
    };
    map_in_blocks(means.len(), BLOCK, |g| cell_of(means[g]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuse::neighbours::nearest_neighbours;
    use crate::util::Rng;

    /// Random centers (distinct distances: no ties) and the same centers shuffled.
    fn shuffled_centers(n: usize) -> (Vec<[f32; 3]>, Vec<u32>) {
        let mut rng = Rng::new(11);
        let means: Vec<[f32; 3]> = (0..n)
            .map(|_| [0, 1, 2].map(|_| rng.range_f64(-2.0, 2.0) as f32))
            .collect();
        let mut shuffle: Vec<u32> = (0..n as u32).collect();
        rng.shuffle(&mut shuffle);
        (means, shuffle)
    }

    /// The numbering depends on the positions only: the same centers in another order are
    /// listed in space at the same positions.
    #[test]
    fn the_numbering_follows_the_positions_not_the_order() {
        let (means, shuffle) = shuffled_centers(5000);
        let shuffled: Vec<[f32; 3]> = shuffle.iter().map(|&g| means[g as usize]).collect();
        let (a, b) = (SpatialOrder::of(&means), SpatialOrder::of(&shuffled));
        assert_eq!(a.to_spatial(&means), b.to_spatial(&shuffled));
        assert_ne!(
            a.to_spatial(&means),
            means,
            "the numbering is not the scene's"
        );
    }

    /// A lattice on two walls, shuffled: the Gaussians share coordinates (every one of a
    /// wall the same x or z, as the synthetic rooms' walls do), and each has several
    /// neighbours at one distance.
    fn lattice_shuffled() -> Vec<[f32; 3]> {
        let mut means = vec![];
        for i in 0..30 {
            for j in 0..30 {
                let (a, b) = (i as f32 * 0.125, j as f32 * 0.125);
                means.extend([[0.0, a, b], [a, b, 4.0]]);
            }
        }
        Rng::new(3).shuffle(&mut means);
        means
    }

    /// The numbering on every core equals its definition sorted on one: by cell (scan
    /// order), then position, then index; over several blocks, with Gaussians sharing
    /// positions and cells of many Gaussians (a lattice's walls).
    #[test]
    fn the_numbering_is_cells_then_positions_then_indices() {
        let (mut means, _) = shuffled_centers(3 * BLOCK);
        means.extend(lattice_shuffled());
        means.extend(lattice_shuffled());
        let cell = cells(&means);
        let mut expected: Vec<u32> = (0..means.len() as u32).collect();
        expected.sort_by(|&a, &b| {
            let (pa, pb) = (means[a as usize], means[b as usize]);
            (cell[a as usize].cmp(&cell[b as usize]))
                .then((0..3).fold(std::cmp::Ordering::Equal, |o, i| {
                    o.then(pa[i].total_cmp(&pb[i]))
                }))
                .then(a.cmp(&b))
        });
        let indices: Vec<u32> = (0..means.len() as u32).collect();
        assert_eq!(SpatialOrder::of(&means).to_spatial(&indices), expected);
    }

    /// Gaussians sharing coordinates are numbered by position too, not by their order.
    #[test]
    fn the_numbering_of_shared_coordinates_follows_the_positions() {
        let means = lattice_shuffled();
        let mut reversed = means.clone();
        reversed.reverse();
        assert_eq!(
            SpatialOrder::of(&means).to_spatial(&means),
            SpatialOrder::of(&reversed).to_spatial(&reversed)
        );
    }

    /// The neighbours searched on the centers listed in space, given back in the scene's
    /// numbering, are the neighbours searched on the scene's centers.
    #[test]
    fn neighbours_found_in_space_map_back_to_the_scenes() {
        let (means, _) = shuffled_centers(3000);
        let order = SpatialOrder::of(&means);
        let k = 6;
        let in_space = nearest_neighbours(&order.to_spatial(&means), k);
        assert_eq!(
            order.neighbours_to_scene(&in_space, k),
            nearest_neighbours(&means, k)
        );
    }
}
