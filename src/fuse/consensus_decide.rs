//! Segment consensus, the decisions: 3D segments from co-occurrence in connected label
//! regions, each segment's class with every view counted once, each Gaussian's class from its
//! segment (its own views where the segment is too small or its own views contradict it), a
//! posterior per Gaussian, and the segments whose vote split is close (flagged).

use serde::Serialize;

use super::assign::Assignment;
use super::consensus_segments::{co_occurrence, find, union, Observations};
use crate::contract::NO_NEIGHBOUR;

/// The knobs of segment consensus (defaults: docs/robustness.md).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ConsensusParams {
    /// Observe a Gaussian only where its center is not hidden (the rendered depth test of
    /// `vote --occlusion`).
    pub occlusion: bool,
    /// Nearest neighbours each Gaussian may join a segment through.
    pub neighbours: usize,
    /// Views that must put two neighbours in the same region before they join...
    pub min_together: u32,
    /// ...and none may put them apart beyond this share of the views seeing both (boundary
    /// noise moves edges by a few pixels: a small share of disagreeing views is tolerated)...
    pub max_apart_share: f64,
    /// ...and at least this share of all views seeing both, those that saw them in one
    /// region on its edge included, must put them together: a floor Gaussian at a wall's
    /// foot is seen with the wall mostly on the label edge, and joined it through the few
    /// views that put both inside the wall's region.
    pub min_together_share: f64,
    /// Smaller segments (boundaries, fragments) leave each Gaussian to its own views.
    pub min_segment: usize,
    /// Rounds of joining neighbouring segments whose dominant regions agree view by view...
    pub merge_rounds: usize,
    /// ...in at least this many views...
    pub merge_min_together: u32,
    /// ...and disagree in at most this share of the views seeing both.
    pub merge_max_apart_share: f64,
    /// A Gaussian seen in at least this many views keeps its own class when fewer than
    /// a quarter of them agree with its segment (it was merged across an edge).
    pub min_own_views: u32,
    /// Dirichlet prior per class of the posterior (0.5: Jeffreys).
    pub prior: f64,
    /// A segment is flagged when its runner-up class holds at least this share of its views...
    pub flag_share: f64,
    /// ...(or it has no decisive class), and it has at least this many Gaussians and views.
    pub flag_min_gaussians: usize,
    pub flag_min_views: usize,
}

impl Default for ConsensusParams {
    fn default() -> Self {
        ConsensusParams {
            occlusion: true,
            neighbours: 8,
            min_together: 2,
            max_apart_share: 0.0,
            min_together_share: 0.5,
            min_segment: 4,
            merge_rounds: 4,
            merge_min_together: 3,
            merge_max_apart_share: 0.1,
            min_own_views: 4,
            prior: 0.5,
            flag_share: 0.25,
            flag_min_gaussians: 20,
            flag_min_views: 5,
        }
    }
}

/// What one segment's views said.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentVotes {
    pub gaussians: usize,
    /// Views that observed any of its Gaussians.
    pub views: usize,
    /// Per class: the views' votes, each view adding the share of the segment's observed
    /// Gaussians it gave the class (sums to `views`).
    pub split: Vec<f64>,
    pub class: Option<usize>,
    pub flagged: bool,
}

/// Segment consensus's result.
#[derive(Clone, Debug, PartialEq)]
pub struct Consensus {
    /// Class and `class_conf` (posterior mean of the class) per Gaussian.
    pub assignment: Assignment,
    /// Entropy (nats) of each Gaussian's posterior mean; ln(classes) when unseen.
    pub entropy: Vec<f32>,
    /// Segment per Gaussian (index into `segments`).
    pub segment: Vec<u32>,
    pub segments: Vec<SegmentVotes>,
    /// Gaussians whose class came from their segment (the rest: their own views).
    pub from_segment: usize,
    /// Per Gaussian, the counts its class was decided from (segment split or own views).
    pub evidence: Vec<Vec<f64>>,
}

/// Segment id per Gaussian: neighbours join when enough views put them in one region and
/// (nearly) none apart. Ids are numbered by first Gaussian, so they are deterministic.
pub fn build_segments(obs: &Observations, knn: &[u32], p: &ConsensusParams) -> Vec<u32> {
    let n = obs.n;
    let k = p.neighbours;
    let mut parent: Vec<u32> = (0..n as u32).collect();
    for g in 0..n {
        for &h in &knn[g * k..(g + 1) * k] {
            if h == NO_NEIGHBOUR || (h as usize) < g && knn_has(knn, k, h as usize, g) {
                continue; // absent, or the pair is tested from h's row
            }
            let c = co_occurrence(obs, g, h as usize);
            let views = (c.together + c.apart) as f64;
            if c.together >= p.min_together
                && c.apart as f64 <= p.max_apart_share * views
                && c.together as f64 >= p.min_together_share * c.views() as f64
            {
                union(&mut parent, g as u32, h);
            }
        }
    }
    let roots: Vec<u32> = (0..n as u32).map(|g| find(&mut parent, g)).collect();
    renumber(&roots)
}

/// Joins neighbouring segments whose dominant regions agree, view by view: a segment pools
/// all its Gaussians' views, so this test rests on far more views than one pair of
/// Gaussians (objects seen in few views per Gaussian, such as a ceiling, come out whole).
/// Rounds repeat until nothing joins.
pub fn merge_segments(
    obs: &Observations,
    knn: &[u32],
    mut segment: Vec<u32>,
    p: &ConsensusParams,
) -> Vec<u32> {
    let k = p.neighbours;
    for _round in 0..p.merge_rounds {
        let dominant = dominant_regions(obs, &segment);
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for g in 0..obs.n {
            for &h in &knn[g * k..(g + 1) * k] {
                if h != NO_NEIGHBOUR && segment[g] != segment[h as usize] {
                    let (a, b) = (segment[g], segment[h as usize]);
                    pairs.push((a.min(b), a.max(b)));
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let count = dominant.len();
        let mut parent: Vec<u32> = (0..count as u32).collect();
        let mut joined = false;
        for (a, b) in pairs {
            let (together, apart) = list_agreement(&dominant[a as usize], &dominant[b as usize]);
            let views = (together + apart) as f64;
            if together >= p.merge_min_together && apart as f64 <= p.merge_max_apart_share * views {
                union(&mut parent, a, b);
                joined = true;
            }
        }
        if !joined {
            break;
        }
        let roots: Vec<u32> = segment.iter().map(|&s| find(&mut parent, s)).collect();
        segment = renumber(&roots);
    }
    segment
}

/// Per segment: (view, the region holding most of its observations in that view), by view.
fn dominant_regions(obs: &Observations, segment: &[u32]) -> Vec<Vec<(u32, u32)>> {
    let count = segment.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
    let mut entries: Vec<(u32, u32, u32)> = Vec::with_capacity(obs.view.len());
    for (g, &seg) in segment.iter().enumerate().take(obs.n) {
        for i in obs.row(g) {
            entries.push((seg, obs.view[i], obs.region[i]));
        }
    }
    entries.sort_unstable();
    let mut out = vec![Vec::new(); count];
    for group in entries.chunk_by(|a, b| a.0 == b.0 && a.1 == b.1) {
        // Runs of one region; the longest wins, ties to the first (lowest region id).
        let mut best = (0usize, 0u32);
        for run in group.chunk_by(|a, b| a.2 == b.2) {
            if run.len() > best.0 {
                best = (run.len(), run[0].2);
            }
        }
        out[group[0].0 as usize].push((group[0].1, best.1));
    }
    out
}

/// Of the views in both lists (sorted by view): same region, different region.
fn list_agreement(a: &[(u32, u32)], b: &[(u32, u32)]) -> (u32, u32) {
    let (mut i, mut j, mut together, mut apart) = (0, 0, 0, 0);
    while i < a.len() && j < b.len() {
        match a[i].0.cmp(&b[j].0) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                if a[i].1 == b[j].1 {
                    together += 1;
                } else {
                    apart += 1;
                }
                (i, j) = (i + 1, j + 1);
            }
        }
    }
    (together, apart)
}

/// Dense ids numbered by first appearance.
fn renumber(keys: &[u32]) -> Vec<u32> {
    let mut id = std::collections::HashMap::new();
    keys.iter()
        .map(|&k| {
            let next = id.len() as u32;
            *id.entry(k).or_insert(next)
        })
        .collect()
}

fn knn_has(knn: &[u32], k: usize, row: usize, g: usize) -> bool {
    knn[row * k..(row + 1) * k].contains(&(g as u32))
}

/// The class with the most `votes`; ties go to the most `mass`; still tied: None.
fn decisive_argmax(votes: &[f64], mass: &[f64]) -> Option<usize> {
    let top = votes.iter().cloned().fold(0.0f64, f64::max);
    if top <= 0.0 {
        return None;
    }
    let tied: Vec<usize> = (0..votes.len()).filter(|&c| votes[c] == top).collect();
    if tied.len() == 1 {
        return Some(tied[0]);
    }
    let best = tied.iter().map(|&c| mass[c]).fold(f64::MIN, f64::max);
    let by_mass: Vec<usize> = tied.into_iter().filter(|&c| mass[c] == best).collect();
    (by_mass.len() == 1).then(|| by_mass[0])
}

/// Per segment: the views' votes (each view once) and the raw observation counts.
fn segment_votes(
    obs: &Observations,
    segment: &[u32],
    segments: usize,
    classes: usize,
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<usize>) {
    let mut entries: Vec<(u32, u32, u32)> = Vec::with_capacity(obs.view.len());
    for (g, &seg) in segment.iter().enumerate().take(obs.n) {
        for i in obs.row(g) {
            entries.push((seg, obs.view[i], obs.label[i]));
        }
    }
    entries.sort_unstable();
    let mut split = vec![vec![0.0; classes]; segments];
    let mut mass = vec![vec![0.0; classes]; segments];
    let mut views = vec![0usize; segments];
    for group in entries.chunk_by(|a, b| a.0 == b.0 && a.1 == b.1) {
        let s = group[0].0 as usize;
        let share = 1.0 / group.len() as f64;
        for &(_, _, label) in group {
            split[s][label as usize] += share;
            mass[s][label as usize] += 1.0;
        }
        views[s] += 1;
    }
    (split, mass, views)
}

/// Per Gaussian: how many of its views gave each class.
fn own_votes(obs: &Observations, classes: usize) -> Vec<Vec<f64>> {
    (0..obs.n)
        .map(|g| {
            let mut v = vec![0.0; classes];
            for i in obs.row(g) {
                v[obs.label[i] as usize] += 1.0;
            }
            v
        })
        .collect()
}

/// Decides segments and Gaussians from the observations, the neighbours and the segments.
pub fn decide(
    obs: &Observations,
    knn: &[u32],
    segment: Vec<u32>,
    classes: usize,
    p: &ConsensusParams,
) -> Consensus {
    let count = segment.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
    let (split, mass, views) = segment_votes(obs, &segment, count, classes);
    let mut sizes = vec![0usize; count];
    for &s in &segment {
        sizes[s as usize] += 1;
    }
    let segments: Vec<SegmentVotes> = (0..count)
        .map(|s| segment_summary(&split[s], &mass[s], sizes[s], views[s], p))
        .collect();
    let own = own_votes(obs, classes);
    let n = obs.n;
    let (mut class, mut conf, mut entropy) = (vec![None; n], vec![0f32; n], vec![0f32; n]);
    let mut from_segment = 0;
    let mut used = Vec::with_capacity(n);
    for g in 0..n {
        let s = segment[g] as usize;
        let own_total: f64 = own[g].iter().sum();
        let seg_class = segments[s].class.filter(|_| sizes[s] >= p.min_segment);
        let contradicted = seg_class
            .is_some_and(|c| own_total >= p.min_own_views as f64 && own[g][c] * 4.0 < own_total);
        let evidence: &[f64] = match seg_class {
            Some(c) if !contradicted => {
                class[g] = Some(c);
                from_segment += 1;
                &split[s]
            }
            _ => {
                class[g] = decisive_argmax(&own[g], &neighbour_votes(&own, knn, p.neighbours, g));
                &own[g]
            }
        };
        let (c, h) = posterior(evidence, class[g], p.prior);
        (conf[g], entropy[g]) = (c as f32, h as f32);
        used.push(evidence.to_vec());
    }
    Consensus {
        assignment: Assignment {
            class,
            confidence: conf,
        },
        entropy,
        segment,
        segments,
        from_segment,
        evidence: used,
    }
}

fn segment_summary(
    split: &[f64],
    mass: &[f64],
    gaussians: usize,
    views: usize,
    p: &ConsensusParams,
) -> SegmentVotes {
    let class = decisive_argmax(split, mass);
    let total: f64 = split.iter().sum();
    let mut shares: Vec<f64> = split.iter().map(|v| v / total.max(1e-300)).collect();
    shares.sort_by(|a, b| b.total_cmp(a));
    let runner_up = shares.get(1).copied().unwrap_or(0.0);
    SegmentVotes {
        gaussians,
        views,
        split: split.to_vec(),
        class,
        // Only a segment large and well enough seen for its split to mean something: a
        // singleton no view saw has no class either, and is not a finding.
        flagged: gaussians >= p.flag_min_gaussians
            && views >= p.flag_min_views
            && (class.is_none() || runner_up >= p.flag_share),
    }
}

/// The own votes of g's neighbours, summed: breaks a tie of g's own views.
fn neighbour_votes(own: &[Vec<f64>], knn: &[u32], k: usize, g: usize) -> Vec<f64> {
    let mut sum = vec![0.0; own[g].len()];
    for &h in &knn[g * k..(g + 1) * k] {
        if h != NO_NEIGHBOUR {
            for (s, v) in sum.iter_mut().zip(&own[h as usize]) {
                *s += v;
            }
        }
    }
    sum
}

/// Posterior mean of `class` under a Dirichlet(prior + counts), and the entropy (nats) of the
/// posterior mean; unseen or undecided: 0 and ln(classes).
pub fn posterior(counts: &[f64], class: Option<usize>, prior: f64) -> (f64, f64) {
    let k = counts.len() as f64;
    let total: f64 = counts.iter().sum::<f64>() + prior * k;
    let entropy = -counts
        .iter()
        .map(|c| (c + prior) / total)
        .filter(|&q| q > 0.0)
        .map(|q| q * q.ln())
        .sum::<f64>();
    match class {
        Some(c) if counts.iter().sum::<f64>() > 0.0 => ((counts[c] + prior) / total, entropy),
        _ => (0.0, k.ln()),
    }
}
