//! Segment consensus, the decisions (the segments: src/fuse/consensus_cluster.rs): the
//! knobs, each segment's class with every view counted once (near ties by the scene's class
//! confusions: src/fuse/consensus_confusion.rs), each Gaussian's class from its
//! segment (in a small segment its neighbours' segments, else its own views, as where its
//! own views contradict its segment, each view read through its label region:
//! src/fuse/consensus_region_votes.rs; its neighbours' classes where no view observed it), a
//! posterior per Gaussian, and the segments whose vote split is close (flagged, where they
//! are objects in their views rather than slivers at an edge: src/fuse/consensus_flags.rs).

use std::sync::Arc;

use serde::Serialize;

use super::assign::Assignment;
use super::consensus_confusion::{decide_near_ties, ConfusionRates, LOOK_ALIKE_RATE};
use super::consensus_flags::{name_views_of_flagged, unflag_slivers};
use super::consensus_region_votes::{RegionVoteRule, RegionVotes};
use super::consensus_relabel::RelabelRule;
use super::consensus_segments::{Groups, Observations, GAUSSIANS_PER_RUN};
use super::shared_counts::{count_of, SharedCounts, SparseCounts, SparseRowList};
use super::FuseConfig;
use crate::contract::NO_NEIGHBOUR;
use crate::util::{parallel_map, runs_of_weight, Laps};

/// The knobs of segment consensus (defaults: docs/robustness.md).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ConsensusParams {
    /// Observe a Gaussian only where its center is not hidden: within the depth tolerance
    /// of the rendered median depth at its pixel (`vote --occlusion` tests against the
    /// expected depth).
    pub occlusion: bool,
    /// Nearest neighbours each Gaussian may join a segment through.
    pub neighbours: usize,
    /// Two flat Gaussians whose normals are more than this many degrees apart lie across a
    /// crease: the ordered joins take every candidate with a pair along a surface before
    /// those whose pairs all cross a crease (src/fuse/consensus_surface.rs). 90 or more: off.
    pub crease_degrees: f64,
    /// A Gaussian is flat, and its shortest axis its surface's normal, where its middle
    /// scale is at least this many times its shortest.
    pub flat_ratio: f64,
    /// Before the joins in order of evidence, two neighbours join outright where at least
    /// this many views saw both and every one of them put them in one region, neither on its
    /// edge (0: none). The ordered joins then start from these pieces rather than from single
    /// Gaussians: they are most of the joins, each a step of one sequential order, where this
    /// step is one pass of union-find over the pairs (the pieces' counts built on every
    /// core). Such a pair would pass every test as two single Gaussians; what it skips is
    /// waiting for its turn in the order, and the region test of the segments it links. Not
    /// fewer than 6: from 4, a few pairs across a ceiling's edge, seen only by views that
    /// flicker had labeled the ceiling as wall, joined the two (docs/robustness-log.md).
    pub premerge_views: u32,
    /// ...and those views are at least this share of the views that saw either of the two:
    /// where more than a quarter of them saw only one, the views that could have told the
    /// two apart may not have seen both (a rug Gaussian seen by 8 views and a floor one
    /// beside it by 7, both by only the 6 that labeled the rug floor, joined the rug to the
    /// floor).
    pub premerge_common_share: f64,
    /// Two segments join only where the views put the neighbour pairs between them in the
    /// same region this many times (summed over the pairs)...
    pub min_together: u32,
    /// ...put them apart in at most this share of those views (boundary noise moves edges
    /// by a few pixels: a small share of disagreeing views is tolerated)...
    pub max_apart_share: f64,
    /// ...put them together in at least this share of all views seeing them, those that saw
    /// them in one region on its edge included (a floor Gaussian at a wall's foot is seen
    /// with the wall mostly on the label edge, and joined it through the few views that put
    /// both inside the wall's region)...
    pub min_together_share: f64,
    /// ...and the two segments' dominant regions disagree in at most this share of the views
    /// that saw both, each view weighed by the fewer of the two segments' observations it
    /// holds (a ceiling tested against a wall on all their views, not on the few their edge
    /// pairs share; a view that glimpsed one Gaussian of either has little say).
    pub region_max_disagree: f64,
    /// Merge order: one view putting a pair apart outweighs this many putting it together.
    pub apart_weight: f64,
    /// How the segments join after the outright joins: all in one order, or the single
    /// Gaussians in rounds between ordered joins ([`Clustering`]).
    pub clustering: Clustering,
    /// Smaller segments (boundaries, fragments) leave each Gaussian to its neighbours'
    /// segments ([`ConsensusParams::min_segment_neighbours`]), else to its own views.
    pub min_segment: usize,
    /// A Gaussian in a smaller segment takes the class more than half of its neighbours in
    /// decided segments of at least `min_segment` hold, where at least this many are.
    /// Segments stay that small where the views give no joining evidence (center pixels on
    /// label edges: thin parts such as a table's legs, rims); a Gaussian's own few views
    /// there flicker, its neighbours' segments pool many views...
    pub min_segment_neighbours: usize,
    /// ...or, where fewer are but at least this many, where its own views do not contradict
    /// their class (`min_own_views`, `contradiction_p`: the test a segment's members are
    /// held to, at the rate their segments' views give the class): a table's
    /// rim has two or three neighbours in the top's segment and the rest along the rim, and
    /// its own views are the few on its side. 0: off.
    pub few_segment_neighbours: usize,
    /// Then, in this many rounds, every observed Gaussian of a segment under `min_segment`
    /// is decided again from its own views plus one vote per neighbour for the neighbour's
    /// class (each round from the classes at its start). Its few views flicker together,
    /// where a fragment's neighbours are decided on views of their own: a face of a box seen
    /// by one view, which called the box a book, takes the box from the Gaussians around it.
    /// 0: off.
    pub smooth_rounds: usize,
    /// A Gaussian seen in at least this many views keeps its own class where its views
    /// contradict its segment's class...
    pub min_own_views: u32,
    /// ...that is, where so few of them give the segment's class that a view of the segment
    /// (giving it with the segment's rate) would give as few with at most this probability.
    pub contradiction_p: f64,
    /// A Gaussian its segment does not decide counts its own views through their label
    /// regions: a view votes the class that the clearly decided segments observed in its
    /// region hold, where the views take that class for the region's label (a flickered
    /// object); else its label, or nothing where they split (a flicker merge); where no view
    /// votes, its labels (src/fuse/consensus_region_votes.rs). None: each view its label.
    pub region_votes: Option<RegionVoteRule>,
    /// A segment whose top classes are within this many views' votes is a near tie,
    /// decided by the scene's confusions (src/fuse/consensus_confusion.rs)...
    pub tie_margin: f64,
    /// ...and a segment of at least `large_tie_gaussians` Gaussians (a whole object or a
    /// large part of one) also where its top classes are within `large_tie_z` standard
    /// deviations of a fair coin's difference (`large_tie_z` sqrt(a + b) views): its views'
    /// votes are the object's label view by view, so 9 : 7 over sixteen views is as near a
    /// coin flip as 5 : 4 over nine (office seed 3 at flicker 0.3: a window labelled wall
    /// in 9 of its 16 views). A small segment's votes come partly from where it lies (a
    /// strip of wall beside a window takes the window's label in the views whose label edge
    /// is off), which the confusions' independent draws do not model: widening every
    /// segment's ties turned such strips into window and lamps into plant...
    pub large_tie_gaussians: usize,
    /// ...(the z).
    pub large_tie_z: f64,
    /// ...estimated from the segments of at least this many views...
    pub confusion_min_views: usize,
    /// ...whose class holds at least this share of their votes...
    pub confusion_min_share: f64,
    /// ...each class's row smoothed toward a prior worth this many views.
    pub confusion_prior_views: f64,
    /// Dirichlet prior per class of the posterior (0.5: Jeffreys).
    pub prior: f64,
    /// A segment is flagged when its runner-up class holds at least this share of its views
    /// (or it has no decisive class)...
    pub flag_share: f64,
    /// ...that is, at least this many views' votes: a few views differing is what boundary
    /// noise does to a wall's strip beside a shelf; a consistently mislabeled object seen
    /// by twenty views has ten or more against it...
    pub flag_min_dissent: f64,
    /// ...and it has at least this many Gaussians...
    pub flag_min_gaussians: usize,
    /// ...and it is what its views show, not a sliver of it: it holds at least this share of
    /// the observations of the region it lies in...
    pub flag_region_share: f64,
    /// ...in at least this many of its views (a strip of wall behind a shelf is a sliver of
    /// the shelf's region in the views that put it there; src/fuse/consensus_flags.rs).
    pub flag_region_views: usize,
    /// `--relabel`: how a view's label regions take the consensus classes.
    pub relabel: RelabelRule,
}

/// How segment consensus's clustering joins its segments after the outright joins
/// (src/fuse/consensus_cluster.rs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Clustering {
    /// Every join in one order, strongest evidence first, on one core.
    #[default]
    Order,
    /// The single Gaussians join in rounds decided on every core, between ordered joins.
    // The ordered joins among the pieces, then the single Gaussians attached in rounds,
    // then the ordered joins among what is left: most joins take in one Gaussian, and in
    // rounds they need no order. Under flicker 0.3 the same per-Gaussian accuracy as the
    // order, held-out mIoU 0.04 points higher with `--relabel` and 0.78 lower without (mean
    // of 10 synthetic runs; most of it one run's 21-pixel sliver of a desk); on many cores
    // less time (docs/robustness-log.md, "The single Gaussians in rounds").
    Rounds,
}

impl ConsensusParams {
    /// The defaults, with the clustering `cfg` asks for.
    pub fn of(cfg: &FuseConfig) -> ConsensusParams {
        ConsensusParams {
            clustering: cfg.clustering,
            ..ConsensusParams::default()
        }
    }
}

impl Default for ConsensusParams {
    fn default() -> Self {
        ConsensusParams {
            occlusion: true,
            neighbours: 8,
            crease_degrees: 60.0,
            flat_ratio: 2.0,
            premerge_views: 6,
            premerge_common_share: 0.75,
            min_together: 2,
            max_apart_share: 0.1,
            min_together_share: 0.5,
            region_max_disagree: 0.1,
            apart_weight: 4.0,
            clustering: Clustering::Order,
            min_segment: 4,
            min_segment_neighbours: 3,
            few_segment_neighbours: 1,
            smooth_rounds: 3,
            min_own_views: 4,
            contradiction_p: 0.01,
            region_votes: Some(RegionVoteRule {
                min_share: 0.85,
                min_share_of_all: 0.5,
                max_confusion: LOOK_ALIKE_RATE,
            }),
            tie_margin: 1.0,
            large_tie_gaussians: 1000,
            large_tie_z: 1.0,
            confusion_min_views: 5,
            confusion_min_share: 0.6,
            confusion_prior_views: 10.0,
            prior: 0.5,
            flag_share: 0.25,
            flag_min_dissent: 5.0,
            flag_min_gaussians: 20,
            flag_region_share: 0.25,
            flag_region_views: 5,
            relabel: RelabelRule {
                min_share: 0.85,
                depth: 3,
                keep_share: 0.25,
                near: 8,
                min_mass: 1.0,
                max_edge_confusion: LOOK_ALIKE_RATE,
            },
        }
    }
}

/// What one segment's views said.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentVotes {
    pub gaussians: usize,
    /// Views that observed any of its Gaussians.
    pub views: usize,
    /// Per class the views gave it: the views' votes, each view adding the share of the
    /// segment's observed Gaussians it gave the class (sums to `views`), as (class, votes)
    /// in class order; the classes no view gave are not listed (a segment's views give few
    /// of a scene's classes: one vector of every class per segment held 0.8 GB for 5,191
    /// classes).
    pub split: Vec<(u32, f64)>,
    pub class: Option<usize>,
    /// Its top classes were within `tie_margin` views' votes (or, being large, within
    /// `large_tie_z` standard deviations): `class` is the one the scene's confusions make
    /// likeliest (unchanged where they tie too).
    pub near_tie: bool,
    pub flagged: bool,
    /// Flagged segments only (else empty): per view that observed it, the class that view
    /// gave most of the segment's observations, as (view, class), by view; a view whose
    /// top classes tie is listed with each. Which views to check (`fuse --report`).
    pub view_classes: Vec<(u32, u32)>,
}

impl SegmentVotes {
    /// The views' votes for `class` (0 where none gave it).
    pub fn votes_for(&self, class: usize) -> f64 {
        count_of(&self.split, class)
    }

    /// The votes of every class: the views that observed it.
    pub fn total(&self) -> f64 {
        self.split.iter().map(|&(_, v)| v).sum()
    }
}

/// Segment consensus's result.
#[derive(Clone, Debug, PartialEq)]
pub struct Consensus {
    /// Class and `class_conf` (posterior mean of the class) per Gaussian.
    pub assignment: Assignment,
    /// Entropy (nats) of each Gaussian's posterior mean; ln(classes) when undecided.
    pub entropy: Vec<f32>,
    /// Segment per Gaussian (index into `segments`).
    pub segment: Vec<u32>,
    pub segments: Vec<SegmentVotes>,
    /// Gaussians whose class came from their segment (the rest: their neighbours' segments,
    /// their own views, or their neighbours).
    pub from_segment: usize,
    /// Observed Gaussians of small segments that took their neighbours' segments' class.
    pub from_neighbour_segments: usize,
    /// Observed Gaussians decided by their own views (a tie left them without a class).
    pub from_own_views: usize,
    /// Gaussians no view observed: with the three above, every Gaussian.
    pub unobserved: usize,
    /// Of those, the ones decided by their neighbours' classes.
    pub from_neighbours: usize,
    /// Observed Gaussians of small segments whose class their neighbours' classes changed
    /// ([`ConsensusParams::smooth_rounds`]).
    pub smoothed: usize,
    /// Per Gaussian, the counts its class was decided from (segment split, own views, or
    /// neighbours' classes); a segment's split is stored once for its members (shared with
    /// the lift's evidence, not copied).
    pub evidence: Arc<SharedCounts>,
    /// How often the views of each class's clearly decided segments give each class (what
    /// the near ties were decided by; `--relabel` reads it).
    pub confusions: ConfusionRates,
}

/// The class with the most `votes`; ties go to the most `mass`; still tied: None.
/// Allocates nothing: it runs for most Gaussians, on every core, and under the CLI's one
/// malloc arena each allocation of a worker thread takes the arena's lock.
fn decisive_argmax(votes: &[f64], mass: &[f64]) -> Option<usize> {
    decisive_argmax_of(votes.iter().copied().enumerate(), |c| mass[c])
}

/// [`decisive_argmax`] of votes given as (class, votes) (those not listed: none) and the
/// mass of a class.
fn decisive_argmax_of(
    votes: impl Iterator<Item = (usize, f64)> + Clone,
    mass: impl Fn(usize) -> f64,
) -> Option<usize> {
    let top = votes.clone().map(|(_, v)| v).fold(0.0f64, f64::max);
    if top <= 0.0 {
        return None;
    }
    let tied = || {
        votes
            .clone()
            .filter(move |&(_, v)| v == top)
            .map(|(c, _)| c)
    };
    let best = tied().map(&mass).fold(f64::MIN, f64::max);
    let mut by_mass = tied().filter(|&c| mass(c) == best);
    match (by_mass.next(), by_mass.next()) {
        (Some(c), None) => Some(c),
        _ => None,
    }
}

/// Per segment, a value per class its views gave, as (class, value) in class order.
type PerSegment = Vec<Vec<(u32, f64)>>;

/// Per segment: the views' votes (each view once) and the raw observation counts, and how
/// many views observed it. Each segment's observations are gathered from its members' rows
/// as keys `view << 32 | label` and sorted on their own, on every core: one sort of all
/// (segment, view, label) took most of the decision's time on a million Gaussians, and
/// gathering every observation into its segment's place on one thread was a serial pass
/// over tens of millions.
pub(crate) fn segment_votes(
    obs: &Observations,
    members: &Groups,
    segments: usize,
    classes: usize,
) -> (PerSegment, PerSegment, Vec<usize>) {
    // Runs of segments of about equal Gaussians: the segments are numbered by first
    // Gaussian, so a scene's walls come early, and in blocks of a fixed count of segments
    // they shared one block (a sixteen-thread model of a capture's votes: 46 of 65 ms one
    // block's, util::scaling).
    let sizes = (0..segments).map(|s| members.group(s).len());
    let runs = runs_of_weight(sizes, GAUSSIANS_PER_RUN);
    // Each run's votes counted in one row of every class a thread reuses and kept by their
    // nonzero classes in one list, cut into the segments' vectors on this thread: under the
    // CLI's one malloc arena every allocation a worker thread's cache of freed blocks cannot
    // serve (new blocks, as these are) takes the arena's lock, and there are tens of
    // thousands of segments.
    let blocks = parallel_map(runs.len(), |r| {
        let (mut split, mut mass) = (vec![0.0; classes], vec![0.0; classes]);
        let (mut splits, mut masses) = (SparseRowList::default(), SparseRowList::default());
        let mut views = Vec::with_capacity(runs[r].len());
        let mut sorted = Vec::new();
        for s in runs[r].clone() {
            split.fill(0.0);
            mass.fill(0.0);
            let rows = || members.group(s).iter().map(|&g| obs.row(g as usize));
            if rows().map(|row| row.len()).sum::<usize>() >= VOTES_BY_VIEW_FROM {
                views.push(votes_counted_by_view(
                    obs,
                    members.group(s),
                    &mut split,
                    &mut mass,
                ));
            } else {
                sorted.clear();
                for row in rows() {
                    sorted.extend(row.map(|i| (obs.view[i] as u64) << 32 | obs.label[i] as u64));
                }
                sorted.sort_unstable();
                views.push(votes_of(&sorted, &mut split, &mut mass));
            }
            splits.push_dense(&split);
            masses.push_dense(&mass);
        }
        (splits, masses, views)
    });
    let (mut split, mut mass, mut views) = (Vec::new(), Vec::new(), Vec::new());
    for (block_split, block_mass, block_views) in blocks {
        split.extend(block_split.iter().map(<[_]>::to_vec));
        mass.extend(block_mass.iter().map(<[_]>::to_vec));
        views.extend(block_views);
    }
    (split, mass, views)
}

/// From this many observations a segment's votes are counted in a table of views by
/// classes ([`votes_counted_by_view`]) rather than from its keys sorted ([`votes_of`]): a
/// wall's millions of observations took most of the votes' time sorted, and a list of keys
/// as long on each thread.
const VOTES_BY_VIEW_FROM: usize = 4096;

/// [`votes_of`] of the observations of `members`, counted per (view, class) first: the same
/// sums, added in the same order (views ascending, within a view classes ascending, a
/// class's share once per observation), so the same bits.
pub(crate) fn votes_counted_by_view(
    obs: &Observations,
    members: &[u32],
    split: &mut [f64],
    mass: &mut [f64],
) -> usize {
    let classes = split.len();
    // Counted in runs of members on every core (a wall of a million observations is one
    // segment), each run's table as long as its last view asks, then summed.
    let runs: Vec<&[u32]> = members.chunks(GAUSSIANS_PER_RUN).collect();
    let tables = parallel_map(runs.len(), |r| {
        let mut counts: Vec<u32> = Vec::new();
        for i in runs[r].iter().flat_map(|&g| obs.row(g as usize)) {
            let view = obs.view[i] as usize;
            if (view + 1) * classes > counts.len() {
                counts.resize((view + 1) * classes, 0);
            }
            counts[view * classes + obs.label[i] as usize] += 1;
        }
        counts
    });
    let mut counts = vec![0u32; tables.iter().map(Vec::len).max().unwrap_or(0)];
    for table in tables {
        counts.iter_mut().zip(table).for_each(|(sum, c)| *sum += c);
    }
    let mut seen_by = 0;
    for of_view in counts.chunks_exact(classes.max(1)) {
        let total: u32 = of_view.iter().sum();
        if total == 0 {
            continue;
        }
        let share = 1.0 / total as f64;
        for (label, &count) in of_view.iter().enumerate() {
            for _ in 0..count {
                split[label] += share;
                mass[label] += 1.0;
            }
        }
        seen_by += 1;
    }
    seen_by
}

/// One segment's votes from its observation keys sorted (by view, then label), added to
/// `split` and `mass` (zeros, one per class): every view adds the share of the segment's
/// observations it gives each class, and each observation one to its class's mass; and
/// the views counted.
fn votes_of(sorted: &[u64], split: &mut [f64], mass: &mut [f64]) -> usize {
    let mut views = 0;
    for group in sorted.chunk_by(|a, b| a >> 32 == b >> 32) {
        let share = 1.0 / group.len() as f64;
        for &key in group {
            let label = (key & u32::MAX as u64) as usize;
            split[label] += share;
            mass[label] += 1.0;
        }
        views += 1;
    }
    views
}

/// Adds how many of Gaussian `g`'s views gave each class to `votes`. Counted as each
/// Gaussian is decided rather than kept for all of them at once (a million Gaussians over
/// 64 classes: 0.5 GB), and again for the few whose neighbours' votes break a tie.
fn add_own_votes(obs: &Observations, g: usize, votes: &mut [f64]) {
    for i in obs.row(g) {
        votes[obs.label[i] as usize] += 1.0;
    }
}

/// A vote per neighbour of Gaussian `g` for that neighbour's class (undecided ones: none).
fn add_neighbour_classes(
    class: &[Option<usize>],
    knn: &[u32],
    k: usize,
    g: usize,
    votes: &mut [f64],
) {
    let near = knn[g * k..(g + 1) * k]
        .iter()
        .filter(|&&h| h != NO_NEIGHBOUR);
    for c in near.filter_map(|&h| class[h as usize]) {
        votes[c] += 1.0;
    }
}

/// Decides segments and Gaussians from the observations, the neighbours and the segments.
pub fn decide(
    obs: &Observations,
    knn: &[u32],
    segment: Vec<u32>,
    classes: usize,
    p: &ConsensusParams,
) -> Consensus {
    decide_timed(obs, knn, segment, classes, p).0
}

/// Where the decision's time went (host seconds), step by step: what `bench fuse --json`
/// reports, so that a machine's profile says which step to take on next.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct DecideProfile {
    /// Each segment's votes, from its members' observations (on every core).
    pub votes_s: f64,
    /// The segments' summaries, near ties, flags and the flagged ones' view classes.
    pub segments_s: f64,
    /// Per Gaussian, whether its segment's class stands (on every core).
    pub kept_s: f64,
    /// What the label regions say for the Gaussians their segment does not decide.
    pub region_votes_s: f64,
    /// Each Gaussian's class and evidence, in turn.
    pub gaussians_s: f64,
    /// The unobserved ones filled from their neighbours, the small segments smoothed and
    /// the posteriors (the last two on every core).
    pub fill_s: f64,
    pub smooth_s: f64,
    pub posteriors_s: f64,
}

/// [`decide`], and where its time went.
pub fn decide_timed(
    obs: &Observations,
    knn: &[u32],
    segment: Vec<u32>,
    classes: usize,
    p: &ConsensusParams,
) -> (Consensus, DecideProfile) {
    assert_eq!(segment.len(), obs.n, "one segment per Gaussian");
    let (mut took, mut laps) = (DecideProfile::default(), Laps::start());
    let count = segment.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
    // Each segment's Gaussians: its size, its votes and, if flagged, its regions.
    let members = Groups::by_key(&segment, count);
    let (split, mass, views) = segment_votes(obs, &members, count, classes);
    took.votes_s = laps.lap();
    let sizes: Vec<usize> = (0..count).map(|s| members.group(s).len()).collect();
    // Each split moves into its segment's summary (a scene of fragments holds as many
    // segments as Gaussians); the masses only break its ties.
    let mut segments: Vec<SegmentVotes> = (split.into_iter().zip(mass).enumerate())
        .map(|(s, (split, mass))| segment_summary(split, &mass, sizes[s], views[s], p))
        .collect();
    let confusions = decide_near_ties(&mut segments, classes, p);
    unflag_slivers(obs, &members, &mut segments, p);
    name_views_of_flagged(obs, &members, &mut segments);
    took.segments_s = laps.lap();
    let kept = segment_classes_kept(obs, &segment, &segments, classes, p);
    took.kept_s = laps.lap();
    let regions = p.region_votes.map(|rule| {
        // Those their segment does not decide read their regions.
        let reads: Vec<bool> = kept.iter().map(Option::is_none).collect();
        RegionVotes::of(obs, (&segment, &segments), &reads, &rule, &confusions, p)
    });
    took.region_votes_s = laps.lap();
    let alone = Alone {
        obs,
        knn,
        segment: &segment,
        segments: &segments,
        classes,
        p,
        regions,
    };
    let mut decided = each_gaussian(&alone, &kept, count);
    took.gaussians_s = laps.lap();
    // Smoothed before the unobserved are filled: a Gaussian no view saw holds no evidence
    // of its own (its class would be its neighbours' votes, counted again), and the fill
    // then reads the smoothed classes.
    let smoothed = smooth_small_segments(&mut decided.class, &mut decided.evidence, &alone);
    took.smooth_s = laps.lap();
    let from_neighbours = fill_unobserved(
        &mut decided.class,
        &mut decided.evidence,
        obs,
        knn,
        p.neighbours,
    );
    took.fill_s = laps.lap();
    let (mut confidence, mut entropy) = posteriors(&decided.evidence, &decided.class, p.prior);
    let unseen: Vec<bool> = (0..obs.n).map(|g| obs.row(g).is_empty()).collect();
    unseen_without_confidence(&unseen, &mut confidence, Some(&mut entropy), classes);
    took.posteriors_s = laps.lap();
    let consensus = Consensus {
        assignment: Assignment {
            class: decided.class,
            confidence,
        },
        entropy,
        segment,
        segments,
        from_segment: decided.from_segment,
        from_neighbour_segments: decided.from_neighbour_segments,
        from_own_views: decided.from_own_views,
        unobserved: decided.unobserved,
        from_neighbours,
        smoothed,
        evidence: Arc::new(decided.evidence),
        confusions,
    };
    (consensus, took)
}

/// Each Gaussian's class and evidence as [`each_gaussian`] decides them, and how many took
/// which way.
struct Decided {
    class: Vec<Option<usize>>,
    evidence: SharedCounts,
    from_segment: usize,
    from_neighbour_segments: usize,
    from_own_views: usize,
    unobserved: usize,
}

/// Each Gaussian's class and evidence: its segment's where `kept` (the split stored once
/// per segment, when a member first takes it: one that decides none of its members is
/// never stored), else as [`Alone::decide`] decides it (those on every core first: on the
/// calling thread they were 2% of a noisy office's decision on one core and 13% of a
/// living room's, all of it serial).
fn each_gaussian(alone: &Alone, kept: &[Option<usize>], segments: usize) -> Decided {
    let (obs, n) = (alone.obs, alone.obs.n);
    let mut decided = Decided {
        class: vec![None; n],
        evidence: SharedCounts::zeros(alone.classes, n),
        from_segment: 0,
        from_neighbour_segments: 0,
        from_own_views: 0,
        unobserved: 0,
    };
    let alone_ids: Vec<usize> = (0..n).filter(|&g| kept[g].is_none()).collect();
    let blocks = decide_alone(alone, &alone_ids);
    let mut decided_alone = blocks.iter().flat_map(|(outcomes, counts)| {
        (outcomes.iter().zip(counts.iter())).map(|(&(c, by), row)| (c, row, by))
    });
    let mut split_row: Vec<Option<u32>> = vec![None; segments];
    for (g, &segment_class) in kept.iter().enumerate() {
        let s = alone.segment[g] as usize;
        match segment_class {
            Some(c) => {
                decided.class[g] = Some(c);
                decided.from_segment += 1;
                let split = &alone.segments[s].split;
                let evidence = &mut decided.evidence;
                let row = *split_row[s].get_or_insert_with(|| evidence.add_row(split));
                evidence.share(g, row);
            }
            None => {
                let (c, counts, by_neighbours) = decided_alone.next().expect("decided alone");
                decided.class[g] = c;
                decided.evidence.set(g, counts);
                // Unobserved ones are counted where their neighbours decide them below.
                match (obs.row(g).is_empty(), by_neighbours) {
                    (true, _) => decided.unobserved += 1,
                    (false, true) => decided.from_neighbour_segments += 1,
                    (false, false) => decided.from_own_views += 1,
                }
            }
        }
    }
    decided
}

/// A block of [`decide_alone`]: each Gaussian's (class, whether by its neighbours'
/// segments), and their counts by their nonzero classes (a Gaussian's views give few of a
/// scene's classes; a row of every class each held 1.6 GB for 5,191 classes).
type AloneBlock = (Vec<(Option<usize>, bool)>, SparseRowList);

/// [`Alone::decide`] of each of `ids`, on every core, in blocks in their order.
fn decide_alone(alone: &Alone, ids: &[usize]) -> Vec<AloneBlock> {
    const BLOCK: usize = 1024;
    let blocks: Vec<&[usize]> = ids.chunks(BLOCK).collect();
    parallel_map(blocks.len(), |b| {
        let mut counts = vec![0.0; alone.classes];
        let mut spare = vec![0.0; 2 * alone.classes];
        let mut rows = SparseRowList::default();
        let outcomes = (blocks[b].iter())
            .map(|&g| {
                let outcome = alone.decide(g, &mut counts, &mut spare);
                rows.push_dense(&counts);
                outcome
            })
            .collect();
        (outcomes, rows)
    })
}

/// Per Gaussian, its segment's class where the segment decides its members and the
/// Gaussian's own views do not contradict it ([`contradicts`]); on every core, in blocks of
/// Gaussians: the test sums a binomial tail term by term, about half of the decision's
/// time on one core (a million Gaussians, tens of views each).
fn segment_classes_kept(
    obs: &Observations,
    segment: &[u32],
    segments: &[SegmentVotes],
    classes: usize,
    p: &ConsensusParams,
) -> Vec<Option<usize>> {
    const BLOCK: usize = 4096;
    let blocks = parallel_map(obs.n.div_ceil(BLOCK), |b| {
        let mut own = vec![0.0; classes];
        let block = b * BLOCK..obs.n.min((b + 1) * BLOCK);
        let kept = block.map(|g| {
            let votes = &segments[segment[g] as usize];
            let c = deciding_class(votes, p)?;
            own.fill(0.0);
            add_own_votes(obs, g, &mut own);
            let split = (votes.votes_for(c), votes.total());
            (!contradicts(&own, c, split, p)).then_some(c)
        });
        kept.collect::<Vec<_>>()
    });
    blocks.concat()
}

/// A segment's class where it holds enough Gaussians (`min_segment`) to decide its members.
fn deciding_class(votes: &SegmentVotes, p: &ConsensusParams) -> Option<usize> {
    votes.class.filter(|_| votes.gaussians >= p.min_segment)
}

/// What decides a Gaussian its segment does not: the inputs of [`decide`], and what its
/// views' label regions say ([`ConsensusParams::region_votes`]).
struct Alone<'a> {
    obs: &'a Observations,
    knn: &'a [u32],
    segment: &'a [u32],
    segments: &'a [SegmentVotes],
    classes: usize,
    p: &'a ConsensusParams,
    regions: Option<RegionVotes>,
}

impl Alone<'_> {
    /// Gaussian `g`'s class and whether the counts it was decided from, written to `counts`
    /// (one per class), are its neighbours' segments: theirs where they decide it
    /// ([`Alone::neighbour_segments`]), else its own views' (a tie broken by its
    /// neighbours' views, then undecided). `spare`: two rows of classes for the steps
    /// between. Allocates nothing: it runs on every core, under the CLI's one malloc arena.
    fn decide(&self, g: usize, counts: &mut [f64], spare: &mut [f64]) -> (Option<usize>, bool) {
        let small = self.segments[self.segment[g] as usize].gaussians < self.p.min_segment;
        if let Some(c) = small
            .then(|| self.neighbour_segments(g, counts, spare))
            .flatten()
        {
            return (Some(c), true);
        }
        counts.fill(0.0);
        self.add_votes_through_regions(g, counts);
        let tie_break = &mut spare[..self.classes];
        tie_break.fill(0.0);
        add_neighbour_votes(self.obs, self.knn, self.p.neighbours, g, tie_break);
        (decisive_argmax(counts, tie_break), false)
    }

    /// Adds Gaussian `g`'s own views' votes: through their label regions where those are
    /// read, its labels where they are not or where no view's region votes.
    fn add_votes_through_regions(&self, g: usize, votes: &mut [f64]) {
        let voted = (self.regions.as_ref()).is_some_and(|r| r.add_votes(self.obs, g, votes));
        if !voted {
            add_own_votes(self.obs, g, votes);
        }
    }

    /// The class more than half of Gaussian `g`'s neighbours in decided segments of at
    /// least `min_segment` Gaussians hold, where at least `min_segment_neighbours` are, or
    /// `few_segment_neighbours` whose class its own views (labels) do not contradict; with
    /// the count of those neighbours per class in `counts`
    /// ([`ConsensusParams::min_segment_neighbours`]). `spare`: two rows of classes.
    fn neighbour_segments(&self, g: usize, counts: &mut [f64], spare: &mut [f64]) -> Option<usize> {
        let (k, p) = (self.p.neighbours, self.p);
        // (class, segment) of each neighbour in a decided segment.
        let decided = || {
            let near = self.knn[g * k..(g + 1) * k].iter();
            near.filter(|&&h| h != NO_NEIGHBOUR)
                .map(|&h| &self.segments[self.segment[h as usize] as usize])
                .filter_map(|votes| Some((deciding_class(votes, p)?, votes)))
        };
        counts.fill(0.0);
        decided().for_each(|(c, _)| counts[c] += 1.0);
        let total: f64 = counts.iter().sum();
        let top = (0..self.classes).find(|&c| 2.0 * counts[c] > total)?;
        if total >= p.min_segment_neighbours as f64 {
            return Some(top);
        }
        if p.few_segment_neighbours == 0 || total < p.few_segment_neighbours as f64 {
            return None;
        }
        // The rate at which the views of the neighbours' segments give `top`: their splits,
        // each scaled to one.
        let (rate, own) = spare.split_at_mut(self.classes);
        let own = &mut own[..self.classes];
        rate.fill(0.0);
        for (_, votes) in decided().filter(|&(c, _)| c == top) {
            let views = votes.total();
            for &(c, v) in &votes.split {
                rate[c as usize] += v / views;
            }
        }
        own.fill(0.0);
        add_own_votes(self.obs, g, own);
        let split = (rate[top], rate.iter().sum());
        (!contradicts(own, top, split, p)).then_some(top)
    }
}

/// Whether a Gaussian's own view counts `own` contradict its segment's class `c`: it has at
/// least `min_own_views` views, and so few give `c` that views of the segment (giving `c`
/// at the segment's rate, `split`) would give as few with probability below
/// `contradiction_p`. Such a Gaussian was joined across an edge; a Gaussian seen by a few
/// flickering views is not (a ceiling Gaussian seen four times as wall, in a ceiling its
/// views call wall 40% of the time, stays ceiling).
/// `(of_c, total)`: the segment's votes for `c` and of every class.
fn contradicts(own: &[f64], c: usize, (of_c, total): (f64, f64), p: &ConsensusParams) -> bool {
    let views = own.iter().sum::<f64>().round() as u64;
    if views < p.min_own_views as u64 || total <= 0.0 {
        return false;
    }
    let (gave_c, rate) = (own[c].round() as u64, of_c / total);
    // Most members give their segment's class at its rate or more: their tail is at least a
    // half ([`at_least_the_mean_plus_one`]), never under a test's `contradiction_p`, so its
    // sum (a logarithm and an exponential a term, over most of the scene) is skipped.
    if p.contradiction_p <= 0.5 && at_least_the_mean_plus_one(gave_c, views, rate) {
        return false;
    }
    binomial_at_most(gave_c, views, rate) < p.contradiction_p
}

/// Whether `k` is at least one over the mean of a Binomial(n, rate): then P(X <= k) is at
/// least a half, since a binomial's median is its mean rounded down or up (Kaas and
/// Buhrman, 1980), so at most `k`. The one covers the mean's rounding in f64.
pub fn at_least_the_mean_plus_one(k: u64, n: u64, rate: f64) -> bool {
    k as f64 >= n as f64 * rate + 1.0
}

/// P(X <= k) for X ~ Binomial(n, rate), summed in log space (terms far below f64's range
/// vanish; the sum does not underflow where it matters).
pub fn binomial_at_most(k: u64, n: u64, rate: f64) -> f64 {
    if rate <= 0.0 || k >= n {
        return 1.0;
    }
    if rate >= 1.0 {
        return 0.0;
    }
    let (ln_rate, ln_miss) = (rate.ln(), (1.0 - rate).ln());
    let mut ln_term = n as f64 * ln_miss; // i = 0
    let mut sum = ln_term.exp();
    for i in 0..k {
        ln_term += ((n - i) as f64 / (i + 1) as f64).ln() + ln_rate - ln_miss;
        sum += ln_term.exp();
    }
    sum.min(1.0)
}

/// Gaussians no view observed (their centers hidden in every view) take the class most of
/// their decided neighbours hold, in rounds outward from the observed ones; those neighbour
/// counts are their evidence. A tie, or no decided neighbour, leaves one the class its
/// neighbours' segments gave it ([`Alone::decide`]), if any. Returns how many of them end
/// with a class: all by their neighbours, one way or the other.
fn fill_unobserved(
    class: &mut [Option<usize>],
    evidence: &mut SharedCounts,
    obs: &Observations,
    knn: &[u32],
    k: usize,
) -> usize {
    let mut pending: Vec<bool> = (0..obs.n).map(|g| obs.row(g).is_empty()).collect();
    let mut frontier: Vec<usize> = (0..obs.n).filter(|&g| pending[g]).collect();
    // Which of those list g among their neighbours: the Gaussians a decision at g may
    // decide next round (only they can change; a scene seen by few views has most
    // Gaussians pending and needs many rounds). Only the pending ones' lists are read: a
    // scene seen well has few.
    let listed_by = reverse_neighbours(knn, k, obs.n, &frontier);
    while !frontier.is_empty() {
        // Decided from the classes as they stood at the round's start.
        // Their counts by nonzero class: a round may decide most of a scene.
        let mut counts = vec![0.0; evidence.classes()];
        let mut found_counts = SparseRowList::default();
        let found: Vec<(usize, usize)> = frontier
            .iter()
            .filter_map(|&g| {
                counts.fill(0.0);
                add_neighbour_classes(class, knn, k, g, &mut counts);
                let c = decisive_argmax(&counts, &counts)?;
                found_counts.push_dense(&counts);
                Some((g, c))
            })
            .collect();
        frontier.clear();
        for ((g, c), counts) in found.into_iter().zip(found_counts.iter()) {
            (class[g], pending[g]) = (Some(c), false);
            evidence.set(g, counts);
            frontier.extend(listed_by.row(g).filter(|&f| pending[f]));
        }
        frontier.sort_unstable();
        frontier.dedup();
        frontier.retain(|&f| pending[f]);
    }
    (0..obs.n)
        .filter(|&g| obs.row(g).is_empty() && class[g].is_some())
        .count()
}

/// [`ConsensusParams::smooth_rounds`]: each round decides every observed Gaussian of a
/// segment under `min_segment` from its own views' votes
/// ([`Alone::add_votes_through_regions`]) plus a vote per neighbour's class, as the classes
/// stood at the round's start; a tie keeps its class. The votes it takes its
/// class from become its evidence, in its own row (such a Gaussian's evidence was set for
/// it alone: a small segment's split is never shared). Returns how many ended with another
/// class than they started with.
fn smooth_small_segments(
    class: &mut [Option<usize>],
    evidence: &mut SharedCounts,
    alone: &Alone,
) -> usize {
    let (obs, p) = (alone.obs, alone.p);
    let k = p.neighbours;
    let small: Vec<usize> = (0..obs.n)
        .filter(|&g| alone.segments[alone.segment[g] as usize].gaussians < p.min_segment)
        .filter(|&g| !obs.row(g).is_empty())
        .collect();
    let first: Vec<Option<usize>> = small.iter().map(|&g| class[g]).collect();
    let blocks: Vec<&[usize]> = small.chunks(4096).collect();
    for _ in 0..p.smooth_rounds {
        // Each block's votes on every core (by nonzero class), then stored in the
        // Gaussians' order.
        let now: &[Option<usize>] = class;
        let voted = parallel_map(blocks.len(), |b| {
            let mut votes = vec![0.0; evidence.classes()];
            let mut rows = SparseRowList::default();
            let decided: Vec<Option<usize>> = (blocks[b].iter())
                .map(|&g| {
                    votes.fill(0.0);
                    alone.add_votes_through_regions(g, &mut votes);
                    add_neighbour_classes(now, alone.knn, k, g, &mut votes);
                    rows.push_dense(&votes);
                    decisive_argmax(&votes, &votes)
                })
                .collect();
            (decided, rows)
        });
        let decided: Vec<Option<usize>> = (voted.iter().flat_map(|(decided, _)| decided))
            .copied()
            .collect();
        let votes = voted.iter().flat_map(|(_, rows)| rows.iter());
        for ((&g, c), votes) in small.iter().zip(&decided).zip(votes) {
            if c.is_some() {
                evidence.replace_own(g, votes); // the rounds read classes, not evidence
            }
        }
        for (&g, c) in small.iter().zip(decided) {
            class[g] = c.or(class[g]);
        }
    }
    small
        .iter()
        .zip(first)
        .filter(|&(&g, c)| class[g] != c)
        .count()
}

/// Reverse adjacency of a [n][k] neighbour table, in compressed rows.
struct ReverseNeighbours {
    offsets: Vec<u32>,
    from: Vec<u32>,
}

impl ReverseNeighbours {
    fn row(&self, g: usize) -> impl Iterator<Item = usize> + '_ {
        let range = self.offsets[g] as usize..self.offsets[g + 1] as usize;
        self.from[range].iter().map(|&f| f as usize)
    }
}

/// The reverse of the rows `rows` (ascending) of a [n][k] neighbour table: per Gaussian,
/// which of those rows list it, ascending.
fn reverse_neighbours(knn: &[u32], k: usize, n: usize, rows: &[usize]) -> ReverseNeighbours {
    let listed = || {
        let row = |&f: &usize| knn[f * k..(f + 1) * k].iter().map(move |&h| (h, f));
        rows.iter()
            .flat_map(row)
            .filter(|&(h, _)| h != NO_NEIGHBOUR)
    };
    let mut offsets = vec![0u32; n + 1];
    for (h, _) in listed() {
        offsets[h as usize + 1] += 1;
    }
    for g in 0..n {
        offsets[g + 1] += offsets[g];
    }
    let mut next = offsets.clone();
    let mut from = vec![0u32; offsets[n] as usize];
    for (h, f) in listed() {
        from[next[h as usize] as usize] = f as u32;
        next[h as usize] += 1;
    }
    ReverseNeighbours { offsets, from }
}

/// A segment's summary from its votes and masses by class (the same classes, in class
/// order).
pub(crate) fn segment_summary(
    split: Vec<(u32, f64)>,
    mass: &SparseCounts,
    gaussians: usize,
    views: usize,
    p: &ConsensusParams,
) -> SegmentVotes {
    let votes = split.iter().map(|&(c, v)| (c as usize, v));
    let class = decisive_argmax_of(votes.clone(), |c| count_of(mass, c));
    let total: f64 = split.iter().map(|&(_, v)| v).sum();
    // The classes not listed hold 0, which a runner-up of none stands for.
    let runner_up = second_largest(votes.map(|(_, v)| v)).unwrap_or(0.0);
    SegmentVotes {
        gaussians,
        views,
        split,
        class,
        near_tie: false,
        // Only a segment large and well enough seen for its split to mean something: a
        // singleton no view saw has no class either, and is not a finding.
        flagged: gaussians >= p.flag_min_gaussians
            && runner_up >= p.flag_min_dissent
            && (class.is_none() || runner_up >= p.flag_share * total),
        view_classes: Vec::new(),
    }
}

/// The second of `values` in descending order (the largest again where it occurs twice),
/// without sorting a copy: a scene of fragments holds tens of thousands of segments, each
/// summarized on one thread.
fn second_largest(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (mut first, mut second, mut count) = (f64::NEG_INFINITY, f64::NEG_INFINITY, 0);
    for x in values {
        if x > first {
            (first, second) = (x, first);
        } else if x > second {
            second = x;
        }
        count += 1;
    }
    (count >= 2).then_some(second)
}

/// Adds the own votes of g's neighbours to `sum`: what breaks a tie of g's own views.
fn add_neighbour_votes(obs: &Observations, knn: &[u32], k: usize, g: usize, sum: &mut [f64]) {
    for &h in &knn[g * k..(g + 1) * k] {
        if h != NO_NEIGHBOUR {
            add_own_votes(obs, h as usize, sum);
        }
    }
}

/// Every Gaussian's (confidence, entropy) of its class under a Dirichlet(prior + counts)
/// ([`RowPosterior::posterior`]), on every core. The entropy (a logarithm per class)
/// depends on the counts alone, so it is computed once per distinct row of counts (a
/// segment's members share its split: 47k rows for the 911k Gaussians of a noisy office,
/// 64k for a 978k room under random block labels, docs/robustness-log.md), the confidence per
/// Gaussian.
pub(crate) fn posteriors(
    evidence: &SharedCounts,
    class: &[Option<usize>],
    prior: f64,
) -> (Vec<f32>, Vec<f32>) {
    const BLOCK: usize = 16384;
    // A row costs a logarithm per class where a Gaussian costs one lookup: the rows in
    // smaller blocks (a living room's 27,838 rows were two blocks of 16,384, one of them
    // 1.7 ms on sixteen threads in a model while the other fifteen waited, util::scaling).
    const ROW_BLOCK: usize = 1024;
    let rows = evidence.rows().max(1); // row 0, the zeros, is there with no classes too
    let posteriors_of_rows = parallel_map(rows.div_ceil(ROW_BLOCK), |b| {
        let block = b * ROW_BLOCK..rows.min((b + 1) * ROW_BLOCK);
        block
            .map(|r| RowPosterior::of(evidence.row(r), evidence.classes(), prior))
            .collect::<Vec<_>>()
    });
    let posteriors_of_rows: Vec<RowPosterior> = posteriors_of_rows.into_iter().flatten().collect();
    let blocks = parallel_map(class.len().div_ceil(BLOCK), |b| {
        let block = b * BLOCK..class.len().min((b + 1) * BLOCK);
        block
            .map(|g| {
                let row_posterior = &posteriors_of_rows[evidence.row_index(g)];
                let (c, h) =
                    row_posterior.posterior(evidence.get(g), evidence.classes(), class[g], prior);
                (c as f32, h as f32)
            })
            .collect::<Vec<_>>()
    });
    blocks.into_iter().flatten().unzip()
}

/// The Gaussians no view saw (`unseen`) have no posterior, whatever class their neighbours gave them
/// ([`fill_unobserved`], whose counts are their evidence, not views): confidence 0 and the
/// entropy of no evidence (ln `classes`), as an undecided Gaussian's. Their neighbours'
/// counts as a posterior read as certainty where few labeled pixels reached a scene (one
/// per view: every Gaussian at confidence 1).
pub(crate) fn unseen_without_confidence(
    unseen: &[bool],
    confidence: &mut [f32],
    mut entropy: Option<&mut [f32]>,
    classes: usize,
) {
    let none = (classes.max(1) as f32).ln();
    for g in (0..unseen.len()).filter(|&g| unseen[g]) {
        confidence[g] = 0.0;
        if let Some(entropy) = entropy.as_deref_mut() {
            entropy[g] = none;
        }
    }
}

/// What a row of counts gives every class's posterior under a Dirichlet(prior + counts):
/// the total, the entropy (nats) of the posterior mean, and whether any view counted.
struct RowPosterior {
    total: f64,
    entropy: f64,
    seen: bool,
}

impl RowPosterior {
    fn of(counts: &SparseCounts, classes: usize, prior: f64) -> RowPosterior {
        let counted: f64 = counts.iter().map(|&(_, x)| x).sum();
        let total = counted + prior * classes as f64;
        // Every class in order, its term or that of a count of 0: the sum as a row of every
        // class's sums it, with one logarithm for all the classes the row does not count
        // (thousands where the classes are ids of label regions: 0.9 s of a decision's 2.3).
        let term = |q: f64| (q > 0.0).then(|| q * q.ln());
        let uncounted = term((0.0 + prior) / total);
        let mut nonzero = counts.iter().peekable();
        let term_of = |k: usize| match nonzero.next_if(|&&(c, _)| c as usize == k) {
            Some(&(_, x)) => term((x + prior) / total),
            None => uncounted,
        };
        // 0 - sum, not -sum: a certain row (one class) has entropy +0, not -0 in the PLY.
        let entropy = 0.0 - (0..classes).filter_map(term_of).sum::<f64>();
        RowPosterior {
            total,
            entropy,
            seen: counted > 0.0,
        }
    }

    /// Posterior mean of `class` under a Dirichlet(prior + counts), and the entropy (nats)
    /// of the posterior mean; unseen or undecided: 0 and ln(classes). `counts`: the row this
    /// was computed from.
    fn posterior(
        &self,
        counts: &SparseCounts,
        classes: usize,
        class: Option<usize>,
        prior: f64,
    ) -> (f64, f64) {
        debug_assert_eq!(
            self.seen,
            counts.iter().any(|&(_, x)| x > 0.0),
            "another row"
        );
        match class {
            Some(c) if self.seen => ((count_of(counts, c) + prior) / self.total, self.entropy),
            _ => (0.0, (classes as f64).ln()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuse::consensus_segments::ViewEntry;
    use crate::fuse::shared_counts::nonzero;
    use crate::util::Rng;

    /// The second largest is what sorting descending puts second, ties and all.
    #[test]
    fn second_largest_is_the_sorted_second() {
        let mut rng = crate::util::Rng::new(12);
        for len in 0..8 {
            for _ in 0..50 {
                let values: Vec<f64> = (0..len).map(|_| rng.below(4) as f64 * 0.5).collect();
                let mut sorted = values.clone();
                sorted.sort_by(|a, b| b.total_cmp(a));
                assert_eq!(
                    second_largest(values.iter().copied()),
                    sorted.get(1).copied(),
                    "{values:?}"
                );
            }
        }
    }

    /// The most votes wins; a tie goes to the most mass; a tie in both, or no vote, to none.
    #[test]
    fn decisive_argmax_breaks_ties_by_mass_or_not_at_all() {
        assert_eq!(decisive_argmax(&[1.0, 3.0, 2.0], &[9.0, 0.0, 9.0]), Some(1));
        assert_eq!(decisive_argmax(&[3.0, 1.0, 3.0], &[2.0, 9.0, 5.0]), Some(2));
        assert_eq!(decisive_argmax(&[3.0, 1.0, 3.0], &[5.0, 9.0, 5.0]), None);
        assert_eq!(decisive_argmax(&[3.0, 3.0, 3.0], &[5.0, 6.0, 6.0]), None);
        assert_eq!(decisive_argmax(&[0.0, 0.0], &[1.0, 2.0]), None);
        assert_eq!(decisive_argmax(&[], &[]), None);
        assert_eq!(decisive_argmax(&[0.0, 0.5], &[0.0, 0.0]), Some(1));
    }

    /// The fill counts every unobserved Gaussian that ends with a class: those it decides,
    /// and one its tie leaves with the class its neighbours' segments gave it; the one its
    /// tie leaves without a class is not counted.
    #[test]
    fn the_fill_counts_the_unobserved_that_end_with_a_class() {
        // 0 and 1 observed as classes 0 and 1; 2, 3 and 4 unobserved, each listing 0 and
        // 1 as its neighbours (a tie), 4 listing 0 twice.
        let per_view = vec![vec![(0u32, 0u32, 0u32, false), (1, 1, 1, false)]];
        let obs = Observations::from_views(5, &per_view);
        let knn: Vec<u32> = vec![1, 2, 0, 2, 0, 1, 0, 1, 0, 0];
        let mut class = vec![Some(0), Some(1), None, Some(1), None];
        let mut evidence = SharedCounts::zeros(2, 5);
        let filled = fill_unobserved(&mut class, &mut evidence, &obs, &knn, 2);
        assert_eq!(class, [Some(0), Some(1), None, Some(1), Some(0)]);
        assert_eq!(filled, 2, "3 kept its class on the tie, 4 was decided");
    }

    /// The reverse of some rows of a neighbour table lists, per Gaussian, exactly those of
    /// the rows that list it, ascending (gaps included).
    #[test]
    fn reverse_neighbours_of_some_rows_list_their_listers() {
        let mut rng = Rng::new(4);
        let (n, k) = (500, 6);
        let knn: Vec<u32> = (0..n * k)
            .map(|_| match rng.below(10) {
                0 => NO_NEIGHBOUR,
                _ => rng.below(n as u64) as u32,
            })
            .collect();
        let rows: Vec<usize> = (0..n).filter(|_| rng.below(3) == 0).collect();
        let reverse = reverse_neighbours(&knn, k, n, &rows);
        for g in 0..n {
            let listers: Vec<usize> = (rows.iter().copied())
                .flat_map(|f| knn[f * k..(f + 1) * k].iter().map(move |&h| (f, h)))
                .filter(|&(_, h)| h == g as u32)
                .map(|(f, _)| f)
                .collect();
            assert_eq!(reverse.row(g).collect::<Vec<_>>(), listers, "Gaussian {g}");
        }
    }

    /// A segment's votes counted per view and class equal those from its keys sorted, bit
    /// for bit (the decision's ties read them), on random segments: views none of its
    /// Gaussians saw, a view that saw one Gaussian, classes no view gave, and a segment
    /// of several runs of members (counted on several threads).
    #[test]
    fn votes_counted_by_view_are_the_sorted_keys_votes() {
        let (views, classes, n) = (23, 7, 2 * GAUSSIANS_PER_RUN + 400);
        let mut rng = Rng::new(5);
        let per_view: Vec<Vec<ViewEntry>> = (0..views)
            .map(|v| {
                // View 3 (and every fifth after it) sees nothing; the last class is never given.
                let gaussians: Vec<u32> = (0..n as u32)
                    .filter(|_| v % 5 != 3 && rng.below(3 + v as u64 % 4) > 0)
                    .collect();
                (gaussians.into_iter())
                    .map(|g| (g, rng.below(classes as u64 - 1) as u32, 0, false))
                    .collect()
            })
            .collect();
        let obs = Observations::from_views(n, &per_view);
        let some = (0..n as u32).step_by(3).collect();
        for members in [vec![0], vec![3, 9, 10], some, (0..n as u32).collect()] {
            let mut keys: Vec<u64> = (members.iter())
                .flat_map(|&g| obs.row(g as usize))
                .map(|i| (obs.view[i] as u64) << 32 | obs.label[i] as u64)
                .collect();
            keys.sort_unstable();
            let (mut split, mut mass) = (vec![0.0; classes], vec![0.0; classes]);
            let seen_by = votes_of(&keys, &mut split, &mut mass);
            let (mut counted_split, mut counted_mass) = (vec![0.0; classes], vec![0.0; classes]);
            let counted =
                votes_counted_by_view(&obs, &members, &mut counted_split, &mut counted_mass);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&counted_split),
                bits(&split),
                "members {}",
                members.len()
            );
            assert_eq!(bits(&counted_mass), bits(&mass));
            assert_eq!(counted, seen_by);
            assert!(seen_by > 0 && split[classes - 1] == 0.0);
        }
    }

    /// Every Gaussian's confidence and entropy against a plain Dirichlet posterior mean per
    /// Gaussian, with rows shared by many Gaussians, rows of their own, the row of zeros,
    /// and undecided Gaussians.
    #[test]
    fn posteriors_per_row_match_a_plain_posterior_per_gaussian() {
        // More distinct rows than a block of the rows' posteriors holds.
        let (classes, n, prior) = (5, 60_000, 0.5);
        let mut rng = Rng::new(11);
        let mut evidence = SharedCounts::zeros(classes, n);
        let draw =
            |rng: &mut Rng| -> Vec<f64> { (0..classes).map(|_| rng.below(4) as f64).collect() };
        let draw = |rng: &mut Rng| nonzero(&draw(rng));
        let shared: Vec<u32> = (0..20).map(|_| evidence.add_row(&draw(&mut rng))).collect();
        let mut class = vec![None; n];
        for (g, class) in class.iter_mut().enumerate() {
            match rng.below(3) {
                0 => evidence.share(g, shared[rng.below(20) as usize]),
                1 => evidence.set(g, &draw(&mut rng)),
                _ => {} // the row of zeros
            }
            if rng.below(5) > 0 {
                *class = Some(rng.below(classes as u64) as usize);
            }
        }
        let (confidence, entropy) = posteriors(&evidence, &class, prior);
        for g in 0..n {
            let counts = evidence.dense(g);
            let total: f64 = counts.iter().sum();
            let (conf, h) = match class[g] {
                Some(c) if total > 0.0 => {
                    let mean = |k: usize| (counts[k] + prior) / (total + prior * classes as f64);
                    let h: f64 = (0..classes).map(|k| -mean(k) * mean(k).ln()).sum();
                    (mean(c), h)
                }
                _ => (0.0, (classes as f64).ln()),
            };
            assert!(
                (confidence[g] as f64 - conf).abs() < 1e-6,
                "{g}: confidence"
            );
            assert!((entropy[g] as f64 - h).abs() < 1e-6, "{g}: entropy");
        }
        assert!(evidence.rows() < n / 2, "rows shared");
    }
}
