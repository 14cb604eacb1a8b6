//! `--relabel`'s footprints: FlashSplat's weights of each view, kept per (Gaussian, label
//! region) by the consensus's observation pass, so the relabeled views need no second walk.
//!
//! Why: `--relabel` relabels each view's connected label regions with the consensus classes
//! and then sums FlashSplat's weights over the relabeled views. A region's new class is
//! known only once the consensus has seen every view, but the weights a Gaussian takes in
//! a view do not depend on it, only on which region each pixel lies in. So the observation
//! pass walks each view's tile lists as FlashSplat does (fuse/region_footprint.comp, which
//! also writes the median depth the occlusion test reads: the pass keeps one walk, not
//! two), adding each pixel's weight per (list entry, the pixel's region among its tile's);
//! the host folds the entries into (Gaussian, region) sums, and once the regions are
//! relabeled, each sum adds to its Gaussian's row of its region's class. The sums are the
//! integers FlashSplat's fixed-point accumulation over the relabeled views gives, bit for
//! bit. A view binned in several bands of tile rows (whose lists reuse one buffer), whose
//! sums would pass [`FOOTPRINT_DEVICE_MAX`], or past the host's budget for footprints
//! ([`FOOTPRINT_BYTES_MAX`]) is walked again on its relabeled labels instead. Kept only on
//! devices that take the CPU drivers' forms ([`footprints_for`]): on a GPU walking again is
//! the cheaper.
//!
//! Tried first, and measured slower on lavapipe: per-Gaussian slots claimed by
//! compare-and-swap on the region id (docs/robustness-log.md). Addressed by list entry, a sum
//! belongs to one tile's workgroup and needs no search.

use anyhow::{ensure, Result};

use super::accumulate::{
    accumulate_by_gaussian, label_threads, record_contrib_walk, Accumulation, ContribWalk,
    FuseConfig, FuseStats, LabelSource, CONTRIB_CARRY_BYTES, LABELS_AHEAD, NO_LABEL,
};
use super::consensus::ConsensusInput;
use super::method::Method;
use super::partial::fixed_to_f64;
use super::shared_counts::SumsByGaussian;
use crate::contract::TILE_SIZE;
use crate::gpu::kernel_table::ids;
use crate::gpu::staging::grown;
use crate::gpu::{Buffer, Gpu, Recorder};
use crate::render::rasterizer::{OcclusionDepths, TileLists};
use crate::render::Rasterizer;
use crate::scene::Camera;
use crate::util::prefetch_ordered;

/// Host bytes the kept footprints may take: past it, the further views are walked again.
/// A footprint takes 16 bytes; a room's view at 320x240 holds tens of thousands.
pub const FOOTPRINT_BYTES_MAX: usize = 1 << 30;

/// Device bytes a view's per-entry sums may take (list entries times the most regions a
/// tile holds, 8 bytes each); a view past it is walked again.
pub const FOOTPRINT_DEVICE_MAX: u64 = 1 << 29;

/// One Gaussian's weights in one label region of one view: FlashSplat's fixed-point sum
/// (weight * 2^32) over the region's pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Footprint {
    pub gaussian: u32,
    /// The region's id: the index of its first pixel (`label_regions`).
    pub region: u32,
    pub amount: u64,
}

/// What the observation pass kept of one view.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ViewFootprints {
    /// The view's footprints, by Gaussian and region (none for a view without labels).
    Kept(Vec<Footprint>),
    /// The view is walked again on its relabeled labels ([`FootprintTable::read`]).
    WalkAgain,
}

/// A view's label regions tile by tile: per pixel the index of its region among its
/// tile's (NO_LABEL: unlabeled), per tile its regions' ids, and the most any tile holds.
pub struct TileRegions {
    pub local: Vec<u32>,
    /// Tile `t`'s region ids: `ids[starts[t]..starts[t + 1]]`, tiles in row order.
    ids: Vec<u32>,
    starts: Vec<u32>,
    pub rows: u32,
}

impl TileRegions {
    /// `regions` (per pixel of a view `width` pixels wide; NO_LABEL: unlabeled) by tile.
    pub fn of(regions: &[u32], width: usize) -> TileRegions {
        let tile = TILE_SIZE as usize;
        let height = regions.len() / width.max(1);
        let tiles_x = width.div_ceil(tile);
        let tiles = tiles_x * height.div_ceil(tile);
        let mut local = vec![NO_LABEL; regions.len()];
        let (mut ids, mut starts, mut rows) = (Vec::new(), vec![0u32], 0);
        for t in 0..tiles {
            let (x0, y0) = ((t % tiles_x) * tile, (t / tiles_x) * tile);
            let first = ids.len();
            for y in y0..(y0 + tile).min(height) {
                for p in y * width + x0..y * width + (x0 + tile).min(width) {
                    if regions[p] == NO_LABEL {
                        continue;
                    }
                    // A tile holds few regions: a linear search beats a map.
                    let at = match ids[first..].iter().position(|&r| r == regions[p]) {
                        Some(at) => at,
                        None => {
                            ids.push(regions[p]);
                            ids.len() - first - 1
                        }
                    };
                    local[p] = at as u32;
                }
            }
            rows = rows.max(ids.len() - first);
            starts.push(ids.len() as u32);
        }
        TileRegions {
            local,
            ids,
            starts,
            rows: rows.max(1) as u32,
        }
    }

    fn of_tile(&self, t: usize) -> &[u32] {
        &self.ids[self.starts[t] as usize..self.starts[t + 1] as usize]
    }
}

/// A lane's device side: one view's per-entry sums at a time, and the per-pixel inputs of
/// its walk.
#[derive(Default)]
pub struct FootprintTable {
    /// [rows][stride] fixed-point sums, a row per region of a tile (its entries, in the
    /// order of the lists, side by side).
    sums: Option<Buffer>,
    /// Entries a row of `sums` holds: the lists' capacity when it was allocated.
    stride: u64,
    /// What of `sums` the last read view added to, (rows, entries): zeroed before the next
    /// view instead of all of it (the lists' capacity is many times what a view uses).
    /// None: unknown (a new buffer), zeroed whole.
    dirty: Option<(u64, u64)>,
    /// Per pixel, the index of its region among its tile's (staged on the host, copied in
    /// the view's own submission), and the walk's carried state.
    staged: Option<Buffer>,
    local: Option<Buffer>,
    carry: Option<Buffer>,
    /// Bytes of the view's staged indices.
    local_bytes: u64,
    /// The view's most regions in a tile, and whether its walk keeps sums the host can read
    /// (one band of tile rows, within [`FOOTPRINT_DEVICE_MAX`]).
    rows: u32,
    kept: bool,
}

impl FootprintTable {
    /// Stages the view's tile-local region indices for its walk (copied to the device by
    /// [`FootprintTable::record_walk`], in the view's submission: no upload of its own).
    pub fn stage_regions(&mut self, gpu: &Gpu, tiles: &TileRegions) -> Result<()> {
        let pixels = tiles.local.len().max(1) as u64;
        if self.local.as_ref().is_none_or(|b| b.size() < pixels * 4) {
            self.local = Some(gpu.buffer("footprint-regions", pixels * 4)?);
            self.carry = Some(gpu.buffer("footprint-carry", pixels * CONTRIB_CARRY_BYTES)?);
        }
        self.local_bytes = std::mem::size_of_val(tiles.local.as_slice()) as u64;
        grown(&mut self.staged, gpu, self.local_bytes, Gpu::staging_buffer)?
            .write_mapped(&tiles.local);
        self.rows = tiles.rows;
        Ok(())
    }

    /// Records the view's walk over the binned `tiles` (band 0 first zeroes what the sums
    /// hold and `depth`): the sums per (region, entry) added, the median depth written into
    /// `depth`. Every attempt at the view records it again (one whose lists overflowed adds
    /// nothing: the kernel reads the binning's status). A view in several bands, or whose
    /// sums would pass [`FOOTPRINT_DEVICE_MAX`], gets its median depth alone.
    pub fn record_walk(
        &mut self,
        rec: &mut Recorder,
        tiles: &TileLists,
        depths: OcclusionDepths,
    ) -> Result<()> {
        let (Some(staged), Some(local), Some(carry)) = (&self.staged, &self.local, &self.carry)
        else {
            anyhow::bail!("a footprint walk without the view's regions staged");
        };
        if tiles.band() == 0 {
            // Every band reads the whole view's indices.
            rec.copy(staged, 0, local, 0, self.local_bytes);
            let capacity = tiles.isect_ids().size() / 4;
            let bytes = self.rows as u64 * capacity * 8;
            self.kept = tiles.is_last_band() && bytes <= FOOTPRINT_DEVICE_MAX;
            let fits = |b: &Buffer| self.stride == capacity && b.size() >= bytes;
            if self.kept && !self.sums.as_ref().is_some_and(fits) {
                self.sums = Some(rec.gpu().buffer("footprint-sums", bytes.max(8))?);
                (self.stride, self.dirty) = (capacity, None);
            }
            if let Some(sums) = self.sums.as_ref().filter(|_| self.kept) {
                match self.dirty {
                    None => rec.fill(sums, 0, sums.size(), 0),
                    Some((rows, entries)) => {
                        (0..rows).for_each(|r| rec.fill(sums, r * self.stride * 8, entries * 8, 0))
                    }
                }
                self.dirty = Some((0, 0));
            }
            for depth in [depths.median, depths.opaque] {
                rec.fill(depth, 0, depth.size(), 0);
            }
            rec.barrier();
        }
        let Some(sums) = self.sums.as_ref().filter(|_| self.kept) else {
            // Not kept: the median depth alone.
            return tiles.record_median_depth(rec);
        };
        let kernel =
            ids::FUSE_REGION_FOOTPRINT.for_device(ids::FUSE_REGION_FOOTPRINT_WIDE, rec.gpu());
        let walk = ContribWalk {
            kernel,
            labels: local,
            carry,
            contrib_addr: sums.address_words(8)?,
            rows: (0, self.rows),
            center_only: false,
            per_view: false,
            depths: Some(depths),
        };
        // The kernel's `n` is the rows' stride.
        record_contrib_walk(rec, tiles, self.stride as u32, &walk)
    }

    /// The view's footprints once its walk ran over `raster`'s lists, by Gaussian and
    /// region (`regions`: the view's, as staged), or [`ViewFootprints::WalkAgain`] where
    /// its sums were not kept.
    pub fn read(&mut self, raster: &Rasterizer, regions: &TileRegions) -> Result<ViewFootprints> {
        let Some(sums) = self.sums.as_ref().filter(|_| self.kept) else {
            return Ok(ViewFootprints::WalkAgain);
        };
        let gpu = raster.gpu();
        let (ranges, isect_ids) = raster.last_tile_lists();
        let ranges: Vec<[u32; 2]> = gpu.download(ranges, 0, regions.starts.len() - 1)?;
        let entries = ranges.iter().map(|r| r[1]).max().unwrap_or(0) as u64;
        let rows = self.rows as u64;
        self.dirty = Some((rows, entries));
        let mut wanted = vec![(isect_ids, 0, entries * 4)];
        wanted.extend((0..rows).map(|r| (sums, r * self.stride * 8, entries * 8)));
        let read = gpu.download_many(&wanted)?;
        let gaussians: Vec<u32> = bytemuck::pod_collect_to_vec(&read[0]);
        let sums: Vec<Vec<u64>> = read[1..]
            .iter()
            .map(|row| bytemuck::pod_collect_to_vec(row))
            .collect();
        let mut kept = Vec::new();
        for (t, range) in ranges.iter().enumerate() {
            for (row, &region) in sums.iter().zip(regions.of_tile(t)) {
                for entry in range[0] as usize..range[1] as usize {
                    if row[entry] != 0 {
                        let (gaussian, amount) = (gaussians[entry], row[entry]);
                        kept.push(Footprint {
                            gaussian,
                            region,
                            amount,
                        });
                    }
                }
            }
        }
        Ok(ViewFootprints::Kept(merged(&mut kept)))
    }
}

/// `footprints` with each (Gaussian, region)'s sums added into one (a Gaussian's entries in
/// several tiles), in Gaussian and region order.
fn merged(footprints: &mut [Footprint]) -> Vec<Footprint> {
    footprints.sort_unstable_by_key(|f| (f.gaussian, f.region));
    let mut out: Vec<Footprint> = Vec::with_capacity(footprints.len());
    for f in footprints.iter() {
        match out.last_mut() {
            Some(last) if (last.gaussian, last.region) == (f.gaussian, f.region) => {
                last.amount += f.amount;
            }
            _ => out.push(*f),
        }
    }
    // Held until the consensus has decided: not at the unmerged length.
    out.shrink_to_fit();
    out
}

/// Whether `--relabel` keeps footprints with `cfg` on `gpu`: the footprints are fixed-point
/// sums, FlashSplat's only where it sums in fixed point too; and only where the device takes
/// the CPU drivers' forms (`DeviceCaps::cpu_forms`). There a walk of the lists is most of a
/// view's time and a download is a copy in the same memory. On a GPU a second binning and
/// walk costs what FlashSplat's pass does a view (2.2-2.7 ms at 1080p for the million-
/// Gaussian room on an H100), less than reading the sums over the bus (8 bytes an entry
/// and region row: tens of MB a view there) and folding them on one host thread.
pub fn footprints_for(cfg: &FuseConfig, gpu: &Gpu) -> bool {
    cfg.accumulation == Accumulation::FixedPoint && gpu.caps().cpu_forms
}

/// FlashSplat's footprints over the relabeled views `relabeled`, per Gaussian by class (the
/// `classes` the relabeling gives): each kept view's footprints added to their region's
/// relabeled class (read from the relabeled map at the region's first pixel), the views
/// kept as [`ViewFootprints::WalkAgain`] accumulated by FlashSplat's pass over their
/// relabeled labels. `progress` gets (views done, views). The same sums as FlashSplat's
/// accumulation over all of `relabeled` (with fixed point, bit for bit).
pub fn relabeled_footprints(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    relabeled: &dyn LabelSource,
    classes: usize,
    kept: &[ViewFootprints],
    mut progress: impl FnMut(usize, usize),
) -> Result<(SumsByGaussian<f64>, FuseStats)> {
    let start = std::time::Instant::now();
    let (n, views) = (input.scene.n as usize, input.cams.len());
    ensure!(
        kept.len() == views,
        "footprints of {} views for {views}",
        kept.len()
    );
    let mut sums = SumsByGaussian::<u64>::new(n);
    let kept_map = |view: usize| match &kept[view] {
        ViewFootprints::Kept(f) if !f.is_empty() => relabeled.labels(view, &input.cams[view]),
        _ => Ok(None),
    };
    prefetch_ordered(
        views,
        label_threads(),
        LABELS_AHEAD,
        kept_map,
        |view, map| {
            progress(view, views);
            let (Some(map), ViewFootprints::Kept(footprints)) = (map, &kept[view]) else {
                return Ok(());
            };
            for f in footprints {
                let class = map.get(f.region as usize).copied().unwrap_or(u32::MAX) as usize;
                ensure!(
                    class < classes,
                    "view {}: region {} relabeled to {class}, past the {classes} rows",
                    input.cams[view].name,
                    f.region
                );
                sums.add(f.gaussian as usize, class as u32, f.amount);
            }
            Ok(())
        },
    )?;
    // Both exact in f64 (sums far under 2^53 units of 2^-32): the sum of the two is the
    // conversion of the integers' sum.
    let mut sums = sums.map(fixed_to_f64);
    let mut stats = match kept.contains(&ViewFootprints::WalkAgain) {
        true => {
            let again = WalkedAgain { relabeled, kept };
            let (walked, stats) = flashsplat_pass(input, cfg, &again, classes, |_, _| {})?;
            sums.add_all(walked);
            stats
        }
        // One pass of every row, over no view.
        false => FuseStats {
            passes: 1,
            rows_per_pass: classes,
            ..Default::default()
        },
    };
    stats.views = views;
    stats.view_s = start.elapsed().as_secs_f64();
    stats.walked_again = kept
        .iter()
        .filter(|k| **k == ViewFootprints::WalkAgain)
        .count();
    progress(views, views);
    Ok((sums, stats))
}

/// FlashSplat's accumulation of `labels` (`rows` classes) over the input's views, per
/// Gaussian by class, with `cfg`'s other settings: the relabeled views walked again.
pub(crate) fn flashsplat_pass(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    labels: &dyn LabelSource,
    rows: usize,
    progress: impl FnMut(usize, usize),
) -> Result<(SumsByGaussian<f64>, FuseStats)> {
    let flashsplat = FuseConfig {
        method: Method::FlashSplat,
        ..cfg.clone()
    };
    let (gpu, scene, cams) = (input.gpu, input.scene, input.cams);
    accumulate_by_gaussian(gpu, scene, cams, labels, rows, &flashsplat, progress)
}

/// The relabeled views whose footprints were not kept; the others without labels.
struct WalkedAgain<'a> {
    relabeled: &'a dyn LabelSource,
    kept: &'a [ViewFootprints],
}

impl LabelSource for WalkedAgain<'_> {
    fn labels(&self, view: usize, cam: &Camera) -> Result<Option<Vec<u32>>> {
        match self.kept[view] {
            ViewFootprints::WalkAgain => self.relabeled.labels(view, cam),
            ViewFootprints::Kept(_) => Ok(None),
        }
    }

    fn before_view(&self, view: usize) -> Result<()> {
        self.relabeled.before_view(view)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::Rng;

    /// Every labeled pixel's tile-local index names its region among its tile's, each tile
    /// lists its regions once, and `rows` is the most any tile lists; unlabeled pixels have
    /// none. A width and height that are no multiple of the tile, blobs of a few labels.
    #[test]
    fn tile_regions_index_each_tiles_regions() {
        let (width, height, mut rng) = (37, 29, Rng::new(3));
        let regions: Vec<u32> = (0..width * height)
            .map(|p| match rng.bool(0.1) {
                true => NO_LABEL,
                false => ((p % width) / 5 + 7 * ((p / width) / 6)) as u32 * 11,
            })
            .collect();
        let tiles = TileRegions::of(&regions, width);
        let tile = TILE_SIZE as usize;
        let tiles_x = width.div_ceil(tile);
        let mut most = 0;
        for t in 0..tiles_x * height.div_ceil(tile) {
            let ids = tiles.of_tile(t);
            let mut distinct = ids.to_vec();
            distinct.sort_unstable();
            distinct.dedup();
            assert_eq!(distinct.len(), ids.len(), "tile {t} lists a region twice");
            most = most.max(ids.len());
        }
        assert_eq!(tiles.rows as usize, most);
        assert!(most > 2);
        for (p, &region) in regions.iter().enumerate() {
            let t = (p / width) / tile * tiles_x + (p % width) / tile;
            match region {
                NO_LABEL => assert_eq!(tiles.local[p], NO_LABEL),
                _ => assert_eq!(
                    tiles.of_tile(t)[tiles.local[p] as usize],
                    region,
                    "pixel {p}"
                ),
            }
        }
    }
}
