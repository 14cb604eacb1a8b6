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

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::hash::{BuildHasherDefault, Hasher};

use super::consensus_decide::ConsensusParams;
use super::consensus_segments::{co_occurrence, Observations};
use crate::contract::NO_NEIGHBOUR;
use crate::util::parallel_map;

/// What the views said of the neighbour pairs between two segments, summed over the pairs
/// ([`co_occurrence`] per pair).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairEvidence {
    pub together: u32,
    pub apart: u32,
    pub on_edge: u32,
    /// Neighbour pairs summed.
    pub pairs: u32,
}

impl PairEvidence {
    fn add(&mut self, other: PairEvidence) {
        self.together += other.together;
        self.apart += other.apart;
        self.on_edge += other.on_edge;
        self.pairs += other.pairs;
    }

    /// Merge order: net evidence per neighbour pair (a view putting a pair apart outweighs
    /// `apart_weight` views putting it together), so pairs seen together by many views join
    /// first; per pair, because a sum would favour large segments for their size alone.
    /// Fixed point (2^-20) so the order is exact and the same wherever it is computed.
    pub fn priority(&self, apart_weight: f64) -> i64 {
        let net = self.together as f64 - apart_weight * self.apart as f64;
        (net / self.pairs.max(1) as f64 * (1 << 20) as f64).round() as i64
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

/// A segment's observations counted per (view, region), sorted.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RegionCounts(pub Vec<(u32, u32, u32)>);

impl RegionCounts {
    pub fn of_gaussian(obs: &Observations, g: usize) -> RegionCounts {
        RegionCounts(
            obs.row(g)
                .map(|i| (obs.view[i], obs.region[i], 1))
                .collect(),
        )
    }

    fn merged(&self, other: &RegionCounts) -> RegionCounts {
        let (a, b) = (&self.0, &other.0);
        let mut out = Vec::with_capacity(a.len() + b.len());
        let (mut i, mut j) = (0, 0);
        while i < a.len() || j < b.len() {
            let key = |e: &(u32, u32, u32)| (e.0, e.1);
            if j == b.len() || (i < a.len() && key(&a[i]) < key(&b[j])) {
                out.push(a[i]);
                i += 1;
            } else if i == a.len() || key(&b[j]) < key(&a[i]) {
                out.push(b[j]);
                j += 1;
            } else {
                out.push((a[i].0, a[i].1, a[i].2 + b[j].2));
                (i, j) = (i + 1, j + 1);
            }
        }
        RegionCounts(out)
    }

    /// Per view: the region holding most of the segment's observations (ties: the lowest
    /// region id) and how many of its observations the view holds, by view.
    pub fn dominant(&self) -> Vec<(u32, u32, u32)> {
        let mut out: Vec<(u32, u32, u32)> = Vec::new();
        let mut best = 0;
        for &(view, region, count) in &self.0 {
            match out.last_mut() {
                Some(last) if last.0 == view => {
                    last.2 += count;
                    if count > best {
                        last.1 = region;
                        best = count;
                    }
                }
                _ => {
                    out.push((view, region, count));
                    best = count;
                }
            }
        }
        out
    }

    /// Of the views that observed both segments, weighed by the fewer of the two segments'
    /// observations each holds: how much say their dominant regions are the same, how much
    /// different. A view that glimpsed one Gaussian of a segment says little about where the
    /// segment lies (one ceiling Gaussian seen at a frame's edge beside a shelf kept two
    /// halves of a ceiling apart, and flicker then decided each half on a few views); a
    /// ceiling and its wall are both seen whole in the views that keep them apart.
    pub fn agreement(&self, other: &RegionCounts) -> (u64, u64) {
        let (a, b) = (self.dominant(), other.dominant());
        let (mut i, mut j, mut same, mut differ) = (0, 0, 0, 0);
        while i < a.len() && j < b.len() {
            match a[i].0.cmp(&b[j].0) {
                std::cmp::Ordering::Less => i += 1,
                std::cmp::Ordering::Greater => j += 1,
                std::cmp::Ordering::Equal => {
                    let say = a[i].2.min(b[j].2) as u64;
                    if a[i].1 == b[j].1 {
                        same += say;
                    } else {
                        differ += say;
                    }
                    (i, j) = (i + 1, j + 1);
                }
            }
        }
        (same, differ)
    }
}

/// Whether two segments may join: their pairs' evidence allows it, and their dominant regions
/// disagree in at most `region_max_disagree` of the views that saw both, weighed as in
/// [`RegionCounts::agreement`] (a segment seen by many views is tested on all of them, not on
/// the few its edge pairs share).
pub fn may_join(
    evidence: &PairEvidence,
    a: &RegionCounts,
    b: &RegionCounts,
    p: &ConsensusParams,
) -> bool {
    if !evidence.allows_join(p) {
        return false;
    }
    let (same, differ) = a.agreement(b);
    differ as f64 <= p.region_max_disagree * (same + differ) as f64
}

/// A candidate join in the queue: highest priority first, then most views together, then
/// the lowest segment ids; `evidence` is what it was queued with (stale once it changed).
type Candidate = (i64, u32, Reverse<u32>, Reverse<u32>, [u32; 4]);

/// Segment id per Gaussian (numbered by first Gaussian). Every segment starts as one Gaussian
/// and is named by its lowest Gaussian index. Candidates (adjacent segments with their summed
/// [`PairEvidence`]) are taken in order of [`PairEvidence::priority`] (ties: more views
/// together, then the lowest ids); one that [`may_join`] joins, any other is dropped until its
/// evidence changes (a join adds pairs to it).
pub fn cluster_segments(obs: &Observations, knn: &[u32], p: &ConsensusParams) -> Vec<u32> {
    let n = obs.n;
    let mut graph = SegmentGraph::new(obs, knn, p.neighbours);
    let mut queue: BinaryHeap<Candidate> = BinaryHeap::new();
    for a in 0..n as u32 {
        for (&b, &e) in &graph.edges[a as usize] {
            if a < b {
                queue.push(candidate(a, b, e, p));
            }
        }
    }
    while let Some((_, _, Reverse(a), Reverse(b), queued)) = queue.pop() {
        let current = graph.edges[a as usize].get(&b).copied();
        if current.map(words) != Some(queued) {
            continue; // a segment joined another, or the evidence grew: queued again since
        }
        let evidence = current.expect("checked above");
        let regions = (&graph.regions[a as usize], &graph.regions[b as usize]);
        if may_join(&evidence, regions.0, regions.1, p) {
            for (c, e) in graph.join(a, b) {
                let (lo, hi) = (a.min(c), a.max(c));
                queue.push(candidate(lo, hi, e, p));
            }
        }
    }
    let mut roots: Vec<u32> = (0..n as u32).collect();
    for g in 0..n {
        roots[g] = roots[graph.parent[g] as usize]; // parents have lower indices
    }
    renumber(&roots)
}

fn words(e: PairEvidence) -> [u32; 4] {
    [e.together, e.apart, e.on_edge, e.pairs]
}

fn candidate(a: u32, b: u32, e: PairEvidence, p: &ConsensusParams) -> Candidate {
    let key = e.priority(p.apart_weight);
    (key, e.together, Reverse(a), Reverse(b), words(e))
}

/// Every neighbour pair once, with what the views said of it (on every core: millions of
/// Gaussians). A pair listed in both rows comes from the lower Gaussian's.
fn neighbour_pairs(obs: &Observations, knn: &[u32], k: usize) -> Vec<(u32, u32, PairEvidence)> {
    const BLOCK: usize = 4096;
    let lists = |g: usize| &knn[g * k..(g + 1) * k];
    let blocks = parallel_map(obs.n.div_ceil(BLOCK), |b| {
        let mut out = Vec::new();
        for g in b * BLOCK..obs.n.min((b + 1) * BLOCK) {
            for &h in lists(g) {
                let from_h = (h as usize) < g && lists(h as usize).contains(&(g as u32));
                if h == NO_NEIGHBOUR || h as usize == g || from_h {
                    continue;
                }
                let c = co_occurrence(obs, g, h as usize);
                let e = PairEvidence {
                    together: c.together,
                    apart: c.apart,
                    on_edge: c.on_edge,
                    pairs: 1,
                };
                out.push((g as u32, h, e));
            }
        }
        out
    });
    blocks.concat()
}

/// A segment's adjacent segments with the summed evidence. Keys are segment ids, so a
/// multiplicative hash does (SipHash, the default, took most of the graph's build time).
type Adjacent = HashMap<u32, PairEvidence, BuildHasherDefault<IdHasher>>;

#[derive(Default)]
struct IdHasher(u64);

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }

    fn write_u32(&mut self, id: u32) {
        self.write_u64(id as u64);
    }

    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

/// The segments while they join: per segment (by its lowest Gaussian) the adjacent segments
/// with the summed evidence, and its region counts.
struct SegmentGraph {
    edges: Vec<Adjacent>,
    regions: Vec<RegionCounts>,
    /// Each Gaussian's segment at the time it joined (a lower index, or itself).
    parent: Vec<u32>,
}

impl SegmentGraph {
    fn new(obs: &Observations, knn: &[u32], k: usize) -> SegmentGraph {
        let n = obs.n;
        let mut edges: Vec<Adjacent> = vec![Adjacent::default(); n];
        for (g, h, e) in neighbour_pairs(obs, knn, k) {
            edges[g as usize].insert(h, e);
            edges[h as usize].insert(g, e);
        }
        SegmentGraph {
            edges,
            regions: (0..n).map(|g| RegionCounts::of_gaussian(obs, g)).collect(),
            parent: (0..n as u32).collect(),
        }
    }

    /// Joins segment `b` into `a` (a < b); returns the segments whose evidence with `a`
    /// changed, with that evidence.
    fn join(&mut self, a: u32, b: u32) -> Vec<(u32, PairEvidence)> {
        let (ai, bi) = (a as usize, b as usize);
        self.parent[bi] = a;
        self.regions[ai] = self.regions[ai].merged(&self.regions[bi]);
        self.regions[bi] = RegionCounts::default();
        let mut moved = std::mem::take(&mut self.edges[bi]);
        moved.remove(&a);
        self.edges[ai].remove(&b);
        let mut changed = Vec::with_capacity(moved.len());
        for (c, e) in moved {
            let other = &mut self.edges[c as usize];
            other.remove(&b);
            let sum = self.edges[ai].entry(c).or_default();
            sum.add(e);
            let sum = *sum;
            self.edges[c as usize].insert(a, sum);
            changed.push((c, sum));
        }
        changed
    }
}

/// Dense ids numbered by first appearance.
pub(crate) fn renumber(keys: &[u32]) -> Vec<u32> {
    let mut id = HashMap::new();
    keys.iter()
        .map(|&k| {
            let next = id.len() as u32;
            *id.entry(k).or_insert(next)
        })
        .collect()
}
