//! Segment consensus, the segments: agglomerative clustering of the Gaussians' neighbour
//! graph, strongest evidence first, with the evidence between two segments summed over every
//! neighbour pair that joins them.
//!
//! Why not join pairs one by one (union-find): under flicker a pair across an object's edge
//! is put in one region by every view that relabeled one object as the other, and a pair
//! seen by two or three views is easily seen only in such views. Across tens of thousands of
//! edge pairs some always are, and one such pair joined a ceiling to its wall. Here two
//! segments join only on the evidence of all the pairs between them and on their dominant
//! regions view by view, so a ceiling whole is tested against a wall whole; and well-seen
//! pairs join first, so a Gaussian seen by three views meets the segment its well-seen
//! neighbours already formed rather than whichever neighbour it was tested with first.
//!
//! The one exception: pairs that many views saw, all of them in one region away from its
//! edge, are joined outright before the ordered joins ([`premerge`]). Most of an object's
//! interior is such pairs, and joining them one at a time in the order was most of the
//! clustering's sequential time. A pair across two objects passes too where every view
//! that saw it had merged their regions (flicker gave both one class): from 4 such views
//! that joined a ceiling to its wall on one sweep run; from 6 (the default) the flicker
//! sweep's means moved by at most 0.4 mIoU points (the office's segment consensus, up;
//! docs/robustness-log.md, "Unanimous pairs joined outright").
//!
//! The order's first key is the geometry: a candidate with a neighbour pair along a surface
//! goes before every candidate whose pairs all cross a crease (src/fuse/consensus_surface.rs).
//! Where the views saw a strip of one surface only in one region with its neighbour across
//! the crease, the evidence ties the two joins, and the surface the strip continues should
//! take it (docs/robustness-log.md, "Joins along a surface first").
//!
//! With [`Clustering::Rounds`] most joins leave the order: those that take in a single
//! Gaussian are made in rounds on every core between an order among the pieces and one
//! among what is left ([`attach`]).

mod attach;

use std::cell::RefCell;

use serde::Serialize;

use super::consensus_adjacent::Adjacent;
use super::consensus_decide::{Clustering, ConsensusParams};
use super::consensus_segments::{
    co_occurrence, Groups, Observations, SharedSets, GAUSSIANS_PER_RUN,
};
use super::consensus_surface::SurfaceNormals;
use crate::contract::NO_NEIGHBOUR;
use crate::util::quad_heap::QuadHeap;
use crate::util::{
    collect_parts, cores, map_in_blocks, merge_sorted_into, merge_sorted_runs, parallel_map,
    partition_point_near, prefetch, runs_of_weight, split_parts, take_part, Laps,
};

/// One view of [`PairEvidence::priority`], its fixed point's unit.
const PRIORITY_ONE: i64 = 1 << 20;

/// What the views said of the neighbour pairs between two segments, summed over the pairs
/// ([`co_occurrence`] per pair).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairEvidence {
    pub together: u32,
    pub apart: u32,
    pub on_edge: u32,
    /// Neighbour pairs summed.
    pub pairs: u32,
    /// Of those, the pairs along a surface (not across a crease: src/fuse/consensus_surface.rs).
    pub pairs_along: u32,
}

impl PairEvidence {
    pub(crate) fn add(&mut self, other: PairEvidence) {
        self.together += other.together;
        self.apart += other.apart;
        self.on_edge += other.on_edge;
        self.pairs += other.pairs;
        self.pairs_along += other.pairs_along;
    }

    /// Merge order: net evidence per neighbour pair (a view putting a pair apart outweighs
    /// `apart_weight` views putting it together), so pairs seen together by many views join
    /// first; per pair, because a sum would favour large segments for their size alone.
    /// Fixed point (2^-20) so the order is exact and the same wherever it is computed.
    pub fn priority(&self, apart_weight: f64) -> i64 {
        let net = self.together as f64 - apart_weight * self.apart as f64;
        (net / self.pairs.max(1) as f64 * PRIORITY_ONE as f64).round() as i64
    }

    /// The candidates' first key: those with a pair along a surface above every candidate
    /// whose pairs all cross a crease, then by [`PairEvidence::priority`]. One integer
    /// rather than a flag beside the priority: the queue's entries stay 24 bytes, not 32.
    pub fn queue_key(&self, apart_weight: f64) -> i64 {
        // Above any priority: a pair's net views are at most its views (thousands at most)
        // times max(1, apart_weight), in fixed point (2^20): far under 2^50.
        const ALONG: i64 = 1 << 50;
        self.priority(apart_weight) + if self.pairs_along > 0 { ALONG } else { 0 }
    }

    /// Whether the pairs' evidence allows a join: enough views together, (nearly) none
    /// apart, and together in at least a share of all the views seeing the pairs.
    pub fn allows_join(&self, p: &ConsensusParams) -> bool {
        let decided = (self.together + self.apart) as f64;
        let seen = decided + self.on_edge as f64;
        self.together >= p.min_together
            && self.apart as f64 <= p.max_apart_share * decided
            && self.together as f64 >= p.min_together_share * seen
    }
}

/// A segment's observations counted per (view, region), and per view its dominant region.
/// Empty for a single Gaussian (most segments, most of the time): its observations are read
/// in place ([`Dominant::Row`]) rather than copied, 12 bytes for every observation of the
/// scene; a segment's counts are built when it first joins another.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RegionCounts {
    /// (view, region, observations), sorted by view, then region.
    counts: Vec<(u32, u32, u32)>,
    /// Per view: the region holding most of the segment's observations (ties: the lowest
    /// region id) and how many of its observations the view holds; sorted by view. Kept
    /// up to date on every join, because every candidate a segment is tested with reads it.
    /// Empty while it would equal `counts` (one region per view: every single Gaussian,
    /// which is most segments, so they hold their observations once).
    dominant: Vec<(u32, u32, u32)>,
}

impl RegionCounts {
    pub fn of_gaussian(obs: &Observations, g: usize) -> RegionCounts {
        RegionCounts {
            counts: obs
                .row(g)
                .map(|i| (obs.view[i], obs.region[i], 1))
                .collect(),
            dominant: Vec::new(), // one observation per view: the counts
        }
    }

    /// The counts of a segment of several Gaussians, built whole (the pieces of
    /// [`premerge`]).
    fn of_gaussians(obs: &Observations, members: &[u32]) -> RegionCounts {
        let observations: usize = members.iter().map(|&g| obs.row(g as usize).len()).sum();
        let mut built = RegionCounts {
            counts: match observations < COUNT_BY_VIEW_FROM {
                true => counts_sorted(obs, members),
                false => counts_by_view(obs, members),
            },
            dominant: Vec::new(),
        };
        let views = built.counts.chunk_by(|a, b| a.0 == b.0).map(|run| run[0].0);
        built.dominant = views.map(|view| built.dominant_in(view)).collect();
        built
    }

    /// Adds `other`'s counts; `first` and `other_first` are the two segments' lowest
    /// Gaussians, whose observations are the counts of a segment of one. The smaller of the
    /// two is added into the larger, so a large segment taking in a Gaussian costs the
    /// Gaussian's views (with binary searches), not a copy of the segment's counts.
    fn absorb(
        &mut self,
        first: usize,
        mut other: RegionCounts,
        other_first: usize,
        obs: &Observations,
    ) {
        if self.counts.is_empty() {
            *self = RegionCounts::of_gaussian(obs, first);
        }
        if other.counts.is_empty() {
            other = RegionCounts::of_gaussian(obs, other_first);
        }
        if other.counts.len() > self.counts.len() {
            std::mem::swap(self, &mut other);
        }
        self.add(&other.counts);
    }

    /// Adds the observations of the single Gaussians `members` (none of them in the
    /// segment) to the counts of the segment whose lowest Gaussian is `first`: what
    /// [`RegionCounts::absorb`] of their [`RegionCounts::of_gaussians`] gives, their counts
    /// built in the thread's lists rather than in new ones where they are few.
    fn absorb_gaussians(
        &mut self,
        first: usize,
        members: impl Iterator<Item = u32> + Clone,
        obs: &Observations,
    ) {
        let observations: usize = members.clone().map(|g| obs.row(g as usize).len()).sum();
        if observations >= COUNT_BY_VIEW_FROM {
            let members: Vec<u32> = members.collect();
            let theirs = RegionCounts::of_gaussians(obs, &members);
            return self.absorb(first, theirs, members[0] as usize, obs);
        }
        if self.counts.is_empty() {
            *self = RegionCounts::of_gaussian(obs, first);
        }
        MEMBERS_SCRATCH.with_borrow_mut(|Scratch(seen, counts)| {
            seen.clear();
            let rows = members.map(|g| obs.row(g as usize));
            seen.extend(rows.flat_map(|row| row.map(|i| (obs.view[i], obs.region[i]))));
            seen.sort_unstable();
            counts.clear();
            let runs = seen.chunk_by(|a, b| a == b);
            counts.extend(runs.map(|run| (run[0].0, run[0].1, run.len() as u32)));
            self.add(counts);
        });
    }

    /// Adds `other`, (view, region, observations) sorted as the counts, to a segment's
    /// built counts, and sets the dominant region of each view it names.
    fn add(&mut self, other: &[(u32, u32, u32)]) {
        if self.dominant.is_empty() {
            self.dominant = self.counts.clone();
        }
        ADD_SCRATCH.with_borrow_mut(|Scratch(fresh, new_views)| {
            // `other`'s entries are sorted as `self`'s, so each search starts where the
            // last ended (most joins: a Gaussian's few dozen views into a segment's
            // thousands of entries; binary searches of the whole list were a third of the
            // ordered joins).
            fresh.clear();
            new_views.clear();
            let mut at = 0;
            for &(view, region, count) in other {
                at += partition_point_near(&self.counts[at..], |e| (e.0, e.1) < (view, region));
                match self.counts.get_mut(at) {
                    Some(e) if (e.0, e.1) == (view, region) => e.2 += count,
                    _ => fresh.push((view, region, count)),
                }
            }
            merge_sorted_into(&mut self.counts, fresh);
            let (mut run, mut entry) = (0, 0);
            for view in other
                .chunk_by(|a, b| a.0 == b.0)
                .map(|entries| entries[0].0)
            {
                run += partition_point_near(&self.counts[run..], |e| e.0 < view);
                let d = self.dominant_from(run, view);
                entry += partition_point_near(&self.dominant[entry..], |e| e.0 < view);
                match self.dominant.get_mut(entry) {
                    Some(e) if e.0 == view => *e = d,
                    _ => new_views.push(d),
                }
            }
            merge_sorted_into(&mut self.dominant, new_views);
        });
    }

    /// (view, dominant region, observations) of one view, from the counts.
    fn dominant_in(&self, view: u32) -> (u32, u32, u32) {
        self.dominant_from(self.counts.partition_point(|e| e.0 < view), view)
    }

    /// [`RegionCounts::dominant_in`], the view's counts starting at `first`.
    fn dominant_from(&self, first: usize, view: u32) -> (u32, u32, u32) {
        let (mut best, mut total) = ((view, 0, 0), 0);
        for &(_, region, count) in self.counts[first..].iter().take_while(|e| e.0 == view) {
            total += count;
            if count > best.2 {
                best = (view, region, count);
            }
        }
        (view, best.1, total)
    }

    /// Per view: (view, dominant region, observations the view holds), by view, once the
    /// counts are built.
    fn table(&self) -> &[(u32, u32, u32)] {
        match self.dominant.is_empty() {
            true => &self.counts,
            false => &self.dominant,
        }
    }

    /// The dominant regions of the segment whose lowest Gaussian is `first`.
    pub fn dominant<'a>(&'a self, first: usize, obs: &'a Observations) -> Dominant<'a> {
        match self.counts.is_empty() {
            true => Dominant::Row {
                view: &obs.view[obs.row(first)],
                region: &obs.region[obs.row(first)],
            },
            false => Dominant::Table(self.table()),
        }
    }
}

thread_local! {
    /// [`RegionCounts::add`]'s lists of new entries, and [`RegionCounts::absorb_gaussians`]'s
    /// of the Gaussians' observations and counts: reused by the thread join after join. The
    /// single Gaussians joined in rounds are added on every core, under the one malloc arena
    /// the CLI's threads share (src/util/memory.rs), where lists allocated for each join kept
    /// the threads waiting on each other.
    static ADD_SCRATCH: RefCell<Scratch<(u32, u32, u32)>> = const { Scratch::new() };
    static MEMBERS_SCRATCH: RefCell<Scratch<(u32, u32)>> = const { Scratch::new() };
}

/// Two lists a thread keeps for its next use (the second of (view, region, observations)).
struct Scratch<T>(Vec<T>, Vec<(u32, u32, u32)>);

impl<T> Scratch<T> {
    const fn new() -> RefCell<Scratch<T>> {
        RefCell::new(Scratch(Vec::new(), Vec::new()))
    }
}

/// From this many observations a piece's region counts are counted view by view
/// ([`counts_by_view`]) rather than sorted ([`counts_sorted`]).
const COUNT_BY_VIEW_FROM: usize = 4096;

/// (view, region, observations) of `members`, sorted: every observation sorted, then
/// counted in runs. For small pieces (most), where a list per view would cost more, and for
/// flagged segments (src/fuse/consensus_flags.rs), which may lie in many regions of a view.
pub(crate) fn counts_sorted(obs: &Observations, members: &[u32]) -> Vec<(u32, u32, u32)> {
    counts_sorted_of(obs, members, &obs.region)
}

/// [`counts_sorted`] of any per-observation value (`of`: `obs.region`, `obs.label`):
/// (view, value, observations), sorted. From [`SORT_BY_VIEW_FROM`] observations (a flagged
/// wall: millions) the values are first bucketed by view and each view's sorted on its
/// own, on every core, where one sort of them all ran on one core.
pub(crate) fn counts_sorted_of(
    obs: &Observations,
    members: &[u32],
    of: &[u32],
) -> Vec<(u32, u32, u32)> {
    debug_assert_eq!(of.len(), obs.view.len(), "one value per observation");
    let rows = || members.iter().map(|&g| obs.row(g as usize));
    let observations = rows().map(|row| row.len()).sum::<usize>();
    if observations >= SORT_BY_VIEW_FROM {
        return counts_sorted_by_view(obs, members, of);
    }
    // Sized once, not grown by doubling: fewer allocations on the worker threads, each of
    // which takes the one malloc arena's lock (src/util/memory.rs).
    let mut seen: Vec<(u32, u32)> = Vec::with_capacity(observations);
    seen.extend(rows().flat_map(|row| row.map(|i| (obs.view[i], of[i]))));
    seen.sort_unstable();
    let runs = seen.chunk_by(|a, b| a == b);
    runs.map(|run| (run[0].0, run[0].1, run.len() as u32))
        .collect()
}

/// From this many observations [`counts_sorted_of`] sorts view by view.
pub(crate) const SORT_BY_VIEW_FROM: usize = 1 << 16;

/// [`counts_sorted_of`] by a counting sort of the values by view, then each view's values
/// sorted and counted in runs, blocks of views on every core. The values are scattered
/// into their views' places directly: grouping the observations' indices by view with
/// [`Groups`] and then reading each value through its index took 2-3x as long on a flagged
/// wall of 4.6M observations (a random read per value, two more arrays). The counting sort
/// itself runs in runs of members on every core, each run writing its own part of each
/// view's place: on one core it took a sixteen-thread model's longest item of the flags'
/// two passes (15 ms each of a capture's flagged wall, util::scaling).
fn counts_sorted_by_view(obs: &Observations, members: &[u32], of: &[u32]) -> Vec<(u32, u32, u32)> {
    let runs: Vec<&[u32]> = members.chunks(GAUSSIANS_PER_RUN).collect();
    let per_run = parallel_map(runs.len(), |r| {
        let mut of_view: Vec<usize> = Vec::new();
        for i in runs[r].iter().flat_map(|&g| obs.row(g as usize)) {
            let view = obs.view[i] as usize;
            if view >= of_view.len() {
                of_view.resize(view + 1, 0);
            }
            of_view[view] += 1;
        }
        of_view
    });
    let views = per_run.iter().map(Vec::len).max().unwrap_or(0);
    let count = |r: usize, view: usize| per_run[r].get(view).copied().unwrap_or(0);
    // Each view's place, within it each run's part: part `view * runs + r`.
    let lens = (0..views).flat_map(|view| (0..runs.len()).map(move |r| count(r, view)));
    let mut start = vec![0usize; views + 1];
    for view in 0..views {
        start[view + 1] = start[view] + (0..runs.len()).map(|r| count(r, view)).sum::<usize>();
    }
    let mut values = vec![0u32; start[views]];
    let parts = split_parts(&mut values, lens.collect::<Vec<_>>());
    parallel_map(runs.len(), |r| {
        let mut of_view: Vec<_> = (0..views)
            .map(|view| take_part(&parts[view * runs.len() + r]))
            .collect();
        let mut next = vec![0usize; views];
        for i in runs[r].iter().flat_map(|&g| obs.row(g as usize)) {
            let view = obs.view[i] as usize;
            of_view[view][next[view]] = of[i];
            next[view] += 1;
        }
    });
    drop(parts);
    const VIEWS_PER_BLOCK: usize = 8;
    let blocks = parallel_map(views.div_ceil(VIEWS_PER_BLOCK), |b| {
        let mut counts = Vec::new();
        for view in b * VIEWS_PER_BLOCK..views.min((b + 1) * VIEWS_PER_BLOCK) {
            let mut of_view = values[start[view]..start[view + 1]].to_vec();
            of_view.sort_unstable();
            let runs = of_view.chunk_by(|a, b| a == b);
            counts.extend(runs.map(|run| (view as u32, run[0], run.len() as u32)));
        }
        counts
    });
    blocks.concat()
}

/// [`counts_sorted`], counted per view in a short list of (region, observations): a piece
/// of outright joins lies in one region of nearly every view that sees it, so each
/// observation is a search of a list of one or two, where sorting a wall's millions of
/// observations on one core took most of the pieces' time (0.56-0.81 of 0.65-0.93 s on a
/// noisy 1080p office, docs/robustness-log.md). A wall's members are counted in runs on every
/// core, each run's lists then summed view by view: on one core it was a sixteen-thread
/// model's longest item of the pieces' counts (8 of 45 ms, util::scaling).
fn counts_by_view(obs: &Observations, members: &[u32]) -> Vec<(u32, u32, u32)> {
    let runs: Vec<&[u32]> = members.chunks(GAUSSIANS_PER_RUN).collect();
    let mut per_run = parallel_map(runs.len(), |r| regions_by_view(obs, runs[r]));
    let mut per_view = per_run.pop().unwrap_or_default();
    for run in per_run {
        if run.len() > per_view.len() {
            per_view.resize_with(run.len(), Vec::new);
        }
        for (sum, regions) in per_view.iter_mut().zip(run) {
            for (region, count) in regions {
                add_to_region(sum, region, count);
            }
        }
    }
    let mut counts = Vec::new();
    for (view, mut regions) in per_view.into_iter().enumerate() {
        regions.sort_unstable();
        counts.extend(regions.into_iter().map(|(r, c)| (view as u32, r, c)));
    }
    counts
}

/// Per view, the (region, observations) of `members`, in no order.
fn regions_by_view(obs: &Observations, members: &[u32]) -> Vec<Vec<(u32, u32)>> {
    let mut per_view: Vec<Vec<(u32, u32)>> = Vec::new();
    for &g in members {
        for i in obs.row(g as usize) {
            let (view, region) = (obs.view[i] as usize, obs.region[i]);
            if view >= per_view.len() {
                per_view.resize_with(view + 1, Vec::new);
            }
            add_to_region(&mut per_view[view], region, 1);
        }
    }
    per_view
}

/// Adds `count` to `region`'s entry of a view's short list.
fn add_to_region(regions: &mut Vec<(u32, u32)>, region: u32, count: u32) {
    match regions.iter_mut().find(|e| e.0 == region) {
        Some(entry) => entry.1 += count,
        None => regions.push((region, count)),
    }
}

/// A segment's dominant region per view, by view: (view, region, observations the view
/// holds).
#[derive(Clone, Copy, Debug)]
pub enum Dominant<'a> {
    /// A single Gaussian's observations, read in place: one per view, each its own region.
    Row { view: &'a [u32], region: &'a [u32] },
    /// A joined segment's table ([`RegionCounts`]).
    Table(&'a [(u32, u32, u32)]),
}

impl Dominant<'_> {
    fn len(&self) -> usize {
        match self {
            Dominant::Row { view, .. } => view.len(),
            Dominant::Table(table) => table.len(),
        }
    }

    fn at(&self, i: usize) -> (u32, u32, u32) {
        match self {
            Dominant::Row { view, region } => (view[i], region[i], 1),
            Dominant::Table(table) => table[i],
        }
    }

    /// The entry of `view`, searched from `*from` on (the lookups of ascending views go
    /// forward from where the last ended, which `from` keeps).
    fn find_from(&self, from: &mut usize, view: u32) -> Option<(u32, u32, u32)> {
        *from += match self {
            Dominant::Row { view: views, .. } => {
                partition_point_near(&views[*from..], |&v| v < view)
            }
            Dominant::Table(table) => partition_point_near(&table[*from..], |e| e.0 < view),
        };
        Some(*from)
            .filter(|&i| i < self.len())
            .map(|i| self.at(i))
            .filter(|e| e.0 == view)
    }

    /// Of the views that observed both segments, weighed by the fewer of the two segments'
    /// observations each holds: how much say their dominant regions are the same, how much
    /// different. A view that glimpsed one Gaussian of a segment says little about where the
    /// segment lies (one ceiling Gaussian seen at a frame's edge beside a shelf kept two
    /// halves of a ceiling apart, and flicker then decided each half on a few views); a
    /// ceiling and its wall are both seen whole in the views that keep them apart.
    pub fn agreement(&self, other: &Dominant) -> (u64, u64) {
        // Each view of the segment seen in fewer views is looked up in the other's.
        let (few, many) = match self.len() <= other.len() {
            true => (self, other),
            false => (other, self),
        };
        let (mut same, mut differ, mut at) = (0, 0, 0);
        for i in 0..few.len() {
            let (view, region, count) = few.at(i);
            if let Some((_, other_region, other_count)) = many.find_from(&mut at, view) {
                let say = count.min(other_count) as u64;
                match region == other_region {
                    true => same += say,
                    false => differ += say,
                }
            }
        }
        (same, differ)
    }
}

/// Whether two segments may join: their pairs' evidence allows it, and their dominant regions
/// disagree in at most `region_max_disagree` of the views that saw both, weighed as in
/// [`Dominant::agreement`] (a segment seen by many views is tested on all of them, not on
/// the few its edge pairs share).
pub fn may_join(evidence: &PairEvidence, a: Dominant, b: Dominant, p: &ConsensusParams) -> bool {
    if !evidence.allows_join(p) {
        return false;
    }
    let (same, differ) = a.agreement(&b);
    differ as f64 <= p.region_max_disagree * (same + differ) as f64
}

/// A candidate join in the queue: those with a neighbour pair along a surface first, then
/// highest priority (both in [`PairEvidence::queue_key`]), then most views together, then the
/// smaller [`size_class`] of the larger segment, then the lowest segment ids. Stale once
/// the pair's evidence gives another (order, together) or a join another size class: a
/// candidate whose evidence changed without changing those stands where its requeued copy
/// would, so taking it with the current evidence decides the same.
///
/// Packed in three words compared as unsigned integers, greatest first: a comparison is
/// three integer compares rather than five of mixed types, and the queue's compares are a
/// large part of the ordered joins (0.47 -> 0.45 s on a noisy 1080p office, 2 cores).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Candidate {
    /// [`PairEvidence::queue_key`] with its sign bit flipped (so unsigned order is signed
    /// order).
    key: u64,
    /// Views together (high half), then the size class, smaller greater (low half).
    together_class: u64,
    /// The two segments, lower ids greater: `!a` (high half), `!b` (low half).
    ids: u64,
}

impl Candidate {
    fn new(key: i64, together: u32, size_class: u32, a: u32, b: u32) -> Candidate {
        Candidate {
            key: key as u64 ^ (1 << 63),
            together_class: (together as u64) << 32 | !size_class as u64,
            ids: (!a as u64) << 32 | !b as u64,
        }
    }

    /// The band of [`PairEvidence::queue_key`] the candidate falls in: one view's worth of
    /// priority (candidates along a surface in bands above all others).
    fn band(&self) -> i64 {
        ((self.key ^ (1 << 63)) as i64).div_euclid(PRIORITY_ONE)
    }

    /// The two segments (the lower first).
    fn segments(&self) -> (u32, u32) {
        (!(self.ids >> 32) as u32, !self.ids as u32)
    }
}

/// Segment id per Gaussian (numbered by first Gaussian). Every segment starts as one Gaussian
/// and is named by its lowest Gaussian index. Candidates (adjacent segments with their summed
/// [`PairEvidence`]) are taken those with a pair along a surface (`surfaces`) first, then
/// in order of [`PairEvidence::priority`] (ties: more views together, then the smaller
/// larger segment, then the lowest ids); one that [`may_join`] joins, any other is dropped
/// until its evidence or that size class changes (a join adds pairs to it, or Gaussians to
/// one of its segments).
pub fn cluster_segments(
    obs: &Observations,
    knn: &[u32],
    surfaces: &SurfaceNormals,
    p: &ConsensusParams,
) -> Vec<u32> {
    cluster_segments_timed(obs, knn, surfaces, p).0.segment
}

/// [`cluster_segments`], and where its time went.
pub fn cluster_segments_timed(
    obs: &Observations,
    knn: &[u32],
    surfaces: &SurfaceNormals,
    p: &ConsensusParams,
) -> (Clustered, ClusterProfile) {
    cluster(obs, knn, surfaces, p, SWEEP_FROM)
}

/// Where the clustering's time went (host seconds) and how much it did: what a profile
/// of a scene's clustering needs first (`bench fuse --json` reports it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ClusterProfile {
    /// Numbering the Gaussians in space, before the views (timed by the caller:
    /// [`super::consensus_order::SpatialOrder::of`]; in the method's `wall_s`, not in its
    /// `view_s` or `segments_s`).
    pub order_s: f64,
    /// The wait, after the views, for each Gaussian's nearest neighbours, the graph
    /// clustered (timed by the caller, which searches them beside the views:
    /// [`super::neighbours::nearest_neighbours`]).
    pub neighbours_s: f64,
    /// What the views said of every neighbour pair ([`co_occurrence`], on every core).
    pub pairs_s: f64,
    /// The outright joins ([`premerge`]), the pieces' region counts and adjacency...
    pub pieces_s: f64,
    /// ...split: the outright joins, the adjacency, the region counts.
    pub outright_s: f64,
    pub adjacency_s: f64,
    pub piece_regions_s: f64,
    /// The joins: the candidates sorted, then taken one at a time, among the pieces and
    /// then among all segments (`joins_s`), the single Gaussians attached between
    /// (`attach_s`) not included.
    pub joins_s: f64,
    /// Of `joins_s`, the ordered joins among the pieces ([`Clustering::Rounds`] only).
    pub pieces_joins_s: f64,
    /// The single Gaussians joined in rounds ([`Clustering::Rounds`] only).
    pub attach_s: f64,
    /// Neighbour pairs, the segments the ordered joins start from (pieces and single
    /// Gaussians), the candidates they start with, the joins they make and the segments
    /// at the end.
    pub pairs: usize,
    pub pieces: usize,
    pub candidates: usize,
    pub joins: usize,
    /// Of `joins`, the single Gaussians attached in rounds, and the rounds.
    pub attached: usize,
    pub attach_rounds: usize,
    pub segments: usize,
    /// Near ties split along their last join after the clustering
    /// ([`super::consensus_split`]; not in `segments`), and the time that took (not in
    /// `joins_s`).
    pub split: usize,
    pub split_s: f64,
    /// The ordered joins' queue: candidates taken from it (most of them stale: a segment
    /// joined another since, or the evidence changed), those tested ([`may_join`]), and
    /// those a join queued again.
    pub popped: usize,
    pub tested: usize,
    pub requeued: usize,
}

/// A heap of requeued candidates smaller than this is not swept ([`Queue::sweep_if_dead`]):
/// it stays in the cache (24 bytes a candidate). From 2^16 as long as sweeps waited for the
/// heap to grow by half: 0.29-0.30 -> 0.26-0.28 s of a capture's ordered joins, swept when
/// half may be dead from 2^12 (2 cores; from 2^8, 2^10: the same).
const SWEEP_FROM: usize = 1 << 12;

/// [`cluster_segments`], its heap swept of candidates whose segment joined another from
/// `sweep_from` candidates on. The segments do not depend on it (the tests sweep from 0,
/// which small scenes otherwise never reach).
pub fn cluster_segments_sweeping_from(
    obs: &Observations,
    knn: &[u32],
    surfaces: &SurfaceNormals,
    p: &ConsensusParams,
    sweep_from: usize,
) -> Vec<u32> {
    cluster(obs, knn, surfaces, p, sweep_from).0.segment
}

/// The clustering, its heap swept from `sweep_from` candidates on, and what it did.
fn cluster(
    obs: &Observations,
    knn: &[u32],
    surfaces: &SurfaceNormals,
    p: &ConsensusParams,
    sweep_from: usize,
) -> (Clustered, ClusterProfile) {
    let mut done = ClusterProfile::default();
    let mut laps = Laps::start();
    let pairs = neighbour_pairs(obs, knn, surfaces, p.neighbours);
    (done.pairs, done.pairs_s) = (pairs.len(), laps.lap());
    let mut graph = SegmentGraph::new(obs, pairs, p, &mut done);
    done.pieces_s = laps.lap();
    done.pieces = graph.parent.len();
    if p.clustering == Clustering::Rounds {
        let mut queue = Queue::new(&graph, p, sweep_from, Among::Pieces);
        done.candidates = queue.sorted.len();
        join_in_order(&mut graph, &mut queue, p, &mut done, Among::Pieces);
        done.pieces_joins_s = laps.lap();
        attach::attach_single_gaussians(&mut graph, p, &mut done);
        done.attach_s = laps.lap();
    }
    let mut queue = Queue::new(&graph, p, sweep_from, Among::All);
    done.candidates += queue.sorted.len();
    join_in_order(&mut graph, &mut queue, p, &mut done, Among::All);
    let (root, part) = graph.roots_and_parts();
    let roots = graph.segment_of_gaussians(&root);
    let last_half = graph.last_halves(&root, &part);
    done.joins_s = laps.lap() + done.pieces_joins_s;
    done.segments = done.pieces - done.joins;
    let segment = renumber(&roots);
    (Clustered { segment, last_half }, done)
}

/// The clustering's segments, and per Gaussian whether it lies in its segment's last
/// joined half ([`SegmentGraph::last_halves`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Clustered {
    /// Segment per Gaussian, numbered by first Gaussian.
    pub segment: Vec<u32>,
    pub last_half: Vec<bool>,
}

/// Which segments the ordered joins take candidates between.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Among {
    /// Segments of two Gaussians or more: the pieces and what they joined, before the
    /// single Gaussians attach ([`attach::attach_single_gaussians`]).
    Pieces,
    /// Every segment.
    All,
}

impl Among {
    fn takes(self, graph: &SegmentGraph, a: u32, b: u32) -> bool {
        self == Among::All || graph.size[a as usize].min(graph.size[b as usize]) > 1
    }
}

/// The ordered joins: the queue's candidates taken best first, each that [`may_join`]
/// joined, the candidates it changed queued again (those `among` takes).
fn join_in_order(
    graph: &mut SegmentGraph,
    queue: &mut Queue,
    p: &ConsensusParams,
    done: &mut ClusterProfile,
    among: Among,
) {
    let mut changed = Vec::new();
    while let Some(queued) = queue.pop() {
        done.popped += 1;
        let (a, b) = queued.segments();
        if !graph.segments.holds(a) || !graph.segments.holds(b) {
            continue; // joined another segment (most stale candidates: no adjacency lookup needed)
        }
        let current = graph.edges[a as usize].get(b);
        let Some(evidence) = current.filter(|&e| graph.candidate(a, b, e, p) == queued) else {
            continue; // a segment joined another, or the evidence grew: queued again since
        };
        done.tested += 1;
        if may_join(&evidence, graph.dominant(a), graph.dominant(b), p) {
            done.joins += 1;
            graph.join(a, b, &mut changed);
            queue.joined(b);
            for &(c, e) in changed.iter().filter(|(_, e)| e.allows_join(p)) {
                if among.takes(graph, a, c) {
                    let (lo, hi) = (a.min(c), a.max(c));
                    queue.push(graph.candidate(lo, hi, e, p));
                    done.requeued += 1;
                }
            }
            queue.sweep_if_dead(&graph.segments);
        }
    }
}

/// The candidates, greatest first: the neighbour pairs' in one sorted list, and those a
/// join changed in a heap. Most candidates are the pairs', and a heap of millions of them
/// spent most of the clustering's time on cache misses; sorted once, they are read in order.
/// A candidate whose evidence does not allow a join ([`PairEvidence::allows_join`]) is never
/// queued: taken, it would be refused (the evidence it holds is the pair's until a join
/// changes it, and that queues it again), so the segments are the same.
struct Queue {
    /// Ascending: the greatest at the end.
    sorted: Vec<Candidate>,
    heap: QuadHeap<Candidate>,
    /// Per segment, the heap's candidates naming it.
    in_heap: Vec<u32>,
    /// The heap's candidates named by the segments that joined another since the last
    /// sweep (some popped since, some counted for both segments).
    dead: usize,
    /// The least heap swept.
    sweep_from: usize,
}

impl Queue {
    /// Every candidate whose evidence allows a join, sorted: ranges of segments listed
    /// and sorted on every core, then merged (a candidate is one pair of segments, so the
    /// order of equal items never arises).
    fn new(graph: &SegmentGraph, p: &ConsensusParams, sweep_from: usize, among: Among) -> Queue {
        let ranges = runs_of_weight(graph.edges.iter().map(Adjacent::len), 1 << 16);
        let runs = parallel_map(ranges.len(), |r| {
            let mut run = Vec::new();
            for a in ranges[r].clone() {
                let a = a as u32;
                run.extend(
                    (graph.edges[a as usize].iter())
                        .filter(|&(b, e)| a < b && e.allows_join(p) && among.takes(graph, a, b))
                        .map(|(b, e)| graph.candidate(a, b, e, p)),
                );
            }
            run.sort_unstable();
            run
        });
        let sorted = merge_sorted_runs(runs);
        Queue {
            sorted,
            heap: QuadHeap::new(),
            in_heap: vec![0; graph.parent.len()],
            dead: 0,
            sweep_from,
        }
    }

    /// Queues a candidate a join changed.
    fn push(&mut self, candidate: Candidate) {
        let (a, b) = candidate.segments();
        self.in_heap[a as usize] += 1;
        self.in_heap[b as usize] += 1;
        self.heap.push(candidate);
    }

    /// Segment `b` joined another: its candidates in the heap are dead.
    fn joined(&mut self, b: u32) {
        self.dead += self.in_heap[b as usize] as usize;
    }

    /// Drops the heap's candidates whose segment joined another, once the joins since the
    /// last sweep named half as many of its candidates as it holds (and it holds
    /// `sweep_from`). Most candidates the ordered joins take are such (955k of a capture's
    /// 1.19M), and each in the heap would cost a pop through its levels; a sweep reads the
    /// heap once, in order. A candidate is named at most twice in all (once per segment),
    /// so the sweeps' reads are at most four times the pushes.
    fn sweep_if_dead(&mut self, segments: &SegmentSet) {
        if self.heap.len() < self.sweep_from || 2 * self.dead < self.heap.len() {
            return;
        }
        let in_heap = &mut self.in_heap;
        self.heap.retain(|c| {
            let (a, b) = c.segments();
            let live = segments.holds(a) && segments.holds(b);
            if !live {
                in_heap[a as usize] -= 1;
                in_heap[b as usize] -= 1;
            }
            live
        });
        self.dead = 0;
    }

    fn pop(&mut self) -> Option<Candidate> {
        let from_heap = match (self.sorted.last(), self.heap.peek()) {
            (Some(s), Some(h)) => h > s,
            (Some(_), None) => false,
            (None, _) => true,
        };
        if !from_heap {
            return self.sorted.pop();
        }
        let taken = self.heap.pop()?;
        let (a, b) = taken.segments();
        self.in_heap[a as usize] -= 1;
        self.in_heap[b as usize] -= 1;
        Some(taken)
    }
}

/// A segment of `size` Gaussians in the candidates' order: its size's binary digits. Among
/// candidates of equal evidence, those whose larger segment is smaller join first, so a
/// surface's single Gaussians join each other before a large neighbour takes them one by
/// one. Which goes first in such ties otherwise went by the Gaussians' numbers: on the
/// office of seed 3 under flicker 0.3 (a dump of its observations), numbered in space, a
/// wall took 41% of the ceiling, Gaussian by Gaussian through those seen only by views that
/// called the ceiling wall (docs/robustness-log.md, "Ties by size"). Classes rather than sizes: a join changes a
/// segment's class only when its size crosses a power of two, which is when its other
/// candidates are queued again.
fn size_class(size: u32) -> u32 {
    32 - size.leading_zeros()
}

/// A neighbour pair of Gaussians (the lower first) and what the views said of it.
type Pair = (u32, u32, PairEvidence);

/// Every neighbour pair once, with what the views said of it and whether it lies along a
/// surface (on every core: millions of Gaussians). A pair listed in both rows comes from
/// the lower Gaussian's.
fn neighbour_pairs(
    obs: &Observations,
    knn: &[u32],
    surfaces: &SurfaceNormals,
    k: usize,
) -> Vec<Pair> {
    const BLOCK: usize = 4096;
    let lists = |g: usize| &knn[g * k..(g + 1) * k];
    let from_g = |g: usize, h: u32| {
        let from_h = (h as usize) < g && lists(h as usize).contains(&(g as u32));
        h != NO_NEIGHBOUR && h as usize != g && !from_h
    };
    let (blocks, block) = (obs.n.div_ceil(BLOCK), |b: usize| {
        b * BLOCK..obs.n.min((b + 1) * BLOCK)
    });
    let counts = parallel_map(blocks, |b| {
        let of_g = |g| lists(g).iter().filter(|&&h| from_g(g, h)).count();
        block(b).map(of_g).sum::<usize>()
    });
    // Counted first, so each block writes its part of one list in place, on its thread.
    collect_parts(counts, |b| {
        block(b).flat_map(move |g| {
            let pairs_of_g = lists(g).iter().filter(move |&&h| from_g(g, h));
            pairs_of_g.map(move |&h| (g as u32, h, pair_evidence(obs, surfaces, g, h as usize)))
        })
    })
}

/// What the views said of neighbours `g` and `h` ([`co_occurrence`]), as the evidence of one
/// pair.
fn pair_evidence(
    obs: &Observations,
    surfaces: &SurfaceNormals,
    g: usize,
    h: usize,
) -> PairEvidence {
    let c = co_occurrence(obs, g, h);
    PairEvidence {
        together: c.together,
        apart: c.apart,
        on_edge: c.on_edge,
        pairs: 1,
        pairs_along: surfaces.along(g, h) as u32,
    }
}

/// Each Gaussian's piece (its lowest Gaussian) after the outright joins: neighbour pairs
/// that at least `premerge_views` views saw, every one of them in one region with neither
/// center on its edge, those views being at least `premerge_common_share` of the views that
/// saw either Gaussian ([`ConsensusParams::premerge_views`]; 0: every Gaussian alone). Such
/// a pair would pass every test of [`may_join`] as two single Gaussians, and most of an
/// object's interior is such pairs; the ordered joins, one at a time, are left the rest.
/// Union-find under the lowest index, so the pieces do not depend on the pairs' order;
/// the pairs tested and joined on every core ([`SharedSets`]).
fn premerge(obs: &Observations, pairs: &[Pair], p: &ConsensusParams) -> Vec<u32> {
    let n = obs.n;
    if p.premerge_views == 0 {
        return (0..n as u32).collect();
    }
    let seen_by = |g: u32| obs.row(g as usize).len() as f64;
    let outright = |&(g, h, e): &Pair| {
        let unanimous = e.together >= p.premerge_views && e.apart == 0 && e.on_edge == 0;
        // Views that saw either: each Gaussian's, less the `together` that saw both.
        let either = seen_by(g) + seen_by(h) - e.together as f64;
        unanimous && e.together as f64 >= p.premerge_common_share * either
    };
    let sets = SharedSets::new(n);
    let blocks: Vec<&[Pair]> = pairs.chunks(1 << 16).collect();
    parallel_map(blocks.len(), |b| {
        for &(g, h, _) in blocks[b].iter().filter(|pair| outright(pair)) {
            sets.union(g, h);
        }
    });
    sets.roots()
}

/// The region counts of every piece of more than one Gaussian ([`premerge`]; `members`:
/// the `n` pieces' Gaussians), on every core; a single Gaussian has none (its observations
/// are read in place). The pieces go to the threads in runs of about [`GAUSSIANS_PER_RUN`]
/// Gaussians: a segmenter's scene holds a few hundred such pieces, a handful of them walls
/// (a noisy 1080p office: 712, the largest five of 84k to 199k Gaussians), and runs of a
/// fixed number of pieces put them all on one thread.
fn piece_regions(obs: &Observations, members: &Groups, n: usize) -> SegmentRegions {
    let pieces: Vec<u32> = (0..n as u32)
        .filter(|&s| members.group(s as usize).len() > 1)
        .collect();
    let sizes = pieces.iter().map(|&s| members.group(s as usize).len());
    let runs = runs_of_weight(sizes, GAUSSIANS_PER_RUN);
    let built = parallel_map(runs.len(), |r| {
        (pieces[runs[r].clone()].iter())
            .map(|&s| RegionCounts::of_gaussians(obs, members.group(s as usize)))
            .collect::<Vec<_>>()
    });
    let mut regions = SegmentRegions::new(n);
    for (&s, counts) in pieces.iter().zip(built.into_iter().flatten()) {
        regions.put(s, counts);
    }
    regions
}

/// The pieces of the outright joins, numbered 0.. in order of their lowest Gaussian, the
/// ids the ordered joins work with: a capture's 977k Gaussians make 221k pieces, and the
/// joins' tables (adjacency, parents, sizes, region slots, queued counts) indexed by piece
/// rather than by Gaussian are a fifth of the size, which keeps more of them in the cache.
/// Numbered in the order of their lowest Gaussians, ties between candidates go as by
/// Gaussian ids.
struct Pieces {
    /// Each Gaussian's piece.
    of_gaussian: Vec<u32>,
    /// Each piece's lowest Gaussian (whose observations are a piece of one's).
    first: Vec<u32>,
}

impl Pieces {
    /// The pieces of `roots` (each Gaussian's piece by its lowest member), on every core.
    fn of(roots: &[u32]) -> Pieces {
        const BLOCK: usize = 1 << 16;
        let blocks = roots.len().div_ceil(BLOCK);
        let firsts = parallel_map(blocks, |b| {
            let block = b * BLOCK..roots.len().min((b + 1) * BLOCK);
            block
                .filter(|&g| roots[g] as usize == g)
                .map(|g| g as u32)
                .collect::<Vec<u32>>()
        });
        let first: Vec<u32> = firsts.concat();
        let mut number = vec![0u32; roots.len()];
        for (piece, &g) in first.iter().enumerate() {
            number[g as usize] = piece as u32;
        }
        let of_gaussian = map_in_blocks(roots.len(), BLOCK, |g| number[roots[g] as usize]);
        Pieces { of_gaussian, first }
    }
}

/// The region counts of the segments that hold them, by segment (its first piece): a slot
/// per piece and the counts in a list, where a [`RegionCounts`] for every Gaussian took 48
/// bytes each, defaults written on the one core the ordered joins run on (17-22 ms of a
/// capture's 977k Gaussians), though only the pieces of several Gaussians and the segments
/// joins make ever hold counts.
struct SegmentRegions {
    /// Per segment, its counts' index in `held`, or [`SegmentRegions::NONE`].
    slot: Vec<u32>,
    held: Vec<RegionCounts>,
    /// Indices in `held` whose segment joined another.
    free: Vec<u32>,
}

impl SegmentRegions {
    const NONE: u32 = u32::MAX;

    fn new(n: usize) -> SegmentRegions {
        SegmentRegions {
            slot: vec![Self::NONE; n],
            held: Vec::new(),
            free: Vec::new(),
        }
    }

    /// Segment `s`'s counts (empty where it holds none: a single Gaussian).
    fn of(&self, s: u32) -> &RegionCounts {
        static NO_COUNTS: RegionCounts = RegionCounts {
            counts: Vec::new(),
            dominant: Vec::new(),
        };
        match self.slot[s as usize] {
            Self::NONE => &NO_COUNTS,
            at => &self.held[at as usize],
        }
    }

    /// Segment `s`'s counts, taken out (empty where it holds none).
    fn take(&mut self, s: u32) -> RegionCounts {
        match std::mem::replace(&mut self.slot[s as usize], Self::NONE) {
            Self::NONE => RegionCounts::default(),
            at => {
                self.free.push(at);
                std::mem::take(&mut self.held[at as usize])
            }
        }
    }

    /// Gives segment `s` (which holds none) its counts.
    fn put(&mut self, s: u32, counts: RegionCounts) {
        let at = match self.free.pop() {
            Some(at) => {
                self.held[at as usize] = counts;
                at
            }
            None => {
                self.held.push(counts);
                (self.held.len() - 1) as u32
            }
        };
        self.slot[s as usize] = at;
    }
}

/// Per segment after the outright joins (`piece`: each Gaussian's piece, of `pieces`), the
/// adjacent segments with the evidence of the pairs between them.
fn piece_adjacency(pairs: &[Pair], piece: &[u32], pieces: usize) -> Vec<Adjacent> {
    let between = pairs_between_pieces(pairs, piece);
    let mut degree = vec![0u32; pieces];
    for &(a, b, _) in &between {
        degree[a as usize] += 1;
        degree[b as usize] += 1;
    }
    // Sized once rather than grown pair by pair (a million lists and maps), here, on one
    // thread: under the one malloc arena (src/util/memory.rs) the threads below would wait
    // on each other's allocations. A piece's degree counts its pairs, so it may get room
    // for more segments than it meets.
    let mut edges: Vec<Adjacent> = (degree.iter())
        .map(|&d| Adjacent::with_capacity(d as usize))
        .collect();
    // Filled on every core: each thread a range of segments of about equal degree, for
    // which it reads every pair between pieces (a pass over them is a small part of the
    // additions).
    let total = degree.iter().map(|&d| d as usize).sum::<usize>();
    let ranges = runs_of_weight(degree.iter().map(|&d| d as usize), total / cores() + 1);
    let parts = split_parts(&mut edges, ranges.iter().map(|r| r.len()));
    parallel_map(parts.len(), |r| {
        let (mut part, first) = (take_part(&parts[r]), ranges[r].start);
        let mut add = |a: u32, b: u32, e: PairEvidence| {
            let at = (a as usize).checked_sub(first);
            if let Some(adjacent) = at.and_then(|i| part.get_mut(i)) {
                adjacent.add(b, e);
            }
        };
        for &(a, b, e) in &between {
            add(a, b, e);
            add(b, a, e);
        }
    });
    drop(parts);
    edges
}

/// The neighbour pairs whose Gaussians lie in two pieces, as pairs of pieces, in order, on
/// every core: what each thread of [`piece_adjacency`] reads, where every pair was (a
/// capture's 3.9M pairs, 125 MB read by every thread; a quarter of them between pieces).
fn pairs_between_pieces(pairs: &[Pair], piece: &[u32]) -> Vec<Pair> {
    const BLOCK: usize = 1 << 16;
    let blocks: Vec<&[Pair]> = pairs.chunks(BLOCK).collect();
    let of_pieces = |&(g, h, e): &Pair| {
        let (a, b) = (piece[g as usize], piece[h as usize]);
        (a != b).then_some((a, b, e))
    };
    let counts = parallel_map(blocks.len(), |b| {
        blocks[b].iter().filter_map(of_pieces).count()
    });
    collect_parts(counts, |b| blocks[b].iter().filter_map(of_pieces))
}

/// The segments while they join: per segment (by its first piece) the adjacent segments
/// with the summed evidence, and its region counts.
struct SegmentGraph<'a> {
    obs: &'a Observations,
    /// The pieces the ordered joins start from, numbered in order of their lowest Gaussian.
    pieces: Pieces,
    edges: Vec<Adjacent>,
    regions: SegmentRegions,
    /// Each piece's segment at the time it joined (a lower index, or itself).
    parent: Vec<u32>,
    /// Per segment, how many Gaussians it holds.
    size: Vec<u32>,
    /// The pieces that name a segment (`parent` of themselves).
    segments: SegmentSet,
    /// Per piece, when the ordered joins joined it into its `parent` (the count of joins
    /// before), or [`NOT_JOINED`]: what [`SegmentGraph::last_halves`] reads.
    joined_at: Vec<u32>,
    joins: u32,
}

/// [`SegmentGraph::joined_at`] of a piece no ordered join took (a segment's root, or a
/// single Gaussian attached in rounds).
const NOT_JOINED: u32 = u32::MAX;

/// The part of a segment that joined it last and is a half: at least this share of the
/// segment's Gaussians, so that the fragments joined after it (edges, slivers) do not
/// hide the join that made it ([`SegmentGraph::last_halves`]).
const HALF_SHARE: u32 = 10;

impl<'a> SegmentGraph<'a> {
    /// The graph after the outright joins ([`premerge`]): its segments are those pieces and
    /// the remaining Gaussians, adjacent through the neighbour pairs between them.
    fn new(
        obs: &'a Observations,
        pairs: Vec<Pair>,
        p: &ConsensusParams,
        done: &mut ClusterProfile,
    ) -> SegmentGraph<'a> {
        let mut laps = Laps::start();
        let pieces = Pieces::of(&premerge(obs, &pairs, p));
        done.outright_s = laps.lap();
        let count = pieces.first.len();
        let edges = piece_adjacency(&pairs, &pieces.of_gaussian, count);
        done.adjacency_s = laps.lap();
        let members = Groups::by_key(&pieces.of_gaussian, count);
        let size = (0..count).map(|s| members.group(s).len() as u32).collect();
        let regions = piece_regions(obs, &members, count);
        done.piece_regions_s = laps.lap();
        SegmentGraph {
            obs,
            pieces,
            edges,
            regions,
            parent: (0..count as u32).collect(),
            size,
            segments: SegmentSet::all(count),
            joined_at: vec![NOT_JOINED; count],
            joins: 0,
        }
    }

    fn candidate(&self, a: u32, b: u32, e: PairEvidence, p: &ConsensusParams) -> Candidate {
        let larger = self.size[a as usize].max(self.size[b as usize]);
        Candidate::new(
            e.queue_key(p.apart_weight),
            e.together,
            size_class(larger),
            a,
            b,
        )
    }

    /// Segment `s`'s dominant regions.
    fn dominant(&self, s: u32) -> Dominant<'_> {
        let first = self.pieces.first[s as usize] as usize;
        self.regions.of(s).dominant(first, self.obs)
    }

    /// Per piece, its segment's root, and the part directly under the root that it lies in
    /// (itself for a root). A joined piece's parent is lower, so pieces resolve in order,
    /// except a single Gaussian attached to a segment ([`attach::attach_single_gaussians`]):
    /// that segment's root, not its own, is resolved after.
    fn roots_and_parts(&self) -> (Vec<u32>, Vec<u32>) {
        let n = self.parent.len();
        let (mut root, mut part): (Vec<u32>, Vec<u32>) = ((0..n as u32).collect(), vec![0; n]);
        let mut attached = Vec::new();
        let resolve = |s: usize, root: &mut [u32], part: &mut [u32]| {
            let parent = self.parent[s] as usize;
            root[s] = root[parent];
            part[s] = match parent == root[s] as usize {
                true => s as u32,
                false => part[parent],
            };
        };
        for s in 0..n {
            match self.parent[s] as usize {
                parent if parent == s => part[s] = s as u32,
                parent if parent < s => resolve(s, &mut root, &mut part),
                _ => attached.push(s),
            }
        }
        for s in attached {
            resolve(s, &mut root, &mut part); // a segment of pieces: resolved above
        }
        (root, part)
    }

    /// Per Gaussian, whether it lies in the half of its segment that joined the rest last:
    /// of the parts the ordered joins joined into the segment's root, the last one that
    /// holds at least 1/[`HALF_SHARE`] of its Gaussians (none: no Gaussian of it is).
    /// What a near tie may be split along ([`super::consensus_split`]). `root`, `part`:
    /// [`SegmentGraph::roots_and_parts`].
    fn last_halves(&self, root: &[u32], part: &[u32]) -> Vec<bool> {
        let n = self.parent.len();
        // Per root, its last part of at least the share (the join count, the part).
        let mut last = vec![(NOT_JOINED, NOT_JOINED); n];
        for s in (0..n).filter(|&s| part[s] == s as u32 && root[s] != s as u32) {
            let r = root[s] as usize;
            let at = self.joined_at[s];
            let half = HALF_SHARE * self.size[s] >= self.size[r];
            if at != NOT_JOINED && half && (last[r].0 == NOT_JOINED || at > last[r].0) {
                last[r] = (at, s as u32);
            }
        }
        map_in_blocks(self.pieces.of_gaussian.len(), 1 << 16, |g| {
            let piece = self.pieces.of_gaussian[g] as usize;
            last[root[piece] as usize].1 == part[piece]
        })
    }

    /// Each Gaussian's segment, named by its lowest Gaussian (`root`: per piece, its
    /// segment's root piece).
    fn segment_of_gaussians(&self, root: &[u32]) -> Vec<u32> {
        let of_piece = |piece: u32| self.pieces.first[root[piece as usize] as usize];
        map_in_blocks(self.pieces.of_gaussian.len(), 1 << 16, |g| {
            of_piece(self.pieces.of_gaussian[g])
        })
    }

    /// Joins segment `b` into `a` (a < b, or `b` a single Gaussian); `changed` gets the segments whose evidence with
    /// `a` changed, and those whose candidate with `a` changed by its size class alone,
    /// with that evidence (a buffer reused over the joins).
    fn join(&mut self, a: u32, b: u32, changed: &mut Vec<(u32, PairEvidence)>) {
        let (ai, bi) = (a as usize, b as usize);
        self.parent[bi] = a;
        self.joined_at[bi] = self.joins;
        self.joins += 1;
        self.segments.remove(b);
        let size_before = self.size[ai];
        self.size[ai] += self.size[bi];
        let taken = self.regions.take(b);
        let mut joined = self.regions.take(a);
        let (a_first, b_first) = (self.pieces.first[ai], self.pieces.first[bi]);
        joined.absorb(a_first as usize, taken, b_first as usize, self.obs);
        self.regions.put(a, joined);
        let mut moved = std::mem::take(&mut self.edges[bi]);
        moved.remove(a);
        self.edges[ai].remove(b);
        changed.clear();
        // Each adjacent segment's list is a cache miss: asked for all at once, they overlap.
        for (c, _) in moved.iter() {
            prefetch(&self.edges[c as usize]);
            prefetch(&self.size[c as usize]);
        }
        for (c, _) in moved.iter() {
            self.edges[c as usize].prefetch();
        }
        for (c, e) in moved.iter() {
            let sum = self.edges[ai].add(c, e);
            self.edges[c as usize].rename(b, a, sum);
            changed.push((c, sum));
        }
        // The segments whose candidate with `a` changed only by `a`'s size class.
        let class = |a_size: u32, c: u32| size_class(a_size.max(self.size[c as usize]));
        if size_class(self.size[ai]) != size_class(size_before) {
            let resized = (self.edges[ai].iter())
                .filter(|&(c, _)| moved.get(c).is_none())
                .filter(|&(c, _)| class(size_before, c) != class(self.size[ai], c));
            changed.extend(resized);
        }
    }
}

/// Which pieces name a segment (a segment is named by its first piece), a bit each: most
/// candidates the ordered joins take name a segment that joined another, and this is what
/// tells (a capture's 221k pieces: 28 KiB of bits, where their parents are 0.9 MB).
struct SegmentSet {
    bits: Vec<u64>,
}

impl SegmentSet {
    /// Segments `0..n`.
    fn all(n: usize) -> SegmentSet {
        let mut bits = vec![u64::MAX; n.div_ceil(64)];
        if !n.is_multiple_of(64) {
            bits[n / 64] = (1 << (n % 64)) - 1;
        }
        SegmentSet { bits }
    }

    fn holds(&self, s: u32) -> bool {
        self.bits[s as usize / 64] >> (s % 64) & 1 == 1
    }

    /// Segment `s` joined another.
    fn remove(&mut self, s: u32) {
        self.bits[s as usize / 64] &= !(1 << (s % 64));
    }
}

/// Dense ids numbered by first appearance; `keys` are under their count (a segment's
/// lowest Gaussian), so a table of them replaces a hash map (a million Gaussians' lookups
/// 0.009 -> 0.002 s, on the one core the clustering ends on).
pub(crate) fn renumber(keys: &[u32]) -> Vec<u32> {
    let mut id = vec![u32::MAX; keys.len()];
    let mut next = 0;
    keys.iter()
        .map(|&k| {
            let slot = &mut id[k as usize];
            if *slot == u32::MAX {
                (*slot, next) = (next, next + 1);
            }
            *slot
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuse::consensus_adjacent::LIST_MAX;
    use crate::util::Rng;
    use std::collections::HashMap;

    /// The heap's candidates are counted per segment as they are queued and taken; a sweep
    /// waits until the joins since the last named half as many as the heap holds, then
    /// drops those with a joined segment, and the counts follow.
    #[test]
    fn queue_sweeps_once_half_may_be_dead() {
        let mut queue = Queue {
            sorted: Vec::new(),
            heap: QuadHeap::new(),
            in_heap: vec![0; 6],
            dead: 0,
            sweep_from: 0,
        };
        for (key, a, b) in [(5, 0, 1), (4, 0, 2), (3, 1, 3), (2, 2, 3), (1, 4, 5)] {
            queue.push(Candidate::new(key, 1, 1, a, b));
        }
        assert_eq!(queue.in_heap, [2, 2, 2, 2, 1, 1]);
        let mut segments = SegmentSet::all(6);
        segments.remove(1);
        queue.joined(1);
        queue.sweep_if_dead(&segments);
        assert_eq!(queue.heap.len(), 5, "2 of 5 named dead: no sweep yet");
        segments.remove(3);
        queue.joined(3);
        queue.sweep_if_dead(&segments);
        assert_eq!(queue.heap.len(), 2, "(0, 2) and (4, 5) left");
        assert_eq!(queue.in_heap, [1, 0, 1, 0, 1, 1]);
        assert_eq!(queue.pop().map(|c| c.segments()), Some((0, 2)));
        assert_eq!(queue.pop().map(|c| c.segments()), Some((4, 5)));
        assert_eq!((queue.pop(), queue.in_heap), (None, vec![0; 6]));
    }

    /// Pieces are numbered in the order of their lowest Gaussians, each Gaussian mapped to
    /// its own piece, on every core (blocks of 2^16: a scene of several); and the set of
    /// segments starts with every piece and loses those removed.
    #[test]
    fn pieces_numbered_by_lowest_gaussian() {
        let mut rng = Rng::new(3);
        let n = 200_000;
        let mut roots = vec![0u32; n];
        for g in 0..n {
            let root = match g == 0 || rng.below(4) == 0 {
                true => g as u32,                             // a piece of its own
                false => roots[rng.below(g as u64) as usize], // another's piece
            };
            roots[g] = root;
        }
        let pieces = Pieces::of(&roots);
        let firsts: Vec<u32> = (0..n as u32).filter(|&g| roots[g as usize] == g).collect();
        assert_eq!(pieces.first, firsts);
        for (g, (&piece, &root)) in pieces.of_gaussian.iter().zip(&roots).enumerate() {
            assert_eq!(pieces.first[piece as usize], root, "Gaussian {g}");
        }
        for count in [1, 63, 64, 65, 130] {
            let mut set = SegmentSet::all(count);
            set.remove(count as u32 - 1);
            let held: Vec<bool> = (0..count as u32).map(|s| set.holds(s)).collect();
            assert!(
                held[..count - 1].iter().all(|&h| h) && !held[count - 1],
                "{count}"
            );
            assert_eq!(set.bits.len(), count.div_ceil(64));
            let total: u32 = set.bits.iter().map(|w| w.count_ones()).sum();
            assert_eq!(total as usize, count - 1, "no bit past the last segment");
        }
    }

    /// Segments' counts kept by slot: each segment reads back what it was given, a
    /// segment given none reads empty, and a freed place is given to the next.
    #[test]
    fn segment_regions_hold_each_segments_own_counts() {
        let counts = |v: u32| RegionCounts {
            counts: vec![(v, v + 1, 2)],
            dominant: Vec::new(),
        };
        let mut regions = SegmentRegions::new(6);
        regions.put(4, counts(4));
        regions.put(1, counts(1));
        assert_eq!(regions.of(4), &counts(4));
        assert_eq!(regions.of(0), &RegionCounts::default());
        assert_eq!(regions.take(4), counts(4));
        assert_eq!(regions.take(4), RegionCounts::default(), "taken once");
        regions.put(5, counts(5));
        assert_eq!(regions.held.len(), 2, "segment 5 took segment 4's place");
        assert_eq!((regions.of(1), regions.of(5)), (&counts(1), &counts(5)));
    }

    /// Ids by first appearance, as a map from key to the next id numbers them.
    #[test]
    fn renumber_numbers_keys_by_first_appearance() {
        let mut rng = Rng::new(21);
        let n = 5000;
        let keys: Vec<u32> = (0..n).map(|_| rng.below(n as u64 / 7) as u32 * 7).collect();
        let mut id = HashMap::new();
        let expected: Vec<u32> = (keys.iter())
            .map(|&k| {
                let next = id.len() as u32;
                *id.entry(k).or_insert(next)
            })
            .collect();
        assert_eq!(renumber(&keys), expected);
        assert!(id.len() > 100, "{} distinct keys", id.len());
    }

    /// The adjacency built on every core holds for each segment what a plain map, summed
    /// pair by pair, holds: pieces of random sizes (a few past the lists' length, so maps
    /// too), random pairs, some within a piece.
    #[test]
    fn piece_adjacency_sums_every_pair_between_pieces() {
        let mut rng = Rng::new(9);
        let n = 4000;
        let mut piece = vec![0u32; n];
        let mut first = 0;
        for (g, p) in piece.iter_mut().enumerate() {
            if g < 100 || rng.below(50) == 0 {
                first = g; // 100 single Gaussians, then pieces of about 50
            }
            *p = first as u32;
        }
        let mut draw = |most: u64| rng.below(most) as u32;
        let pairs: Vec<(u32, u32, PairEvidence)> = (0..30_000)
            .map(|_| {
                let (g, h) = (draw(n as u64), draw(n as u64));
                let e = PairEvidence {
                    together: draw(9),
                    apart: draw(3),
                    on_edge: draw(3),
                    pairs: 1,
                    pairs_along: draw(2),
                };
                (g.min(h), g.max(h), e)
            })
            .collect();
        let built = piece_adjacency(&pairs, &piece, n);
        let mut plain: Vec<HashMap<u32, PairEvidence>> = vec![HashMap::new(); n];
        for &(g, h, e) in &pairs {
            let (a, b) = (piece[g as usize], piece[h as usize]);
            if a != b {
                plain[a as usize].entry(b).or_default().add(e);
                plain[b as usize].entry(a).or_default().add(e);
            }
        }
        assert!(plain.iter().any(|m| m.len() > LIST_MAX), "a map among them");
        for (s, expected) in plain.iter().enumerate() {
            let got: HashMap<u32, PairEvidence> = built[s].iter().collect();
            assert_eq!(&got, expected, "segment {s}");
        }
    }

    /// The packed candidates order as the tuple they pack: first key (signed), views
    /// together, the smaller size class, the lower first id, the lower second id.
    #[test]
    fn candidates_order_as_their_fields() {
        use std::cmp::Reverse;
        let mut rng = Rng::new(4);
        let mut pick = |values: &[i64]| values[rng.below(values.len() as u64) as usize];
        let keys = [i64::MIN, -(1 << 40), -3, -1, 0, 1, 7, 1 << 50, i64::MAX];
        let small = [0, 1, 2, 31, 32, u32::MAX as i64];
        type Fields = (i64, u32, Reverse<u32>, Reverse<u32>, Reverse<u32>);
        let drawn: Vec<(Candidate, Fields)> = (0..400)
            .map(|_| {
                let (key, together, class) =
                    (pick(&keys), pick(&small) as u32, pick(&small) as u32);
                let (a, b) = (pick(&small) as u32, pick(&small) as u32);
                let tuple = (key, together, Reverse(class), Reverse(a), Reverse(b));
                let packed = Candidate::new(key, together, class, a, b);
                assert_eq!(packed.segments(), (a, b));
                (packed, tuple)
            })
            .collect();
        for (x, tx) in &drawn {
            for (y, ty) in &drawn {
                assert_eq!(x.cmp(y), tx.cmp(ty), "{tx:?} against {ty:?}");
            }
        }
    }

    /// Observations of `n` Gaussians, Gaussian `g` seen by each of its first `views(g)`
    /// views with odds of 2 in 3, the `v`-th as `draw(rng, v)`: (view, region). No labels,
    /// no edges.
    fn drawn_observations(
        rng: &mut Rng,
        n: usize,
        views: impl Fn(usize) -> u32,
        mut draw: impl FnMut(&mut Rng, u32) -> (u32, u32),
    ) -> Observations {
        let mut offsets = vec![0];
        let (mut view, mut region) = (Vec::new(), Vec::new());
        for g in 0..n {
            for v in 0..views(g) {
                if rng.below(3) > 0 {
                    let (drawn_view, drawn_region) = draw(rng, v);
                    view.push(drawn_view);
                    region.push(drawn_region);
                }
            }
            offsets.push(view.len());
        }
        let m = view.len();
        Observations {
            n,
            offsets,
            view,
            label: vec![0; m],
            region,
            edge: vec![false; m],
        }
    }

    /// Single Gaussians added to a segment at once (`absorb_gaussians`: a few in the
    /// thread's lists, many counted as a piece's) give the counts and per-view dominant
    /// regions of a plain count of all its Gaussians; so does a segment absorbing a larger
    /// one. Dominant: the region holding most of the view's observations, ties to the lowest
    /// region id, beside the view's total.
    #[test]
    fn gaussians_absorbed_at_once_count_as_the_whole_segment() {
        let mut rng = Rng::new(17);
        let obs = drawn_observations(
            &mut rng,
            3000,
            |_| 40,
            |rng, v| (v, 100 * v + rng.below(3) as u32),
        );
        let plain = |members: &[u32]| {
            let mut counts = std::collections::BTreeMap::new();
            for i in members.iter().flat_map(|&g| obs.row(g as usize)) {
                *counts.entry((obs.view[i], obs.region[i])).or_insert(0u32) += 1;
            }
            let mut dominant: Vec<(u32, u32, u32)> = Vec::new();
            for (&(v, r), &c) in &counts {
                match dominant.last_mut() {
                    Some(d) if d.0 == v => {
                        let best = if counts[&(v, d.1)] < c { r } else { d.1 };
                        *d = (v, best, d.2 + c);
                    }
                    _ => dominant.push((v, r, c)),
                }
            }
            let counts: Vec<(u32, u32, u32)> =
                counts.into_iter().map(|((v, r), c)| (v, r, c)).collect();
            (counts, dominant)
        };
        // (the segment's Gaussians, those joining it): a single Gaussian taking one, a
        // piece taking a few, a piece taking more than COUNT_BY_VIEW_FROM observations.
        let cases: [(Vec<u32>, Vec<u32>); 3] = [
            (vec![5], vec![9]),
            ((100..150).collect(), vec![7, 300, 2999]),
            ((0..10).collect(), (1000..1400).step_by(2).collect()),
        ];
        for (segment, joining) in cases {
            let mut counts = match segment.len() {
                1 => RegionCounts::default(),
                _ => RegionCounts::of_gaussians(&obs, &segment),
            };
            let first = segment[0] as usize;
            counts.absorb_gaussians(first, joining.iter().copied(), &obs);
            let all: Vec<u32> = segment.iter().chain(&joining).copied().collect();
            let (want_counts, want_dominant) = plain(&all);
            assert_eq!(
                counts.counts,
                want_counts,
                "{} + {}",
                segment.len(),
                joining.len()
            );
            assert_eq!(
                counts.table(),
                want_dominant,
                "{} + {}",
                segment.len(),
                joining.len()
            );
            // The other way: the joining Gaussians' segment absorbs the (smaller) segment.
            let mut theirs = RegionCounts::of_gaussians(&obs, &joining);
            let ours = match segment.len() {
                1 => RegionCounts::default(),
                _ => RegionCounts::of_gaussians(&obs, &segment),
            };
            theirs.absorb(joining[0] as usize, ours, first, &obs);
            assert_eq!(theirs.counts, want_counts);
            assert_eq!(theirs.table(), want_dominant);
        }
        let big: usize = (1000..1400).step_by(2).map(|g| obs.row(g).len()).sum();
        assert!(big >= COUNT_BY_VIEW_FROM, "{big}");
    }

    /// Both ways of counting a piece's observations agree, on pieces of one region per
    /// view and of many (each view's regions in no order).
    #[test]
    fn counts_by_view_match_the_sorted_counts() {
        let mut rng = Rng::new(7);
        // The last: a wall in several runs, its later members seen by more views.
        let wall = 2 * GAUSSIANS_PER_RUN + 700;
        for (regions_per_view, n) in [(1, 500), (3, 500), (40, 500), (3, wall)] {
            let views = |g: usize| if g < n / 2 { 30 } else { 34 };
            let obs = drawn_observations(&mut rng, n, views, |rng, v| {
                (v * 7, 1000 * v + rng.below(regions_per_view) as u32 * 13)
            });
            let members: Vec<u32> = (0..n as u32).filter(|_| rng.below(4) > 0).collect();
            let by_view = counts_by_view(&obs, &members);
            assert_eq!(by_view, counts_sorted(&obs, &members));
            let total: u32 = by_view.iter().map(|e| e.2).sum();
            assert!(total as usize >= COUNT_BY_VIEW_FROM, "{total}");
        }
    }

    /// Counted view by view (past `SORT_BY_VIEW_FROM` observations) as a plain ordered map
    /// counts them, regions and labels, views left out and numbered past the members', the
    /// later Gaussians seeing fewer views.
    #[test]
    fn counts_sorted_by_view_match_a_plain_count() {
        let mut rng = Rng::new(9);
        let n = 2 * GAUSSIANS_PER_RUN + 3000;
        let mut offsets = vec![0];
        let (mut view, mut region, mut label) = (Vec::new(), Vec::new(), Vec::new());
        for g in 0..n {
            let views = if g < 2 * n / 3 { 40 } else { 30 };
            for v in 0..views {
                if v % 7 != 3 && rng.below(3) > 0 {
                    view.push(v * 3);
                    region.push(rng.below(200) as u32 * 11);
                    label.push(rng.below(5) as u32);
                }
            }
            offsets.push(view.len());
        }
        let m = view.len();
        let obs = Observations {
            n,
            offsets,
            view,
            label,
            region,
            edge: vec![false; m],
        };
        let members: Vec<u32> = (0..n as u32).filter(|_| rng.below(3) > 0).collect();
        for of in [&obs.region, &obs.label] {
            let mut plain = std::collections::BTreeMap::new();
            for &g in &members {
                for i in obs.row(g as usize) {
                    *plain.entry((obs.view[i], of[i])).or_insert(0u32) += 1;
                }
            }
            let plain: Vec<(u32, u32, u32)> =
                plain.into_iter().map(|((v, x), c)| (v, x, c)).collect();
            let total: u32 = plain.iter().map(|e| e.2).sum();
            assert!(total as usize >= SORT_BY_VIEW_FROM, "{total}");
            assert_eq!(counts_sorted_of(&obs, &members, of), plain);
            // Under the threshold counts_sorted_of sorts them all at once: the same counts.
            let few = &members[..40];
            assert_eq!(
                counts_sorted_by_view(&obs, few, of),
                counts_sorted_of(&obs, few, of)
            );
        }
    }
}
