//! Segment consensus, between the segments and their classes: a segment whose views split
//! near evenly between two classes is split again along the join that made it, where each
//! of the two halves its views decide clearly, and for different classes.
//!
//! With few views the clustering cannot tell two surfaces from one across a crease: a floor
//! seen together with its wall only in the one view that labeled both "wall" (flicker) is
//! joined to it on that view's word, and no view says otherwise. The joined segment's votes
//! then split near evenly (6 wall : 5 floor), and whichever class the near tie goes to,
//! one surface is wrong as a whole (the tiny room at 12 views: 5,977 wall Gaussians decided
//! floor). Each half's own views still tell the two apart (floor 5.5 : wall 2.5, wall
//! 5 : ceiling 1): split, each half takes its class. Only near ties are split: a segment
//! its views decide clearly keeps every join, and a half decided by a near tie of its own
//! is no better evidence than the whole (docs/robustness-log.md, "Near ties split along
//! their last join").

use super::consensus_cluster::{renumber, ClusterProfile, Clustered};
use super::consensus_confusion::tied_classes;
use super::consensus_decide::{
    segment_summary, segment_votes, votes_counted_by_view, ConsensusParams, SegmentVotes,
};
use super::consensus_segments::{Groups, Observations};

/// The segments with each near tie whose halves decide different classes split in two,
/// numbered by first Gaussian again; how many were split and the time it took go into the
/// clustering's profile (`split`, `split_s`).
pub fn split_near_ties(
    obs: &Observations,
    clustered: Clustered,
    classes: usize,
    p: &ConsensusParams,
    done: &mut ClusterProfile,
) -> Vec<u32> {
    let start = std::time::Instant::now();
    let Clustered { segment, last_half } = clustered;
    let count = segment.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
    // The segments both of whose halves hold `min_segment` Gaussians: few, so only their
    // observations are counted (a capture's segments are mostly single Gaussians).
    let mut sizes = vec![[0usize; 2]; count];
    for (&s, &last) in segment.iter().zip(&last_half) {
        sizes[s as usize][last as usize] += 1;
    }
    let halved: Vec<usize> = (0..count)
        .filter(|&s| sizes[s].iter().all(|&n| n >= p.min_segment))
        .collect();
    let mut rank = vec![u32::MAX; count];
    for (i, &s) in halved.iter().enumerate() {
        rank[s] = i as u32;
    }
    // Their halves in one grouping, 2i the rest and 2i + 1 the last half of the i-th; every
    // other Gaussian in one group after them, never counted.
    let others = 2 * halved.len() as u32;
    let half_key: Vec<u32> = (segment.iter().zip(&last_half))
        .map(|(&s, &last)| match rank[s as usize] {
            u32::MAX => others,
            r => 2 * r + last as u32,
        })
        .collect();
    let halves = Groups::by_key(&half_key, 2 * halved.len() + 1);
    let (split, mass, views) = segment_votes(obs, &halves, 2 * halved.len(), classes);
    let summary = |h: usize| {
        let gaussians = halves.group(h).len();
        segment_summary(split[h].clone(), &mass[h], gaussians, views[h], p)
    };
    // Halves first; the whole only where they differ.
    let split_apart: Vec<usize> = (0..halved.len())
        .filter(|&i| {
            let (rest, last) = (summary(2 * i), summary(2 * i + 1));
            let clear = |v: &SegmentVotes| v.class.is_some() && tied_classes(v, p).len() < 2;
            clear(&rest) && clear(&last) && rest.class != last.class
        })
        .filter(|&i| {
            let whole = [halves.group(2 * i), halves.group(2 * i + 1)].concat();
            tied_classes(&votes_of_members(obs, &whole, classes, p), p).len() >= 2
        })
        .collect();
    let halves_apart: Vec<[&[u32]; 2]> = (split_apart.iter())
        .map(|&i| [halves.group(2 * i), halves.group(2 * i + 1)])
        .collect();
    let segment = renumbered_with_halves(&segment, &halves_apart);
    (done.split, done.split_s) = (split_apart.len(), start.elapsed().as_secs_f64());
    segment
}

/// Every segment named by its first Gaussian, each of `apart`'s halves (a split segment's
/// rest and last half) by its own, and numbered by first appearance again (as the
/// clustering numbers them). Unchanged where nothing is apart.
fn renumbered_with_halves(segment: &[u32], apart: &[[&[u32]; 2]]) -> Vec<u32> {
    if apart.is_empty() {
        return segment.to_vec();
    }
    let count = segment.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
    let mut first = vec![u32::MAX; count];
    for (g, &s) in segment.iter().enumerate().rev() {
        first[s as usize] = g as u32;
    }
    let mut key: Vec<u32> = segment.iter().map(|&s| first[s as usize]).collect();
    for half in apart.iter().flatten() {
        let name = *half.first().expect("a half of min_segment Gaussians");
        half.iter().for_each(|&g| key[g as usize] = name);
    }
    renumber(&key)
}

/// The votes of a set of Gaussians (a segment's two halves together) as one segment's.
fn votes_of_members(
    obs: &Observations,
    members: &[u32],
    classes: usize,
    p: &ConsensusParams,
) -> SegmentVotes {
    let (mut split, mut mass) = (vec![0.0; classes], vec![0.0; classes]);
    let views = votes_counted_by_view(obs, members, &mut split, &mut mass);
    let sparse = |dense: &[f64]| -> Vec<(u32, f64)> {
        (dense.iter().enumerate())
            .filter(|&(_, &v)| v != 0.0)
            .map(|(c, &v)| (c as u32, v))
            .collect()
    };
    segment_summary(sparse(&split), &sparse(&mass), members.len(), views, p)
}
