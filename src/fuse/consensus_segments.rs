//! The host side of segment consensus (src/fuse/consensus.rs), its inputs: the observations,
//! connected label regions of a view, the Gaussians' nearest neighbours, and what the views
//! said of a pair of neighbours (co-occurrence in regions). The segments are clustered in
//! src/fuse/consensus_cluster.rs and decided in src/fuse/consensus_decide.rs.
//!
//! Why regions: flicker relabels a whole object in a view but does not move its edges, so two
//! neighbouring Gaussians of one object fall in the same connected label region in (nearly)
//! every view that sees both, whatever class the view gives it; Gaussians of two objects fall
//! in different regions except in views where noise gave both the same class. Class ids only
//! find region boundaries here; they vote once per view, per segment.

use super::accumulate::NO_LABEL;
use crate::util::{map_in_blocks, parallel_map, split_parts, take_part};
use std::borrow::Cow;
use std::ops::Range;
use std::sync::atomic::{AtomicU32, Ordering};

/// Per Gaussian, the views that observed it (center visible on a labeled pixel), in
/// compressed rows sorted by view: what a view says about a Gaussian.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Observations {
    pub n: usize,
    /// Rows: Gaussian g's observations are `offsets[g]..offsets[g + 1]` (usize: a large
    /// scene seen in many views passes 2^32 observations).
    pub offsets: Vec<usize>,
    pub view: Vec<u32>,
    /// Compact class of the pixel under the center.
    pub label: Vec<u32>,
    /// Connected label region of that pixel, unique within the view.
    pub region: Vec<u32>,
    /// Whether that pixel lies on its region's edge (a 4-neighbour in another region or
    /// unlabeled). Whether a Gaussian near an object's edge lands on this side of the label
    /// edge or the other is decided by a pixel's width, so two Gaussians in one region there
    /// are no evidence that they belong together (a floor Gaussian at the wall's foot would
    /// join the wall, and through it the floor would join the wall). Two in different
    /// regions still count as apart: the veto that keeps objects apart under flicker.
    pub edge: Vec<bool>,
}

impl Observations {
    /// From per-view lists of (Gaussian, label, region, edge), views in order. A counting
    /// sort by Gaussian, on every core: the Gaussians are split into ranges, each gathered
    /// from its slice of every view's list (lists in Gaussian order, as `observe` writes
    /// them; any other is sorted first). Each row ends up sorted by view, a view's entries
    /// for one Gaussian in list order.
    pub fn from_views<E: ViewObservation>(n: usize, per_view: &[Vec<E>]) -> Observations {
        let sorted: Vec<Cow<[E]>> = per_view.iter().map(|l| in_gaussian_order(l)).collect();
        let ranges: Vec<Range<usize>> = (0..n.div_ceil(GATHER_RANGE))
            .map(|r| r * GATHER_RANGE..n.min((r + 1) * GATHER_RANGE))
            .collect();
        let range_lens = || ranges.iter().map(|r| r.len());
        // offsets[g + 1] counts Gaussian g's entries, then sums them: row g's start at g.
        let mut offsets = vec![0usize; n + 1];
        let counts = split_parts(&mut offsets[1..], range_lens());
        parallel_map(ranges.len(), |r| {
            let mut count = take_part(&counts[r]);
            for entry in range_parts(&sorted, &ranges[r]).flatten() {
                count[entry.gaussian() as usize - ranges[r].start] += 1;
            }
        });
        drop(counts);
        for g in 0..n {
            offsets[g + 1] += offsets[g];
        }
        let total = offsets[n];
        let (mut view, mut label, mut region) = (vec![0; total], vec![0; total], vec![0; total]);
        let mut edge = vec![false; total];
        let rows = |r: &Range<usize>| offsets[r.end] - offsets[r.start];
        let row_lens: Vec<usize> = ranges.iter().map(rows).collect();
        let (views, labels) = (
            split_parts(&mut view, row_lens.clone()),
            split_parts(&mut label, row_lens.clone()),
        );
        let (regions, edges) = (
            split_parts(&mut region, row_lens.clone()),
            split_parts(&mut edge, row_lens),
        );
        // offsets[g] is row g's next free entry as it fills: its end (g + 1's start) after.
        let cursors = split_parts(&mut offsets[..n], range_lens());
        parallel_map(ranges.len(), |r| {
            let mut next = take_part(&cursors[r]);
            let base = next.first().copied().unwrap_or(0);
            let (mut v_out, mut l_out) = (take_part(&views[r]), take_part(&labels[r]));
            let (mut r_out, mut e_out) = (take_part(&regions[r]), take_part(&edges[r]));
            // Views in order, so every row ends up sorted by view.
            for (v, part) in range_parts(&sorted, &ranges[r]).enumerate() {
                for entry in part {
                    let (l, rg, e) = entry.seen();
                    let at = &mut next[entry.gaussian() as usize - ranges[r].start];
                    let i = *at - base;
                    (v_out[i], l_out[i], r_out[i], e_out[i]) = (v as u32, l, rg, e);
                    *at += 1;
                }
            }
        });
        drop((cursors, views, labels, regions, edges));
        offsets.copy_within(0..n, 1);
        offsets[0] = 0;
        Observations {
            n,
            offsets,
            view,
            label,
            region,
            edge,
        }
    }

    pub fn row(&self, g: usize) -> std::ops::Range<usize> {
        self.offsets[g]..self.offsets[g + 1]
    }

    /// The Gaussians cut into `parts` consecutive ranges of about equal observations
    /// (fewer where Gaussians are fewer): work items for a pass whose cost is the
    /// observations', where ranges of equal Gaussians differ by the views seeing them.
    pub(crate) fn runs_of_equal_observations(&self, parts: usize) -> Vec<Range<usize>> {
        let total = self.offsets[self.n];
        let mut ends: Vec<usize> = (1..parts.max(1))
            .map(|k| self.offsets.partition_point(|&o| o * parts < k * total))
            .chain([self.n])
            .collect();
        ends.dedup();
        let starts = std::iter::once(0).chain(ends.iter().copied());
        starts
            .zip(ends.iter().copied())
            .filter(|(a, b)| a < b)
            .map(|(a, b)| a..b)
            .collect()
    }
}

/// One view's observation of a Gaussian: (Gaussian, label, region, edge).
pub type ViewEntry = (u32, u32, u32, bool);

/// A set of (view, region) pairs, each numbered (its slot): per view its regions sorted, so
/// a pair is found by a binary search. Regions are numbered within their view, and a view
/// of salt noise holds hundreds of thousands: too many for a table per view.
pub(crate) struct RegionSlots {
    regions: Vec<Vec<u32>>,
    /// Slot of each view's first region; the last entry: how many slots in all.
    start: Vec<usize>,
}

impl RegionSlots {
    pub(crate) fn of(pairs: impl Iterator<Item = (u32, u32)>) -> RegionSlots {
        let mut regions: Vec<Vec<u32>> = Vec::new();
        for (view, region) in pairs {
            if regions.len() <= view as usize {
                regions.resize_with(view as usize + 1, Vec::new);
            }
            regions[view as usize].push(region);
        }
        let mut start = vec![0usize; regions.len() + 1];
        for (v, list) in regions.iter_mut().enumerate() {
            list.sort_unstable();
            list.dedup();
            start[v + 1] = start[v] + list.len();
        }
        RegionSlots { regions, start }
    }

    /// The slots of the observations of `gaussians` (ascending), each with the label of
    /// its last observation among them in that order (a region's pixels hold one label, so
    /// any would do; the last is what one pass in order gives): on every core, in blocks of
    /// Gaussians whose slots are then merged view by view, where one pass on the calling
    /// thread took a twentieth of a living room's decision on one core.
    pub(crate) fn of_rows_labelled(
        obs: &Observations,
        gaussians: &[usize],
    ) -> (RegionSlots, Vec<u32>) {
        const BLOCK: usize = 1024;
        // Per block, (view, region, label) sorted, the last of each (view, region).
        let blocks: Vec<&[usize]> = gaussians.chunks(BLOCK).collect();
        let seen = parallel_map(blocks.len(), |b| {
            let rows = blocks[b].iter().flat_map(|&g| obs.row(g));
            let mut seen: Vec<(u32, u32, u32)> = rows
                .map(|i| (obs.view[i], obs.region[i], obs.label[i]))
                .collect();
            seen.sort_by_key(|&(view, region, _)| (view, region)); // stable: in order
            last_of_each_region(seen)
        });
        let views = seen
            .iter()
            .filter_map(|s| s.last())
            .map(|s| s.0 as usize + 1)
            .max();
        // Per view, the blocks' parts in block order, the last of each region again.
        let of_view = parallel_map(views.unwrap_or(0), |view| {
            let view = view as u32;
            let part = |s: &[(u32, u32, u32)]| {
                let from = s.partition_point(|e| e.0 < view);
                s[from..from + s[from..].partition_point(|e| e.0 == view)].to_vec()
            };
            let mut merged: Vec<(u32, u32, u32)> = seen.iter().flat_map(|s| part(s)).collect();
            merged.sort_by_key(|&(_, region, _)| region);
            last_of_each_region(merged)
        });
        let mut start = vec![0usize; of_view.len() + 1];
        for (v, list) in of_view.iter().enumerate() {
            start[v + 1] = start[v] + list.len();
        }
        let labels = of_view.iter().flatten().map(|e| e.2).collect();
        let regions = of_view
            .into_iter()
            .map(|l| l.into_iter().map(|e| e.1).collect());
        let slots = RegionSlots {
            regions: regions.collect(),
            start,
        };
        (slots, labels)
    }

    pub(crate) fn len(&self) -> usize {
        *self.start.last().unwrap_or(&0)
    }

    /// The slot of (view, region), if it is in the set.
    pub(crate) fn slot(&self, view: u32, region: u32) -> Option<usize> {
        let regions = self.regions.get(view as usize)?;
        Some(self.start[view as usize] + regions.binary_search(&region).ok()?)
    }
}

/// (view, region, label) sorted by (view, region), kept in order within each: the last of
/// each (view, region).
fn last_of_each_region(sorted: Vec<(u32, u32, u32)>) -> Vec<(u32, u32, u32)> {
    let runs = sorted.chunk_by(|a, b| (a.0, a.1) == (b.0, b.1));
    runs.map(|run| run[run.len() - 1]).collect()
}

/// A view's observation of a Gaussian as [`Observations::from_views`] reads it: a
/// [`ViewEntry`], or the views' own compact form (src/fuse/consensus_observe.rs: 12 bytes
/// where the tuple takes 16, held for every observation until the views are done).
pub trait ViewObservation: Copy + Send + Sync {
    fn gaussian(&self) -> u32;
    /// (label, region, edge).
    fn seen(&self) -> (u32, u32, bool);
}

impl ViewObservation for ViewEntry {
    fn gaussian(&self) -> u32 {
        self.0
    }

    fn seen(&self) -> (u32, u32, bool) {
        (self.1, self.2, self.3)
    }
}

/// Gaussians per range of [`Observations::from_views`]'s counting sort.
const GATHER_RANGE: usize = 1 << 15;

/// `list` in Gaussian order: as it is when it already is (stable, so a Gaussian's entries
/// keep their order).
fn in_gaussian_order<E: ViewObservation>(list: &[E]) -> Cow<'_, [E]> {
    if list.is_sorted_by_key(|e| e.gaussian()) {
        Cow::Borrowed(list)
    } else {
        let mut sorted = list.to_vec();
        sorted.sort_by_key(|e| e.gaussian());
        Cow::Owned(sorted)
    }
}

/// Each list's entries of the Gaussians in `range`: one slice of each, found by binary search.
fn range_parts<'a, E: ViewObservation>(
    lists: &'a [Cow<[E]>],
    range: &Range<usize>,
) -> impl Iterator<Item = &'a [E]> {
    let (start, end) = (range.start, range.end);
    lists.iter().map(move |list| {
        let at = |g: usize| list.partition_point(|e| (e.gaussian() as usize) < g);
        &list[at(start)..at(end)]
    })
}

/// Connected regions (4-neighbourhood) of equal labels; unlabeled pixels get [`NO_LABEL`].
/// A region's id is the index of its first pixel in scan order (the root union-find keeps,
/// as it links the larger root under the smaller), so ids are deterministic and the GPU's
/// (src/fuse/regions_gpu.rs) are the same.
pub fn label_regions(labels: &[u32], width: usize) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..labels.len() as u32).collect();
    for p in 0..labels.len() {
        if labels[p] == NO_LABEL {
            continue;
        }
        if p % width > 0 && labels[p - 1] == labels[p] {
            union(&mut parent, p as u32, p as u32 - 1);
        }
        if p >= width && labels[p - width] == labels[p] {
            union(&mut parent, p as u32, (p - width) as u32);
        }
    }
    (0..labels.len())
        .map(|p| match labels[p] {
            NO_LABEL => NO_LABEL,
            _ => find(&mut parent, p as u32),
        })
        .collect()
}

/// Per pixel of `regions` (a view's [`label_regions`]): whether a 4-neighbour inside the image
/// lies in another region (or is unlabeled). The image border is not an edge.
pub fn region_edges(regions: &[u32], width: usize) -> Vec<bool> {
    (0..regions.len())
        .map(|p| four_neighbours(p, width, regions.len()).any(|q| regions[q] != regions[p]))
        .collect()
}

/// The 4-neighbours of pixel `p` inside an image of `pixels` pixels, `width` a row.
pub fn four_neighbours(p: usize, width: usize, pixels: usize) -> impl Iterator<Item = usize> {
    let x = p % width;
    [
        (x > 0).then(|| p - 1),
        (x + 1 < width).then(|| p + 1),
        (p >= width).then(|| p - width),
        (p + width < pixels).then(|| p + width),
    ]
    .into_iter()
    .flatten()
}

/// Gaussians one thread takes at a time where a pass over a large set of them is split
/// among the threads (the pieces' region counts, a wall's votes): a segmenter's scene
/// holds a few segments of hundreds of thousands.
pub(crate) const GAUSSIANS_PER_RUN: usize = 16_384;

/// Indices grouped by their key, in index order within a group (a counting sort): the
/// Gaussians of each segment, piece or grid cell.
#[derive(Default)]
pub(crate) struct Groups {
    /// Group `k` is `members[starts[k]..starts[k + 1]]`.
    starts: Vec<u32>,
    members: Vec<u32>,
}

impl Groups {
    /// The indices `0..key.len()` grouped by `key[i]`, each below `keys`.
    pub(crate) fn by_key(key: &[u32], keys: usize) -> Groups {
        let mut starts = vec![0u32; keys + 1];
        for &k in key {
            starts[k as usize + 1] += 1;
        }
        for k in 0..keys {
            starts[k + 1] += starts[k];
        }
        let mut members = vec![0u32; key.len()];
        let mut next = starts.clone();
        for (i, &k) in key.iter().enumerate() {
            members[next[k as usize] as usize] = i as u32;
            next[k as usize] += 1;
        }
        Groups { starts, members }
    }

    /// The indices of key `k`.
    pub(crate) fn group(&self, k: usize) -> &[u32] {
        &self.members[self.starts[k] as usize..self.starts[k + 1] as usize]
    }
}

pub(crate) fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let up = parent[parent[x as usize] as usize];
        parent[x as usize] = up;
        x = up;
    }
    x
}

/// Joins the sets of a and b under the smaller root (deterministic whatever the order).
pub(crate) fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi as usize] = lo;
    }
}

/// Disjoint sets joined from several threads at once: union-find on atomic parents, each
/// join linking the higher root under the lower (a compare-and-swap that fails, and is
/// retried, where another thread linked that root first). A set's root is then its lowest
/// member whatever the joins' order or threads, so the sets and their names are those of
/// [`union`] in one thread.
pub(crate) struct SharedSets(Vec<AtomicU32>);

impl SharedSets {
    /// `n` sets of one member each.
    pub(crate) fn new(n: usize) -> SharedSets {
        SharedSets((0..n as u32).map(AtomicU32::new).collect())
    }

    /// The root of `x`'s set, halving its path on the way (each step points a member at
    /// its grandparent, which is an ancestor whatever other threads link meanwhile).
    fn find(&self, mut x: u32) -> u32 {
        let parent = |x: u32| self.0[x as usize].load(Ordering::Relaxed);
        loop {
            let up = parent(x);
            if up == x {
                return x;
            }
            let grand = parent(up);
            if grand != up {
                let _ = self.0[x as usize].compare_exchange(
                    up,
                    grand,
                    Ordering::Relaxed,
                    Ordering::Relaxed,
                );
            }
            x = grand;
        }
    }

    /// Joins the sets of `a` and `b` under the lower root.
    pub(crate) fn union(&self, a: u32, b: u32) {
        loop {
            let (ra, rb) = (self.find(a), self.find(b));
            if ra == rb {
                return;
            }
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            let link =
                self.0[hi as usize].compare_exchange(hi, lo, Ordering::Relaxed, Ordering::Relaxed);
            if link.is_ok() {
                return;
            }
        }
    }

    /// Each member's root (its set's lowest member), on every core; after every join.
    pub(crate) fn roots(&self) -> Vec<u32> {
        map_in_blocks(self.0.len(), 1 << 16, |x| self.find(x as u32))
    }
}

/// Of the views that observed both rows: how many put them in the same region (both away
/// from its edge), how many in different ones, and how many in one region on its edge (no
/// evidence either way). Rows are sorted by view.
pub fn co_occurrence(obs: &Observations, a: usize, b: usize) -> CoOccurrence {
    let (ra, rb) = (obs.row(a), obs.row(b));
    let (mut i, mut j) = (ra.start, rb.start);
    let (mut together, mut apart, mut on_edge) = (0, 0, 0);
    while i < ra.end && j < rb.end {
        match obs.view[i].cmp(&obs.view[j]) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                if obs.region[i] != obs.region[j] {
                    apart += 1;
                } else if !(obs.edge[i] || obs.edge[j]) {
                    together += 1;
                } else {
                    on_edge += 1; // no evidence (see `Observations::edge`)
                }
                i += 1;
                j += 1;
            }
        }
    }
    CoOccurrence {
        together,
        apart,
        on_edge,
    }
}

/// What the views that observed two Gaussians said of them ([`co_occurrence`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CoOccurrence {
    pub together: u32,
    pub apart: u32,
    pub on_edge: u32,
}

impl CoOccurrence {
    /// Views that observed both.
    pub fn views(&self) -> u32 {
        self.together + self.apart + self.on_edge
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::Rng;

    /// The labelled slots of some Gaussians' rows, found in blocks on every core, are the
    /// slots of a plain pass over the same observations with the label each slot's last
    /// observation gave (labels drawn at random, so "last" is tested).
    #[test]
    fn labelled_slots_of_rows_are_a_plain_pass() {
        let mut rng = Rng::new(6);
        let n = 5000;
        let mut obs = Observations {
            n,
            offsets: vec![0],
            ..Default::default()
        };
        for _ in 0..n {
            for v in 0..40u32 {
                if rng.below(4) == 0 {
                    obs.view.push(v);
                    obs.region.push(rng.below(30) as u32);
                    obs.label.push(rng.below(9) as u32);
                    obs.edge.push(false);
                }
            }
            obs.offsets.push(obs.view.len());
        }
        let read: Vec<usize> = (0..n).filter(|_| rng.below(3) > 0).collect();
        let (slots, labels) = RegionSlots::of_rows_labelled(&obs, &read);
        let rows = || read.iter().flat_map(|&g| obs.row(g));
        let plain = RegionSlots::of(rows().map(|i| (obs.view[i], obs.region[i])));
        assert_eq!((slots.len(), &slots.start), (plain.len(), &plain.start));
        assert_eq!(slots.regions, plain.regions);
        let mut last = vec![u32::MAX; plain.len()];
        for i in rows() {
            last[plain.slot(obs.view[i], obs.region[i]).unwrap()] = obs.label[i];
        }
        assert_eq!(labels, last);
    }

    /// Runs of equal observations cover the Gaussians in order, each run's observations
    /// within a row of the even share, none empty: rows of random lengths (unobserved ones
    /// among them), parts more than Gaussians, no observations at all.
    #[test]
    fn runs_of_equal_observations_cover_the_gaussians() {
        let mut rng = Rng::new(2);
        for (n, parts) in [(1000, 7), (1000, 1), (5, 9), (300, 16)] {
            let lens: Vec<usize> = (0..n).map(|_| rng.below(40) as usize).collect();
            let mut offsets = vec![0];
            lens.iter()
                .for_each(|l| offsets.push(offsets.last().unwrap() + l));
            let total = offsets[n];
            let obs = Observations {
                n,
                offsets,
                ..Default::default()
            };
            let runs = obs.runs_of_equal_observations(parts);
            assert!(runs.len() <= parts.min(n), "{n} in {parts}: {runs:?}");
            let covered: Vec<usize> = runs.iter().cloned().flatten().collect();
            assert_eq!(covered, (0..n).collect::<Vec<_>>(), "{n} in {parts}");
            let longest_row = lens.iter().max().copied().unwrap_or(0);
            for run in &runs {
                let held: usize = lens[run.clone()].iter().sum();
                assert!(
                    held <= total / parts + 2 * longest_row,
                    "{n} in {parts}: {run:?}"
                );
            }
        }
        let unobserved = Observations {
            n: 10,
            offsets: vec![0; 11],
            ..Default::default()
        };
        assert_eq!(unobserved.runs_of_equal_observations(4), vec![0..10]);
    }

    /// Joined on every core in any order, the sets and their roots are those of one thread
    /// joining the same pairs in order: chains (long paths to halve) and random pairs, some
    /// joining a set with itself.
    #[test]
    fn shared_sets_join_as_one_thread_does() {
        let mut rng = Rng::new(13);
        let n = 50_000u32;
        let mut pairs: Vec<(u32, u32)> = (1..n).step_by(3).map(|g| (g, g - 1)).collect();
        pairs.extend((0..40_000).map(|_| (rng.below(n as u64) as u32, rng.below(n as u64) as u32)));
        let mut parent: Vec<u32> = (0..n).collect();
        for &(a, b) in &pairs {
            union(&mut parent, a, b);
        }
        let serial: Vec<u32> = (0..n).map(|g| find(&mut parent, g)).collect();
        rng.shuffle(&mut pairs);
        let sets = SharedSets::new(n as usize);
        let blocks: Vec<&[(u32, u32)]> = pairs.chunks(997).collect();
        parallel_map(blocks.len(), |b| {
            for &(a, b) in blocks[b] {
                sets.union(a, b);
            }
        });
        let shared = sets.roots();
        assert_eq!(shared, serial);
        let roots = (0..n).filter(|&g| serial[g as usize] == g).count();
        assert!(roots > 100 && roots < 20_000, "{roots} sets");
    }
}
