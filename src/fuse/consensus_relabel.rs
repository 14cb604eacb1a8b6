//! Relabeled FlashSplat (`--method segment-consensus --relabel`): segment consensus decides
//! what each object is, FlashSplat's pixel footprints decide where its edges are.
//!
//! Why: flicker relabels a whole object in a view but leaves its label edges where they
//! were, and FlashSplat, which weighs each Gaussian by the pixels it covers, places edges
//! better than any decision from a Gaussian's center (an edge Gaussian renders as the class
//! it covers most). So every view's connected label regions are relabeled with the class
//! the consensus gave the Gaussians observed inside them, and FlashSplat runs on the
//! relabeled views. A region whose observed Gaussians split between classes (a view in
//! which flicker gave two touching objects one class, so their regions merged) says
//! nothing about where their edge is: it is left unlabeled in that view, unless the
//! centers of its own label, with those of other classes lying near a pixel of their
//! class, make up the share a class needs (boundary noise, below:
//! [`RelabelRule::keep_share`]), or its Gaussians are of classes the scene's views hardly
//! ever take for its label, so that the label cannot be their flicker
//! ([`RelabelRule::max_edge_confusion`]). Nor is a region relabeled to a class the view
//! labels beside it, an edge the segmenter drew ([`decide_regions`]). A region no Gaussian
//! center was observed in keeps its label.

use std::cmp::Reverse;
use std::sync::{Arc, Mutex};

use anyhow::Result;
use serde::Serialize;

use super::accumulate::{FuseConfig, FuseStats, LabelSource, NO_LABEL};
use super::assign::{assign_counts_near, Assignment};
use super::consensus::{consensus_run, ConsensusInput, ConsensusLift, Kept};
use super::consensus_confusion::ConfusionRates;
use super::consensus_decide::{posteriors, unseen_without_confidence, ConsensusParams};
use super::consensus_footprints::{
    flashsplat_pass, footprints_for, relabeled_footprints, ViewFootprints,
};
use super::consensus_segments::{four_neighbours, label_regions, region_edges};
use super::regions_gpu::{RegionFinder, RegionStats};
use super::shared_counts::{SharedCounts, SumsByGaussian};
use crate::contract::RELABEL_KEEP;
use crate::gpu::timings::KernelTotal;
use crate::scene::Camera;

/// How a view's label regions take the consensus classes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RelabelRule {
    /// A region takes one class where that class holds at least this share (> 0.5) of the
    /// observed Gaussians' centers that decide ([`RelabelRule::depth`]) and the view does not
    /// label that class beside the region ([`decide_regions`]); else the region is
    /// unlabeled in that view: flicker gave two touching objects one class there and merged
    /// their regions, so the region says nothing of where their edge runs. Its pixels then
    /// count for the consensus class of whichever Gaussian renders there
    /// ([`fold_undecided`]), so an undecided region costs little, and the share can ask
    /// for more than a relabeled region whose edge is wrong would give.
    pub min_share: f64,
    /// The centers at least this many pixels (city-block, within the region) from the
    /// region's edge decide; in a region with none that deep, its deepest ones. A label edge
    /// a segmenter drew a few pixels off puts a neighbour's Gaussians just inside the
    /// region, where a flicker merge puts the other object's deep inside: counting only
    /// deep centers keeps the shifted region labeled and still finds the merge.
    pub depth: u32,
    /// A region no class holds `min_share` of keeps its own label where that label holds
    /// at least this share of its deciding centers and, with the centers of other classes
    /// that lie within `near` pixels of a pixel labeled their class, `min_share` of them;
    /// else it is unlabeled. Boundary noise shifts a label edge by a few pixels: a small or
    /// thin object (a lamp, a cup) loses part of its region to its neighbours and takes
    /// part of theirs, so its remnant regions hold its neighbours' Gaussians, each a few
    /// pixels from a pixel labeled with its neighbour's class; unlabeling those regions
    /// would take away the only views that still show it. In a flicker merge (two touching
    /// objects given one class) the flickered object's Gaussians fill its whole extent,
    /// most of them far from any pixel of their class, which flicker took from this view.
    pub keep_share: f64,
    /// How near (city-block pixels) a center of another class must lie to a pixel labeled
    /// its class to count for its region's own label ([`RelabelRule::keep_share`]), and to
    /// count as seen beside the region, which then does not take its class
    /// ([`decide_regions`]). The default, 8, forgives label edges moved by up to 4 pixels
    /// along each axis.
    pub near: u32,
    /// A Gaussian whose footprint over the relabeled views sums to fewer pixels keeps its
    /// consensus class.
    pub min_mass: f64,
    /// A region no class takes keeps its own label where the centers of classes the
    /// scene's views call by that label more often than this (the consensus's
    /// [`ConfusionRates`], from its clearly decided segments) are under `1 - min_share` of
    /// its deciding ones. The label cannot then be those objects' flicker, so the region is
    /// an edge drawn a few pixels off and its pixels are right where the label says: under
    /// boundary noise (living room, seed 1) the eroded lamps' regions held Gaussians the
    /// consensus had given the wall, and left undecided they gave those pixels to the wall.
    /// Under flicker 0.3 a look-alike is called so in 5-27% of the views, other classes in
    /// under 2%. 0: never.
    pub max_edge_confusion: f64,
}

/// A label source whose views come relabeled region by region ([`RelabelRule`]).
pub struct RelabeledViews<'a> {
    pub inner: &'a dyn LabelSource,
    /// Per view, (Gaussian, pixel under its center) of every observation.
    pub centers: &'a [Vec<(u32, u32)>],
    /// Consensus class per Gaussian.
    pub class: &'a [Option<usize>],
    pub rule: RelabelRule,
    /// The consensus's class confusions ([`RelabelRule::max_edge_confusion`]).
    pub confusions: &'a ConfusionRates,
    /// Relabels on the GPU ([`RegionFinder::relabel`]; one view at a time: the label
    /// source is read from several worker threads); None: on the host ([`relabel_view`]).
    pub finder: Option<Mutex<RegionFinder<'a>>>,
    /// The label given to the pixels the relabeling left undecided (labeled before,
    /// unlabeled after): a channel past the classes, which [`fold_undecided`] counts for
    /// each Gaussian's own consensus class. None leaves them unlabeled.
    pub undecided: Option<u32>,
}

impl LabelSource for RelabeledViews<'_> {
    fn labels(&self, view: usize, cam: &Camera) -> Result<Option<Vec<u32>>> {
        let Some(labels) = self.inner.labels(view, cam)? else {
            return Ok(None);
        };
        let seeds = self.centers.get(view).map_or(&[][..], |c| c.as_slice());
        let seeds = seeds
            .iter()
            .filter_map(|&(g, p)| self.class[g as usize].map(|c| (p, c as u32)));
        let mut map = match &self.finder {
            Some(finder) => {
                let seeds: Vec<(u32, u32)> = seeds.collect();
                let mut finder = finder.lock().unwrap_or_else(|e| e.into_inner());
                finder.relabel(&labels, cam.width, &seeds, &self.rule, self.confusions)?
            }
            None => {
                let mut map = labels.clone();
                relabel_view(
                    &mut map,
                    cam.width as usize,
                    seeds,
                    &self.rule,
                    self.confusions,
                );
                map
            }
        };
        if let Some(undecided) = self.undecided {
            // Only the relabeling's unlabeled pixels: the view's own (an ignore id) stay so.
            for (label, &before) in map.iter_mut().zip(&labels) {
                if *label == NO_LABEL && before != NO_LABEL {
                    *label = undecided;
                }
            }
        }
        Ok(Some(map))
    }

    fn before_view(&self, view: usize) -> Result<()> {
        self.inner.before_view(view)
    }
}

/// Relabels `map` (one view, `width` pixels a row) from `seeds`, the (pixel, class) of the
/// observed Gaussians' centers: a region takes the class holding `rule.min_share` of its
/// deciding seeds (those at least `rule.depth` pixels inside it, else its deepest) where
/// the view does not label that class beside it ([`decide_regions`]), is unlabeled where
/// none does (unless it keeps its label by [`RelabelRule::keep_share`] or
/// [`RelabelRule::max_edge_confusion`]), and keeps its label where no seed lies. The host
/// version of [`RegionFinder::relabel`](super::regions_gpu::RegionFinder::relabel).
pub fn relabel_view(
    map: &mut [u32],
    width: usize,
    seeds: impl Iterator<Item = (u32, u32)>,
    rule: &RelabelRule,
    confusions: &ConfusionRates,
) {
    let regions = label_regions(map, width);
    let depth = edge_depth(&regions, width, rule.depth);
    let seeds: Vec<RegionSeed> = seeds
        .filter(|&(p, _)| regions[p as usize] != NO_LABEL)
        .map(|(p, c)| RegionSeed {
            region: regions[p as usize],
            depth: depth[p as usize],
            class: c,
            near: label_near(map, width, p as usize, c, rule.near),
        })
        .collect();
    // Per region id (the index of the region's first pixel): its new label, as on the GPU.
    let mut table = vec![RELABEL_KEEP; map.len()];
    for (region, entry) in decide_regions(seeds, map, rule, confusions) {
        table[region as usize] = entry;
    }
    for (label, &region) in map.iter_mut().zip(&regions) {
        // NO_LABEL (unlabeled pixels) lies past the table.
        if let Some(&entry) = table.get(region as usize) {
            if entry != RELABEL_KEEP {
                *label = entry;
            }
        }
    }
}

/// Whether a pixel labeled `class` lies within `radius` (city-block) of pixel `p` of `map`
/// (`width` pixels a row): what region_near.comp gives a center.
pub fn label_near(map: &[u32], width: usize, p: usize, class: u32, radius: u32) -> bool {
    let height = map.len() / width;
    let (x, y, r) = (p % width, p / width, radius as usize);
    (y.saturating_sub(r)..(y + r + 1).min(height)).any(|qy| {
        let reach = r - qy.abs_diff(y);
        (x.saturating_sub(reach)..(x + reach + 1).min(width))
            .any(|qx| map[qy * width + qx] == class)
    })
}

/// An observed Gaussian's center in a view: the label region it lies in, its depth there
/// ([`edge_depth`], capped at the rule's depth), the Gaussian's consensus class, and whether
/// a pixel labeled that class lies within the rule's `near` pixels ([`label_near`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RegionSeed {
    pub region: u32,
    pub depth: u32,
    pub class: u32,
    pub near: bool,
}

/// Every region holding seeds, with its new label: the class holding `rule.min_share` of its
/// deciding seeds (its deepest, all of them from `rule.depth` pixels inward), unless it is
/// another class than the region's own label and at least half of its seeds lie near a
/// pixel the view labels it (the view labels that class beside the region); where no class
/// takes the region, its own label (in `map`, the view's labels, at the region's id: its
/// first pixel) if that holds `rule.keep_share` of them and, with the seeds of other classes
/// that lie near their class's label, `rule.min_share`; or if the seeds of classes the
/// views take for its label more often than `rule.max_edge_confusion` (by `confusions`) are
/// short of `1 - rule.min_share` of them; else NO_LABEL. Regions in increasing id.
///
/// Why not a class the view labels beside the region: the segmenter drew an edge between
/// the region and that class, and relabeling would erase the region from the view. Under
/// boundary noise a small object (a lamp, a cup) loses its edges to its neighbour's label,
/// wholly in the views that see it small, and the consensus (every view once) gives part
/// of its Gaussians the neighbour's class (living room, seed 5, boundary=4: 324 of the
/// lamps' 1,157 Gaussians wall); relabeled as the neighbour, the object's remaining
/// regions would leave it no pixels at all. Unlabeled, each Gaussian rendering there
/// counts for its own consensus class ([`fold_undecided`]), so those the consensus got
/// right keep the object.
/// Flicker relabels whole objects and moves no edge: an object flickered to a look-alike
/// next to one of its own class (a book beside books) is unlabeled instead of relabeled,
/// and its Gaussians count for the class the consensus gave them either way.
pub fn decide_regions(
    seeds: Vec<RegionSeed>,
    map: &[u32],
    rule: &RelabelRule,
    confusions: &ConfusionRates,
) -> Vec<(u32, u32)> {
    debug_assert!(rule.min_share > 0.5, "a tie could hold min_share");
    // (region, depth from deepest, class, near): by region, each region's deciding seeds
    // first.
    let mut seeds: Vec<(u32, Reverse<u32>, u32, bool)> = seeds
        .into_iter()
        .map(|s| (s.region, Reverse(s.depth), s.class, s.near))
        .collect();
    seeds.sort_unstable();
    let mut decided = Vec::new();
    for region in seeds.chunk_by(|a, b| a.0 == b.0) {
        let deciding = &region[..region.partition_point(|s| s.1 == region[0].1)];
        let holds = |n: usize, share: f64| n as f64 >= share * deciding.len() as f64;
        // Sorted by class within one depth: runs of one class.
        let (class, n) = deciding
            .chunk_by(|a, b| a.2 == b.2)
            .map(|run| (run[0].2, run.len()))
            .fold(
                (NO_LABEL, 0),
                |best, run| if run.1 > best.1 { run } else { best },
            );
        let own = map[region[0].0 as usize];
        let own_seeds = deciding.iter().filter(|s| s.2 == own).count();
        let near_seeds = deciding.iter().filter(|s| s.2 != own && s.3).count();
        let near_class = deciding.iter().filter(|s| s.2 == class && s.3).count();
        let labeled_beside = class != own && 2 * near_class >= n;
        // Seeds of classes that flicker could have given this label.
        let confusable =
            |c: u32| confusions.rate(c as usize, own as usize) > rule.max_edge_confusion;
        let look_alike_seeds = deciding
            .iter()
            .filter(|s| s.2 != own && confusable(s.2))
            .count();
        let label = if holds(n, rule.min_share) && !labeled_beside {
            class
        } else if (holds(own_seeds, rule.keep_share)
            && holds(own_seeds + near_seeds, rule.min_share))
            || holds(deciding.len() - look_alike_seeds, rule.min_share)
        {
            own
        } else {
            NO_LABEL
        };
        decided.push((region[0].0, label));
    }
    decided
}

/// Per pixel of `regions` (a view's [`label_regions`]), its city-block distance within its
/// region to the region's edge ([`region_edges`]: 0 on the edge), capped at `cap`; pixels
/// of a region without an edge get `cap`. A breadth-first search out from the edges, `cap`
/// steps deep.
pub fn edge_depth(regions: &[u32], width: usize, cap: u32) -> Vec<u32> {
    let edges = region_edges(regions, width);
    let mut depth = vec![cap; regions.len()];
    let mut front: Vec<usize> = (0..regions.len()).filter(|&p| edges[p]).collect();
    for &p in &front {
        depth[p] = 0;
    }
    // A pixel still at `cap` is unreached: every depth set below is under `cap`.
    for d in 1..cap {
        let mut next = Vec::new();
        for &p in &front {
            for q in four_neighbours(p, width, regions.len()) {
                if regions[q] == regions[p] && depth[q] == cap {
                    depth[q] = d;
                    next.push(q);
                }
            }
        }
        front = next;
    }
    depth
}

/// Sums over views relabeled with an undecided channel ([`RelabeledViews::undecided`], the
/// class past the others) to sums over the classes alone: each Gaussian's mass on
/// undecided pixels counts for its own consensus `class` (dropped where it has none).
/// Where the relabeling could not tell which object a region's pixels show, each Gaussian
/// rendering there is taken to show its own; left out instead, an object's Gaussians at an
/// edge whose own side was undecided in a view see only the other side's pixels there, and
/// take its class.
pub fn fold_undecided(
    sums: SumsByGaussian<f64>,
    classes: usize,
    class: &[Option<usize>],
) -> SharedCounts {
    let mut folded = SharedCounts::zeros(classes, sums.len());
    for (g, mut row) in sums.into_sorted_rows().enumerate() {
        // The undecided channel, past the classes, sorts last.
        if let Some(&(_, mass)) = row.last().filter(|e| e.0 as usize == classes) {
            row.pop();
            if let Some(own) = class[g] {
                match row.binary_search_by_key(&(own as u32), |e| e.0) {
                    Ok(i) => row[i].1 += mass,
                    Err(i) => row.insert(i, (own as u32, mass)),
                }
            }
        }
        row.retain(|e| e.1 != 0.0);
        folded.set(g, &row);
    }
    folded
}

/// Segment consensus, then FlashSplat's accumulation over the views relabeled with its
/// classes ([`RelabeledViews`], the undecided pixels counting for each Gaussian's consensus
/// class: [`fold_undecided`]), assigned as FlashSplat (ties by the neighbours' evidence):
/// the consensus decides what each object is, the pixels each Gaussian covers where the
/// objects' edges run. A Gaussian keeps its consensus class where the relabeled views leave
/// it undecided or its footprint there sums to less than `params.relabel.min_mass` pixels
/// (too little of it is seen for its pixels to say where an edge runs, and it renders
/// nowhere anyway). `progress` gets (views done, twice the views): every view is visited
/// twice (the second time only its labels, where its footprints were kept:
/// [`RelabeledSums`]).
pub fn fuse_relabeled(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    params: &ConsensusParams,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ConsensusLift> {
    let sums = match footprints_for(cfg, input.gpu) {
        true => RelabeledSums::FromFootprints,
        false => RelabeledSums::WalkAgain,
    };
    fuse_relabeled_by(input, cfg, params, sums, progress)
}

/// How [`fuse_relabeled`] sums FlashSplat's weights over the relabeled views: from the
/// footprints the consensus's observation pass keeps per label region
/// (src/fuse/consensus_footprints.rs: no second walk of the views; with fixed-point
/// accumulation), or by FlashSplat's pass over the relabeled views. The same sums.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RelabeledSums {
    FromFootprints,
    WalkAgain,
}

/// [`fuse_relabeled`], its sums over the relabeled views found as `sums` says.
pub fn fuse_relabeled_by(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    params: &ConsensusParams,
    sums: RelabeledSums,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ConsensusLift> {
    let start = std::time::Instant::now();
    let views = input.cams.len();
    let first_visit = &mut |done, _| progress(done, 2 * views);
    let kept = match sums {
        RelabeledSums::FromFootprints => Kept::Footprints,
        RelabeledSums::WalkAgain => Kept::CenterPixels,
    };
    let mut run = consensus_run(input, cfg, params, kept, first_visit)?;
    // The relabeling reads the centers and the classes, not the observations (13 bytes
    // each): freed before the views' second visit, so its FlashSplat pass reuses their
    // memory instead of adding to the peak.
    let seen_by_none = (0..run.observations.n).map(|g| run.observations.row(g).is_empty());
    let unseen = run.order.to_scene(&seen_by_none.collect::<Vec<bool>>());
    drop(std::mem::take(&mut run.observations));
    let relabeled = RelabeledViews {
        inner: input.labels,
        centers: &run.centers,
        class: &run.consensus.assignment.class,
        rule: params.relabel,
        confusions: &run.consensus.confusions,
        // Where the host finds regions (a CPU device), it relabels too, each of the label
        // source's threads its own view, without the finder's lock.
        finder: (!RegionFinder::on_host_for(input.gpu))
            .then(|| RegionFinder::new(input.gpu, input.shapes.len()))
            .transpose()?
            .map(Mutex::new),
        undecided: Some(input.classes as u32),
    };
    let second_visit = |done, _| progress(views + done, 2 * views);
    let kept = std::mem::take(&mut run.footprints);
    let (sums, fs_stats) = relabeled_sums(input, cfg, &relabeled, sums, &kept, second_visit)?;
    drop(kept);
    let relabel_stats = match relabeled.finder {
        Some(finder) => finder.into_inner().unwrap_or_else(|e| e.into_inner()).stats,
        None => Default::default(),
    };
    let consensus = run.consensus;
    let footprints = fold_undecided(sums, input.classes, &consensus.assignment.class);
    let knn = run.order.neighbours_to_scene(&run.knn, params.neighbours);
    let by_pixels = assign_counts_near(&footprints, Some((&knn, params.neighbours)));
    let mut evidence = SharedCounts::clone(&consensus.evidence);
    let mut class = consensus.assignment.class.clone();
    for (g, (own, &by_footprint)) in class.iter_mut().zip(&by_pixels.class).enumerate() {
        let row = footprints.get(g);
        let mass: f64 = row.iter().map(|e| e.1).sum();
        if by_footprint.is_some() && mass >= params.relabel.min_mass {
            *own = by_footprint;
            evidence.set(g, row);
        }
    }
    let (mut confidence, _) = posteriors(&consensus.evidence, &class, params.prior);
    unseen_without_confidence(&unseen, &mut confidence, None, input.classes);
    let mut stats = both_visits(run.stats, fs_stats, relabel_stats);
    stats.finish(start);
    Ok(ConsensusLift {
        assignment: Assignment { class, confidence },
        consensus,
        evidence: Arc::new(evidence),
        stats,
    })
}

/// The second visit's sums over the `relabeled` views (the classes and the undecided
/// channel), as `sums` says: from the footprints `kept` by the first, or by FlashSplat's
/// pass.
fn relabeled_sums(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    relabeled: &RelabeledViews,
    sums: RelabeledSums,
    kept: &[ViewFootprints],
    progress: impl FnMut(usize, usize),
) -> Result<(SumsByGaussian<f64>, FuseStats)> {
    let rows = input.classes + 1;
    match sums {
        RelabeledSums::FromFootprints => {
            relabeled_footprints(input, cfg, relabeled, rows, kept, progress)
        }
        RelabeledSums::WalkAgain => flashsplat_pass(input, cfg, relabeled, rows, progress),
    }
}

/// The stats of `--relabel`'s two visits of the views: the consensus's `first`, the
/// `second` (its sums), and the GPU relabeling's `relabel` (times and counts added, the
/// consensus's own parts taken from the first).
fn both_visits(first: FuseStats, second: FuseStats, relabel: RegionStats) -> FuseStats {
    let mut stats = second;
    stats.gpu_ms += first.gpu_ms + relabel.gpu_ms;
    // The kernels of both visits, the observation pass's first.
    let second_kernels = std::mem::replace(&mut stats.kernels, first.kernels);
    KernelTotal::add_all(&mut stats.kernels, second_kernels);
    stats.view_s += first.view_s; // the consensus's visit of the views
    stats.label_wait_s += first.label_wait_s;
    stats.label_read_s += first.label_read_s;
    stats.views_in_flight = stats.views_in_flight.max(first.views_in_flight);
    stats.views_with_labels = first.views_with_labels;
    (stats.segments_s, stats.decide_s) = (first.segments_s, first.decide_s);
    stats.observe = first.observe;
    stats.observe.regions_gpu_ms += relabel.gpu_ms;
    (stats.clustering, stats.decision) = (first.clustering, first.decision);
    stats.peak_device_bytes = stats.peak_device_bytes.max(first.peak_device_bytes);
    stats.scene_device_bytes = stats.scene_device_bytes.max(first.scene_device_bytes);
    stats.region_host_fallbacks = first.region_host_fallbacks + relabel.host_fallbacks;
    stats
}
