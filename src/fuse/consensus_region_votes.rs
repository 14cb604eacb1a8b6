//! Segment consensus, the views of a Gaussian its segment does not decide, read through
//! their label regions: a view votes the class that the clearly decided segments observed
//! in the Gaussian's region hold there, not the region's label.
//!
//! Why: such Gaussians (single ones along an object's edges, a table's apron, a box's rim:
//! centers on or near label edges give the clustering nothing to join them by) decide on
//! their own few views. Those are not a fair sample of their object's views: a table's
//! side is seen by the views on that side, and flicker relabels the whole table in a view,
//! so where those views happen to call it the coffee table more often than not, the whole
//! side goes to the coffee table while the table's top, seen by every view, stays a dining
//! table (the living room of seed 3 at flicker 0.3: 246 Gaussians of its rim and side,
//! 6,830 held-out pixels). In each such view the side lies in the table's label region,
//! beside Gaussians of the table's top, which its views decided; so the region says what
//! the flickered label means there. A region whose clear segments split among look-alikes
//! of its label (flicker gave two touching objects one class and merged their regions) says
//! nothing; one none of them was observed in, one whose clear class the views hardly ever
//! take for its label, and one mostly of Gaussians no segment decides (a small object's
//! region eroded by boundary noise) keep their label ([`RegionVoteRule`];
//! docs/robustness-log.md, "Small segments read through their views' regions").

use super::consensus_confusion::{clear_class, ConfusionRates};
use super::consensus_decide::{ConsensusParams, SegmentVotes};
use super::consensus_segments::{Observations, RegionSlots};
use crate::util::parallel_map;
use serde::Serialize;
use std::ops::Range;

/// How a view's label region speaks for the Gaussians in it its segment does not decide.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RegionVoteRule {
    /// A region says a class where that class holds at least this share (> 0.5) of the
    /// observations, off the region's edge, of clearly decided segments (those the
    /// confusions are estimated from: src/fuse/consensus_confusion.rs)...
    pub min_share: f64,
    /// ...and at least this share of all its observations off its edge: a flickered
    /// object's region is mostly its own decided segments, where under boundary noise a
    /// small object's eroded region holds its own undecided fragments and a few of its
    /// neighbour's Gaussians shifted in (the living room at boundary=4: chair legs taken for
    /// the floor)...
    pub min_share_of_all: f64,
    /// ...and the views take that class for the region's label more often than this (the
    /// consensus's confusions): a label that cannot be the class's flicker is an edge
    /// drawn a few pixels off, and stands. The same rate `--relabel`'s regions ask
    /// ([`RelabelRule::max_edge_confusion`]). Where those observations split, and more than
    /// what `min_share` leaves are of classes the views take for the label, the view votes
    /// nothing (a flicker merge); else its label.
    ///
    /// [`RelabelRule::max_edge_confusion`]: super::consensus_relabel::RelabelRule
    pub max_confusion: f64,
}

/// What a view's label region says of the Gaussians in it that read it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum RegionSays {
    /// Its label ([`RegionVoteRule`]).
    Label,
    /// A class the clear segments observed in it hold, one the views take for its label.
    Class(u32),
    /// Its clear segments split among look-alikes of its label: no vote.
    Nothing,
}

/// For the (view, region) pairs some Gaussians read, what each region says.
pub(crate) struct RegionVotes {
    slots: RegionSlots,
    says: Vec<RegionSays>,
}

/// Gaussians per block of the passes over the observations, on average (each block counts
/// into its own copy of the slots' counts). The blocks hold about equal observations:
/// where they held equal Gaussians, the best-seen block took a sixteen-thread model's
/// longest (11 of 112 ms in fifteen blocks on a capture, util::scaling).
const BLOCK: usize = 1 << 16;

/// At least this many blocks for the one pass ([`counted_by_class`]), whose tables are at
/// most [`ONE_PASS_MAX`] counters (a segmenter's scene: tens of thousands): blocks of
/// [`BLOCK`] Gaussians made four of a living room's 206k, 3.6 ms of a sixteen-thread
/// model's decision, where 32 take 0.9 ms (util::scaling).
const ONE_PASS_BLOCKS: usize = 32;

/// A slot's observations off its region's edge.
#[derive(Clone, Copy, Default)]
struct SlotCounts {
    /// All of them.
    observed: u64,
    /// Those of Gaussians of clearly decided segments...
    total: u64,
    /// ...of them, those of the majority candidate's class...
    held: u64,
    /// ...and those of classes, other than the region's label, that the views take for it.
    look_alike: u64,
}

impl RegionVotes {
    /// What the regions of the Gaussians `reads` marks say ([`RegionVoteRule`]), from the
    /// observations of the Gaussians of clearly decided segments ([`clear_class`]) and of
    /// all. `segment`: per Gaussian; `segments`: decided, near ties included.
    pub(crate) fn of(
        obs: &Observations,
        (segment, segments): (&[u32], &[SegmentVotes]),
        reads: &[bool],
        rule: &RegionVoteRule,
        confusions: &ConfusionRates,
        p: &ConsensusParams,
    ) -> RegionVotes {
        assert!(
            rule.min_share > 0.5,
            "a share of a majority finds the class in one pass"
        );
        let read: Vec<usize> = (0..obs.n).filter(|&g| reads[g]).collect();
        let (slots, label) = RegionSlots::of_rows_labelled(obs, &read);
        let clear: Vec<Option<u32>> = segments
            .iter()
            .map(|s| clear_class(s, p).map(|c| c as u32))
            .collect();
        // Each observation in a slot (off its region's edge), as (slot, clear class).
        let in_slots = |g: usize| {
            let class = clear[segment[g] as usize];
            let row = obs.row(g).filter(|&i| !obs.edge[i]);
            let slots = &slots;
            row.filter_map(move |i| slots.slot(obs.view[i], obs.region[i]).map(|at| (at, class)))
        };
        let look_alike =
            |c: u32, l: u32| c != l && confusions.rate(c as usize, l as usize) > rule.max_confusion;
        let classes = clear.iter().flatten().max().map_or(0, |&c| c as usize + 1);
        let blocks =
            |least: usize| obs.runs_of_equal_observations(obs.n.div_ceil(BLOCK).max(least));
        let (candidate, counts) = match slots.len() * (classes + 1) <= ONE_PASS_MAX {
            true => {
                let blocks = blocks(ONE_PASS_BLOCKS);
                counted_by_class(&blocks, classes, &label, &in_slots, &look_alike)
            }
            false => {
                let blocks = blocks(1);
                let candidate = majority_candidates(&blocks, slots.len(), &in_slots);
                let counts = slot_counts(&blocks, &candidate, &label, &in_slots, &look_alike);
                (candidate, counts)
            }
        };
        let holds = |n: u64, all: u64| n as f64 >= rule.min_share * all as f64;
        let says = (0..slots.len())
            .map(|at| {
                let (c, l, n) = (candidate[at].0, label[at], counts[at]);
                match n.total {
                    0 => RegionSays::Label,
                    _ if holds(n.held, n.total)
                        && n.held as f64 >= rule.min_share_of_all * n.observed as f64
                        && look_alike(c, l) =>
                    {
                        RegionSays::Class(c)
                    }
                    all if holds(n.held, all) || holds(all - n.look_alike, all) => {
                        RegionSays::Label
                    }
                    _ => RegionSays::Nothing,
                }
            })
            .collect();
        RegionVotes { slots, says }
    }

    /// Adds Gaussian `g`'s views' votes to `votes`, one per observation: the class its
    /// region says, or its label, or none ([`RegionSays`]); whether any view voted. `g`
    /// must be one of those the regions were found for.
    pub(crate) fn add_votes(&self, obs: &Observations, g: usize, votes: &mut [f64]) -> bool {
        let mut voted = false;
        for i in obs.row(g) {
            let at = self.slots.slot(obs.view[i], obs.region[i]);
            let class = match self.says[at.expect("g reads its regions")] {
                RegionSays::Label => obs.label[i],
                RegionSays::Class(c) => c,
                RegionSays::Nothing => continue,
            };
            votes[class as usize] += 1.0;
            voted = true;
        }
        voted
    }
}

/// Counters per block up to which [`counted_by_class`] counts every slot's classes in one
/// pass over the observations (a segmenter's scene: a few thousand slots of a few dozen
/// classes), where two passes find the majority first ([`majority_candidates`]: a scene
/// of salt noise reads hundreds of thousands of regions).
const ONE_PASS_MAX: usize = 1 << 18;

/// Per slot (`label`: each slot's label), its most frequent class with its count (the
/// majority where one holds more than half: what [`majority_candidates`] finds) and its
/// [`SlotCounts`] with that class held, from one pass counting every (slot, class) of
/// `votes` on every core; `classes` bounds the classes voted.
fn counted_by_class<I: Iterator<Item = (usize, Option<u32>)>>(
    blocks: &[Range<usize>],
    classes: usize,
    label: &[u32],
    votes: &(impl Fn(usize) -> I + Sync),
    look_alike: &(impl Fn(u32, u32) -> bool + Sync),
) -> (Vec<(u32, u64)>, Vec<SlotCounts>) {
    // Per slot, a count per class and last the observations of no clear class.
    let row = classes + 1;
    let blocks = parallel_map(blocks.len(), |b| {
        let mut counts = vec![0u32; label.len() * row];
        for g in blocks[b].clone() {
            for (at, c) in votes(g) {
                counts[at * row + c.map_or(classes, |c| c as usize)] += 1;
            }
        }
        counts
    });
    let mut counts = vec![0u64; label.len() * row];
    for block in blocks {
        counts
            .iter_mut()
            .zip(block)
            .for_each(|(sum, c)| *sum += u64::from(c));
    }
    let summaries = counts.chunks_exact(row).zip(label).map(|(of_slot, &l)| {
        let by_class = &of_slot[..classes];
        let (top, &held) = (by_class.iter().enumerate())
            .max_by_key(|&(c, &count)| (count, std::cmp::Reverse(c)))
            .unwrap_or((0, &0));
        let total: u64 = by_class.iter().sum();
        let sum_where = |keep: &dyn Fn(u32) -> bool| {
            (0..classes as u32)
                .filter(|&c| keep(c))
                .map(|c| by_class[c as usize])
                .sum()
        };
        let counted = SlotCounts {
            observed: total + of_slot[classes],
            total,
            held,
            look_alike: sum_where(&|c| look_alike(c, l)),
        };
        ((top as u32, held), counted)
    });
    summaries.unzip()
}

/// Per slot, the one class that can hold more than half of its votes (the majority vote of
/// Boyer and Moore: a class and its lead, a rival's vote taking one off), from every
/// Gaussian's `votes` (slot, class) on every core; the blocks' candidates merge the same
/// way (a class with more than half of all votes survives any order of merging).
fn majority_candidates<I: Iterator<Item = (usize, Option<u32>)>>(
    blocks: &[Range<usize>],
    slots: usize,
    votes: &(impl Fn(usize) -> I + Sync),
) -> Vec<(u32, u64)> {
    let blocks = parallel_map(blocks.len(), |b| {
        let mut candidate = vec![(0u32, 0u64); slots];
        for g in blocks[b].clone() {
            for (at, c) in votes(g) {
                if let Some(c) = c {
                    candidate[at] = merged(candidate[at], (c, 1));
                }
            }
        }
        candidate
    });
    let mut candidate = vec![(0u32, 0u64); slots];
    for block in blocks {
        for (sum, other) in candidate.iter_mut().zip(block) {
            *sum = merged(*sum, other);
        }
    }
    candidate
}

/// Two (class, lead) summaries as one.
fn merged(a: (u32, u64), b: (u32, u64)) -> (u32, u64) {
    match (a.0 == b.0, a.1 >= b.1) {
        (true, _) => (a.0, a.1 + b.1),
        (false, true) => (a.0, a.1 - b.1),
        (false, false) => (b.0, b.1 - a.1),
    }
}

/// Per slot, its votes counted ([`SlotCounts`]): `candidate` per slot, `label` per slot,
/// `look_alike(class, label)`.
fn slot_counts<I: Iterator<Item = (usize, Option<u32>)>>(
    blocks: &[Range<usize>],
    candidate: &[(u32, u64)],
    label: &[u32],
    votes: &(impl Fn(usize) -> I + Sync),
    look_alike: &(impl Fn(u32, u32) -> bool + Sync),
) -> Vec<SlotCounts> {
    let slots = candidate.len();
    let blocks = parallel_map(blocks.len(), |b| {
        let mut counts = vec![SlotCounts::default(); slots];
        for g in blocks[b].clone() {
            for (at, c) in votes(g) {
                let count = &mut counts[at];
                count.observed += 1;
                let Some(c) = c else { continue };
                count.total += 1;
                count.held += u64::from(candidate[at].0 == c);
                count.look_alike += u64::from(look_alike(c, label[at]));
            }
        }
        counts
    });
    let mut counts = vec![SlotCounts::default(); slots];
    for block in blocks {
        for (sum, x) in counts.iter_mut().zip(block) {
            sum.observed += x.observed;
            sum.total += x.total;
            sum.held += x.held;
            sum.look_alike += x.look_alike;
        }
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    /// Counting every class in one pass agrees with the two passes: the same counts, and
    /// the same class and count held wherever a class holds more than half of a slot.
    #[test]
    fn one_pass_by_class_agrees_with_the_majority_passes() {
        let mut rng = Rng::new(8);
        let (n, slots, classes) = (2 * BLOCK + 99, 60, 5u32);
        // Slot s favours class s % 5 at a rate growing with s; None: no clear class.
        let class_of: Vec<Option<u32>> = (0..n)
            .map(|g| {
                let s = g % slots;
                let c = match rng.f64() < s as f64 / slots as f64 {
                    true => (s % 5) as u32,
                    false => rng.below(6) as u32,
                };
                Some(c).filter(|&c| c < classes)
            })
            .collect();
        let votes = |g: usize| std::iter::once((g % slots, class_of[g]));
        let label: Vec<u32> = (0..slots).map(|s| (s % 3) as u32).collect();
        let look_alike = |c: u32, l: u32| c != l && (c + l) % 2 == 1;
        let blocks = [0..7, 7..BLOCK + 3, BLOCK + 3..n];
        let candidate = majority_candidates(&blocks, slots, &votes);
        let two = slot_counts(&blocks, &candidate, &label, &votes, &look_alike);
        let (top, one) = counted_by_class(&blocks, classes as usize, &label, &votes, &look_alike);
        let mut majorities = 0;
        for s in 0..slots {
            let (a, b) = (&one[s], &two[s]);
            assert_eq!(
                (a.observed, a.total, a.look_alike),
                (b.observed, b.total, b.look_alike),
                "slot {s}"
            );
            if 2 * a.held > a.total {
                majorities += 1;
                assert_eq!((top[s].0, a.held), (candidate[s].0, b.held), "slot {s}");
            }
        }
        assert!((10..slots).contains(&majorities), "{majorities} majorities");
    }

    /// The majority candidate and the counts against a plain count per slot, for random
    /// votes in random blocks; a class holding more than half is always found.
    #[test]
    fn majority_candidates_find_every_majority() {
        let mut rng = Rng::new(5);
        let (n, slots) = (3 * BLOCK + 17, 40);
        // Gaussian g votes (g % slots, class): slot s favours class s % 3 at a rate that
        // grows with s, from none to all; class 5 stands for no clear class.
        let class_of: Vec<u32> = (0..n)
            .map(|g| {
                let s = g % slots;
                match rng.f64() < s as f64 / slots as f64 {
                    true => (s % 3) as u32,
                    false => rng.below(6) as u32,
                }
            })
            .collect();
        let votes = |g: usize| std::iter::once((g % slots, Some(class_of[g]).filter(|&c| c < 5)));
        let blocks: Vec<Range<usize>> =
            (0..n).step_by(BLOCK).map(|g| g..n.min(g + BLOCK)).collect();
        let candidate = majority_candidates(&blocks, slots, &votes);
        let label = vec![0u32; slots];
        let look_alike = |c: u32, l: u32| c != l && c % 2 == 1;
        let got = slot_counts(&blocks, &candidate, &label, &votes, &look_alike);
        for s in 0..slots {
            let mut counts = [0u64; 6];
            (0..n)
                .filter(|g| g % slots == s)
                .for_each(|g| counts[class_of[g] as usize] += 1);
            let all: u64 = counts[..5].iter().sum();
            assert_eq!(got[s].observed, all + counts[5], "slot {s}");
            assert_eq!(got[s].total, all, "slot {s}");
            assert_eq!(got[s].held, counts[candidate[s].0 as usize], "slot {s}");
            assert_eq!(
                got[s].look_alike,
                counts[1] + counts[3],
                "slot {s}: classes 1, 3"
            );
            if let Some(c) = (0..5).find(|&c| 2 * counts[c] > all) {
                assert_eq!(candidate[s].0, c as u32, "slot {s}: a majority");
            }
        }
    }
}
