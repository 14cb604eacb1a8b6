//! Segment consensus, the flags' last test: a segment whose views split is flagged only
//! where it is what those views show, not a sliver of it.
//!
//! Why: a fragment at the edge between two objects (a strip of wall behind a shelf, a shelf
//! board between the books on it) lies, in the views that see it, inside a region whose
//! observations are mostly another segment's. Which side of the label edge its center pixels
//! fall on decides its vote, so its views split though none mislabels anything: on the
//! consistent-mislabel sweep at 320x240 such fragments were up to six flags a run. An
//! object its views mislabel is a region of its own, or a large part of one, at least in the
//! views that call it by its own class (docs/robustness-log.md, "Flags on objects, not on
//! slivers").

use super::consensus_cluster::{counts_sorted, counts_sorted_of};
use super::consensus_decide::{ConsensusParams, SegmentVotes};
use super::consensus_segments::{Groups, Observations, RegionSlots};
use crate::util::parallel_map;

/// (view, region, observations): where a segment lies in one view.
type Placement = (u32, u32, u32);

/// Clears the flag of every flagged segment that holds at least `flag_region_share` of the
/// observations of its region in fewer than `flag_region_views` of its views (its region in
/// a view: the one holding most of its observations there).
/// `members`: each segment's Gaussians.
pub(crate) fn unflag_slivers(
    obs: &Observations,
    members: &Groups,
    segments: &mut [SegmentVotes],
    p: &ConsensusParams,
) {
    let flagged = flagged_ids(segments);
    if flagged.is_empty() {
        return;
    }
    let placements = dominant_regions(obs, members, &flagged);
    let totals = region_totals(obs, &placements);
    for ((&s, placed), total) in flagged.iter().zip(&placements).zip(&totals) {
        let as_object = placed
            .iter()
            .zip(total)
            .filter(|(&(.., own), &all)| own as f64 >= p.flag_region_share * all as f64)
            .count();
        if as_object < p.flag_region_views {
            segments[s as usize].flagged = false;
        }
    }
}

/// Sets each flagged segment's [`SegmentVotes::view_classes`]: per view, the class (compact
/// id, the observations' labels) holding most of its observations there, each tied class
/// listed. The segments on every core; the others keep theirs empty.
pub(crate) fn name_views_of_flagged(
    obs: &Observations,
    members: &Groups,
    segments: &mut [SegmentVotes],
) {
    let flagged = flagged_ids(segments);
    let named = parallel_map(flagged.len(), |k| {
        let counts = counts_sorted_of(obs, members.group(flagged[k] as usize), &obs.label);
        let per_view = counts.chunk_by(|a, b| a.0 == b.0);
        let top_of = |run: &[(u32, u32, u32)]| {
            let most = run.iter().map(|e| e.2).max().unwrap_or(0);
            let top = run.iter().filter(move |e| e.2 == most);
            top.map(|&(view, class, _)| (view, class))
                .collect::<Vec<_>>()
        };
        per_view.flat_map(top_of).collect::<Vec<_>>()
    });
    for (&s, views) in flagged.iter().zip(named) {
        segments[s as usize].view_classes = views;
    }
}

/// The ids of the flagged segments, ascending.
pub(crate) fn flagged_ids(segments: &[SegmentVotes]) -> Vec<u32> {
    (0..segments.len() as u32)
        .filter(|&s| segments[s as usize].flagged)
        .collect()
}

/// Per segment of `flagged` (in its order), per view that observes it, the region holding
/// most of its observations there (ties: the lowest region id) and how many; the segments
/// on every core (a flagged wall holds millions of observations, and under salt noise lies
/// in hundreds of regions of a view: they are sorted, not searched).
pub(crate) fn dominant_regions(
    obs: &Observations,
    members: &Groups,
    flagged: &[u32],
) -> Vec<Vec<Placement>> {
    parallel_map(flagged.len(), |k| {
        let counts = counts_sorted(obs, members.group(flagged[k] as usize));
        let mut best: Vec<Placement> = Vec::new();
        for (view, region, count) in counts {
            match best.last_mut() {
                Some(last) if last.0 == view => {
                    if count > last.2 {
                        *last = (view, region, count);
                    }
                }
                _ => best.push((view, region, count)),
            }
        }
        best
    })
}

/// How many observations, of any Gaussian, each placement's region holds in its view (one
/// pass over the observations, on every core, in blocks of 2^18: each block's table is a
/// slot per flagged segment's view, small, and blocks of 2^20 left a living room's 5M
/// observations in five, a sixteen-thread model's 4.5 ms; util::scaling).
pub(crate) fn region_totals(obs: &Observations, placements: &[Vec<Placement>]) -> Vec<Vec<u32>> {
    const BLOCK: usize = 1 << 18;
    let slots = RegionSlots::of(placements.iter().flatten().map(|p| (p.0, p.1)));
    let total = obs.view.len();
    let blocks = parallel_map(total.div_ceil(BLOCK), |b| {
        let mut counts = vec![0u32; slots.len()];
        for i in b * BLOCK..total.min((b + 1) * BLOCK) {
            if let Some(at) = slots.slot(obs.view[i], obs.region[i]) {
                counts[at] += 1;
            }
        }
        counts
    });
    let mut counts = vec![0u32; slots.len()];
    for block in blocks {
        counts.iter_mut().zip(block).for_each(|(sum, c)| *sum += c);
    }
    let total_of = |&(view, region, _): &Placement| {
        counts[slots
            .slot(view, region)
            .expect("every placement's region is asked for")]
    };
    placements
        .iter()
        .map(|placed| placed.iter().map(total_of).collect())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuse::consensus_segments::ViewEntry;
    use crate::util::rng::Rng;

    fn votes(gaussians: usize) -> SegmentVotes {
        SegmentVotes {
            gaussians,
            views: 10,
            split: vec![(0, 6.0), (1, 4.0)],
            class: Some(0),
            near_tie: false,
            flagged: true,
            view_classes: Vec::new(),
        }
    }

    /// Segments 1.. of (Gaussians, views as an object, company), each observed in views
    /// 0..10: a region of its own in the first `own` views, in the others one it shares with
    /// `company` Gaussians of segment 0 (its own company, seen in every view).
    fn scene(flagged: &[(u32, usize, u32)]) -> (Observations, Groups) {
        let mut per_view: Vec<Vec<ViewEntry>> = vec![Vec::new(); 10];
        let mut segment = Vec::new();
        for (k, &(size, own, company)) in flagged.iter().enumerate() {
            let (s, shared) = (k as u32 + 1, 1000 + k as u32);
            for (id, count) in [(s, size), (0, company)] {
                for _ in 0..count {
                    let g = segment.len() as u32;
                    segment.push(id);
                    for (v, list) in per_view.iter_mut().enumerate() {
                        let region = if id == s && v < own { s } else { shared };
                        list.push((g, 0, region, false));
                    }
                }
            }
        }
        let n = segment.len();
        let members = Groups::by_key(&segment, flagged.len() + 1);
        (Observations::from_views(n, &per_view), members)
    }

    #[test]
    fn slivers_lose_their_flag_objects_keep_it() {
        let p = ConsensusParams::default();
        assert_eq!((p.flag_region_views, p.flag_region_share), (5, 0.25));
        let cases = [
            (25, 0, 200, false), // a sliver in every view
            (30, 10, 200, true), // an object in every view
            (30, 4, 200, false), // an object in 4 views, a sliver in the rest
            (30, 5, 200, true),  // ... in 5
            (10, 0, 30, true),   // a quarter of its region in every view
            (10, 0, 31, false),  // just under
        ];
        let (obs, members) = scene(&cases.map(|c| (c.0, c.1, c.2)));
        let sizes = [0].into_iter().chain(cases.map(|c| c.0 as usize));
        let mut segments: Vec<SegmentVotes> = sizes.map(votes).collect();
        segments[0].flagged = false;
        unflag_slivers(&obs, &members, &mut segments, &p);
        let flags: Vec<bool> = segments.iter().map(|s| s.flagged).collect();
        let expected: Vec<bool> = [false].into_iter().chain(cases.map(|c| c.3)).collect();
        assert_eq!(flags, expected);
    }

    /// `views` lists of observations of Gaussians 0..n: in each view a Gaussian is left out
    /// where a draw is divisible by `left_out_one_in`, else observed with the (label,
    /// region) `value` draws.
    fn random_views(
        rng: &mut Rng,
        n: usize,
        views: usize,
        left_out_one_in: u32,
        value: impl Fn(&mut Rng) -> (u32, u32),
    ) -> Vec<Vec<ViewEntry>> {
        let mut view = || {
            let mut list = Vec::new();
            for g in 0..n as u32 {
                if !rng.next_u32().is_multiple_of(left_out_one_in) {
                    let (label, region) = value(rng);
                    list.push((g, label, region, false));
                }
            }
            list
        };
        (0..views).map(|_| view()).collect()
    }

    #[test]
    fn dominant_regions_and_their_totals_match_a_plain_count() {
        let mut rng = Rng::new(3);
        let n = 400;
        let per_view = random_views(&mut rng, n, 7, 3, |rng| (0, rng.next_u32() % 5));
        let obs = Observations::from_views(n, &per_view);
        let segment: Vec<u32> = (0..n).map(|_| rng.next_u32() % 9).collect();
        let flagged = [2u32, 5, 7];
        let placements = dominant_regions(&obs, &Groups::by_key(&segment, 9), &flagged);
        let totals = region_totals(&obs, &placements);
        for (k, &s) in flagged.iter().enumerate() {
            let mut expected = Vec::new();
            for (view, list) in per_view.iter().enumerate() {
                let mut count = [0u32; 5];
                for &(_, _, region, _) in list.iter().filter(|e| segment[e.0 as usize] == s) {
                    count[region as usize] += 1;
                }
                let most = *count.iter().max().unwrap();
                if most > 0 {
                    // The lowest region of the most observations.
                    let region = count.iter().position(|&c| c == most).unwrap() as u32;
                    let all = list.iter().filter(|e| e.2 == region).count() as u32;
                    expected.push(((view as u32, region, most), all));
                }
            }
            let got: Vec<_> = placements[k]
                .iter()
                .copied()
                .zip(totals[k].iter().copied())
                .collect();
            assert_eq!(got, expected, "segment {s}");
        }
    }

    /// Each flagged segment's views under the class most of its observations there have
    /// (every tied class), against a plain count; unflagged segments get none.
    #[test]
    fn flagged_views_are_named_by_their_most_observed_class() {
        let mut rng = Rng::new(5);
        let n = 300;
        let per_view = random_views(&mut rng, n, 6, 4, |rng| (rng.next_u32() % 3, 0));
        let obs = Observations::from_views(n, &per_view);
        let segment: Vec<u32> = (0..n).map(|_| rng.next_u32() % 40).collect();
        let mut segments: Vec<SegmentVotes> = (0..40).map(|_| votes(n / 40)).collect();
        segments
            .iter_mut()
            .step_by(3)
            .for_each(|s| s.flagged = false);
        name_views_of_flagged(&obs, &Groups::by_key(&segment, 40), &mut segments);
        let mut tied_views = 0;
        for (s, votes) in segments.iter().enumerate() {
            let mut expected = Vec::new();
            for (view, list) in per_view.iter().enumerate().filter(|_| votes.flagged) {
                let mut count = [0u32; 3];
                for &(_, class, ..) in list.iter().filter(|e| segment[e.0 as usize] == s as u32) {
                    count[class as usize] += 1;
                }
                let most = *count.iter().max().unwrap();
                let top = (0..3u32).filter(|&c| most > 0 && count[c as usize] == most);
                tied_views += usize::from(top.clone().count() > 1);
                expected.extend(top.map(|c| (view as u32, c)));
            }
            assert_eq!(votes.view_classes, expected, "segment {s}");
        }
        assert!(tied_views > 0, "the scene should hold ties");
    }
}
