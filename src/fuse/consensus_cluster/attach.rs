//! Segment consensus, the clustering's middle phase: the single Gaussians left after the
//! ordered joins among the pieces join segments in rounds.
//!
//! Why rounds rather than the order: most joins of a capture take in one Gaussian (192,179
//! of the 202,624 of a noisy 1080p office), and in the one order they were five sixths of
//! the ordered joins' time, on the one core the order runs on. A single Gaussian can decide
//! alone which segment it joins (its best candidate, as the order would take them), so a
//! round's Gaussians decide on every core, and a round's joins are applied at once, segment
//! by segment, on every core too; each round's work is per Gaussian or per segment, the
//! form a GPU's passes take.

use std::cell::RefCell;
use std::collections::BTreeMap;

use super::{may_join, Candidate, ClusterProfile, PairEvidence, RegionCounts, SegmentGraph};
use crate::fuse::consensus_adjacent::Adjacent;
use crate::fuse::consensus_decide::ConsensusParams;
use crate::util::{map_in_blocks, parallel_map, split_parts, take_part};

/// Attaches the single Gaussians by levels, the bands of one view of priority
/// ([`Candidate::band`]), highest first, each in rounds. At a level a single Gaussian chooses
/// the first of its candidates at the level or above, in the queue's order, that
/// [`may_join`], a segment of several where one may; in a round each Gaussian tested joins
/// its choice if that is a segment of several, or a single Gaussian that chose it too
/// (neither could join a segment of several there); all choices are made on the segments as
/// the round found them. A level's first round tests the Gaussians with a candidate in its
/// band, each next round those one of whose candidates' evidence the last round changed.
///
/// Without the levels a ceiling seen by few views went to its wall Gaussian by Gaussian:
/// those at the crease joined the wall first, and the ceiling's next Gaussians then had
/// pairs along their surface with the wall (office seed 3 under flicker 0.3: 7,420 ceiling
/// Gaussians labeled wall, 146 in the order); the order had taken the ceiling's well-seen
/// pairs first. Without pairs of single Gaussians, a surface seen by few views had no
/// segment of its own to grow (2,225). Pairs formed where a segment of several could take
/// the two, though, made segments of their own beside it that the order would not have
/// (living seed 1: 109 of a speaker's Gaussians decided apart from it, another class).
/// Finer bands (a quarter or a thirty-second of a view), or no ordered joins among the
/// pieces first, changed nothing on the scenes tried.
pub(super) fn attach_single_gaussians(
    graph: &mut SegmentGraph,
    p: &ConsensusParams,
    done: &mut ClusterProfile,
) {
    let single: Vec<u32> = (0..graph.parent.len() as u32)
        .filter(|&s| graph.size[s as usize] == 1 && graph.segments.holds(s))
        .collect();
    // Per piece, the band below the level it was last tested at where its next candidates
    // lie (NO_BAND: none); the levels to come, with the Gaussians waiting for each.
    let mut next_band = vec![NO_BAND; graph.parent.len()];
    let mut waiting: BTreeMap<i64, Vec<u32>> = BTreeMap::new();
    let top = graph.choices(&single, i64::MAX, p);
    graph.wait(&single, &top, &mut next_band, &mut waiting);
    while let Some((level, bucket)) = waiting.pop_last() {
        let mut tested: Vec<u32> = (bucket.into_iter())
            .filter(|&s| next_band[s as usize] == level && graph.segments.holds(s))
            .filter(|&s| graph.size[s as usize] == 1)
            .collect();
        tested.sort_unstable();
        tested.dedup();
        while !tested.is_empty() {
            let chosen = graph.choices(&tested, level, p);
            graph.wait(&tested, &chosen, &mut next_band, &mut waiting);
            let attach = graph.attachments(&tested, &chosen, level, p);
            done.attach_rounds += 1;
            done.attached += attach.len();
            done.joins += attach.len();
            tested = graph.attach_round(attach);
        }
    }
}

thread_local! {
    /// A single Gaussian's candidates while it chooses ([`SegmentGraph::choice`]), the
    /// thread's list reused Gaussian after Gaussian. A list allocated for each (about two
    /// million allocations for a capture's rounds), from the one malloc arena the CLI's
    /// threads share (src/util/memory.rs), kept the cores waiting on each other: the
    /// office at 1080p attached in 1.07-1.22 s on two cores, slower than on one
    /// (docs/robustness-log.md, "The rounds' allocations").
    static CANDIDATES: RefCell<Vec<(Candidate, u32, PairEvidence)>> =
        const { RefCell::new(Vec::new()) };
}

/// No band: no candidate left below.
const NO_BAND: i64 = i64::MIN;

/// A single Gaussian's choice at a level: the segment it joins, if any, and the band of its
/// best candidate below the level.
#[derive(Clone, Copy)]
struct Choice {
    segment: Option<u32>,
    next_band: i64,
}

impl SegmentGraph<'_> {
    /// Per single Gaussian of `singles`, its [`SegmentGraph::choice`] at `level` (on every
    /// core).
    fn choices(&self, singles: &[u32], level: i64, p: &ConsensusParams) -> Vec<Choice> {
        // Blocks of a 256th: the late rounds test a few hundred Gaussians.
        let block = (singles.len() / 256).max(16);
        map_in_blocks(singles.len(), block, |i| self.choice(singles[i], level, p))
    }

    /// The segment the single Gaussian `s` joins at `level`: the first of its candidates
    /// at the level or above, in the queue's order, that [`may_join`]; a segment of several
    /// before any single Gaussian.
    fn choice(&self, s: u32, level: i64, p: &ConsensusParams) -> Choice {
        CANDIDATES.with_borrow_mut(|candidates| self.choice_among(s, level, p, candidates))
    }

    /// [`SegmentGraph::choice`], its candidates listed in `candidates` (the thread's buffer).
    fn choice_among(
        &self,
        s: u32,
        level: i64,
        p: &ConsensusParams,
        candidates: &mut Vec<(Candidate, u32, PairEvidence)>,
    ) -> Choice {
        candidates.clear();
        candidates.extend(
            (self.edges[s as usize].iter())
                .filter(|&(_, e)| e.allows_join(p))
                .map(|(c, e)| (self.candidate(s.min(c), s.max(c), e, p), c, e)),
        );
        candidates.sort_unstable_by_key(|c| std::cmp::Reverse(c.0));
        let at_level = candidates.iter().take_while(|c| c.0.band() >= level);
        let joins = |&&(_, c, e): &&(Candidate, u32, PairEvidence)| {
            may_join(&e, self.dominant(s), self.dominant(c), p)
        };
        let several = |c: &&(Candidate, u32, PairEvidence)| self.size[c.1 as usize] > 1;
        let single = |c: &&(Candidate, u32, PairEvidence)| !several(c);
        let segment = (at_level.clone().filter(several).find(joins))
            .or_else(|| at_level.clone().filter(single).find(joins))
            .map(|&(_, c, _)| c);
        let below = candidates.iter().map(|c| c.0.band()).find(|&b| b < level);
        Choice {
            segment,
            next_band: below.unwrap_or(NO_BAND),
        }
    }

    /// Each tested Gaussian waits for the band of its next candidates.
    fn wait(
        &self,
        tested: &[u32],
        chosen: &[Choice],
        next_band: &mut [i64],
        waiting: &mut BTreeMap<i64, Vec<u32>>,
    ) {
        for (&s, choice) in tested.iter().zip(chosen) {
            next_band[s as usize] = choice.next_band;
            if choice.next_band != NO_BAND {
                waiting.entry(choice.next_band).or_default().push(s);
            }
        }
    }

    /// A round's joins, (segment, Gaussian joining it): each tested Gaussian that chose a
    /// segment of several, and each pair of single Gaussians that chose each other (named
    /// by the lower, listed once; the other's choice made at `level` too if it was not
    /// tested).
    fn attachments(
        &self,
        tested: &[u32],
        chosen: &[Choice],
        level: i64,
        p: &ConsensusParams,
    ) -> Vec<(u32, u32)> {
        let mut asked: Vec<u32> = (chosen.iter().filter_map(|c| c.segment))
            .filter(|&c| self.size[c as usize] == 1 && tested.binary_search(&c).is_err())
            .collect();
        asked.sort_unstable();
        asked.dedup();
        let asked_chosen = self.choices(&asked, level, p);
        let choice_of = |t: u32| match tested.binary_search(&t) {
            Ok(i) => chosen[i].segment,
            Err(_) => asked_chosen[asked.binary_search(&t).expect("asked")].segment,
        };
        (tested.iter().zip(chosen))
            .filter_map(|(&s, c)| match c.segment? {
                c if self.size[c as usize] > 1 => Some((c, s)),
                t if choice_of(t) == Some(s) && (s > t || tested.binary_search(&t).is_err()) => {
                    Some((s.min(t), s.max(t)))
                }
                _ => None,
            })
            .collect()
    }

    /// Joins a round's single Gaussians to their segments, `attach` (segment, Gaussian) by
    /// Gaussian, at once: the segments keep their ids, and the adjacency of every segment a
    /// Gaussian was adjacent to, and the segments' counts, are rebuilt on every core.
    /// Returns the single Gaussians to test next round: those adjacent to one attached
    /// (their evidence with its segment changed).
    fn attach_round(&mut self, mut attach: Vec<(u32, u32)>) -> Vec<u32> {
        for &(segment, s) in &attach {
            self.parent[s as usize] = segment;
            self.segments.remove(s);
        }
        attach.sort_unstable(); // by segment
        let groups: Vec<&[(u32, u32)]> = attach.chunk_by(|a, b| a.0 == b.0).collect();
        // (segment, Gaussian attached this round adjacent to it), by segment.
        let mut adjacent: Vec<(u32, u32)> = (attach.iter())
            .flat_map(|&(_, s)| self.edges[s as usize].iter().map(move |(c, _)| (c, s)))
            .filter(|&(c, _)| self.segments.holds(c))
            .collect();
        adjacent.sort_unstable();
        let mut changed: Vec<u32> = (adjacent.iter().map(|a| a.0))
            .chain(groups.iter().map(|group| group[0].0))
            .collect();
        changed.sort_unstable();
        changed.dedup();
        // Taken out, each updated on a thread of its own, put back.
        let mut lists: Vec<Adjacent> = (changed.iter())
            .map(|&a| std::mem::take(&mut self.edges[a as usize]))
            .collect();
        {
            let graph = &*self;
            let parts = split_parts(&mut lists, std::iter::repeat_n(1, changed.len()));
            let of = |pairs: &'_ [(u32, u32)], a: u32| -> std::ops::Range<usize> {
                let at = pairs.partition_point(|p| p.0 < a);
                at..at + pairs[at..].partition_point(|p| p.0 == a)
            };
            let block = (changed.len() / 256).max(16);
            map_in_blocks(changed.len(), block, |i| {
                let (a, mut list) = (changed[i], take_part(&parts[i]));
                let adjacent = &adjacent[of(&adjacent, a)];
                graph.update_adjacency(a, &mut list[0], adjacent, &attach[of(&attach, a)]);
            });
        }
        for (&a, list) in changed.iter().zip(lists) {
            self.edges[a as usize] = list;
        }
        for &(_, s) in &attach {
            self.edges[s as usize] = Adjacent::default();
        }
        self.grow_segments(&groups);
        // `changed`: the attached Gaussians' neighbours (sorted), and their segments.
        changed.retain(|&c| self.size[c as usize] == 1);
        changed
    }

    /// Each segment of `groups` (segment, Gaussian) takes in its attached Gaussians: their
    /// number, their observations in its region counts (on every core).
    fn grow_segments(&mut self, groups: &[&[(u32, u32)]]) {
        let mut taken: Vec<RegionCounts> = (groups.iter())
            .map(|group| self.regions.take(group[0].0))
            .collect();
        let (obs, first) = (self.obs, &self.pieces.first);
        let parts = split_parts(&mut taken, std::iter::repeat_n(1, groups.len()));
        parallel_map(groups.len(), |i| {
            let counts = &mut take_part(&parts[i])[0];
            // The Gaussians' counts together, then added once: a wall takes in thousands
            // in a round, and each addition merges into its counts.
            let members = groups[i].iter().map(|&(_, s)| first[s as usize]);
            let segment_first = first[groups[i][0].0 as usize] as usize;
            counts.absorb_gaussians(segment_first, members, obs);
        });
        for (group, counts) in groups.iter().zip(taken) {
            let segment = group[0].0;
            self.size[segment as usize] += group.len() as u32;
            self.regions.put(segment, counts);
        }
    }

    /// Segment `a`'s adjacency `list` once the round's Gaussians joined their segments:
    /// each attached Gaussian it was adjacent to (`adjacent`: (a, Gaussian)) named by its
    /// segment, and the adjacency of those joining `a` (`attached`: (a, Gaussian)) added,
    /// the evidence with each segment summed.
    fn update_adjacency(
        &self,
        a: u32,
        list: &mut Adjacent,
        adjacent: &[(u32, u32)],
        attached: &[(u32, u32)],
    ) {
        let segment_of = |c: u32| match self.segments.holds(c) {
            true => c,
            false => self.parent[c as usize], // attached this round
        };
        for &(_, s) in adjacent {
            let e = list.remove(s).expect("adjacency is symmetric");
            if segment_of(s) != a {
                list.add(segment_of(s), e);
            }
        }
        for &(_, s) in attached {
            for (c, e) in self.edges[s as usize].iter() {
                if segment_of(c) != a {
                    list.add(segment_of(c), e);
                }
            }
        }
    }
}
