//! What segment consensus found, for people: the segments whose views disagree (flagged:
//! close or bimodal vote splits of segments that are objects in their views, not slivers at
//! an edge; where a consistently mislabeled object shows) and, per
//! class, how the views voted on the segments given that class (`fuse --report`).

use serde::Serialize;

use super::consensus_decide::Consensus;
use super::consensus_flags::flagged_ids;
use super::consensus_segments::Groups;

/// The votes of some views over the classes, named, largest first (classes without votes
/// left out).
pub type NamedVotes = Vec<(String, f64)>;

/// One segment's vote split.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentSplit {
    /// The `segment` property of its Gaussians in the fused PLY.
    pub segment: u32,
    pub gaussians: usize,
    /// Views that observed any of its Gaussians (each votes once).
    pub views: usize,
    /// The class it was given (None: no decisive class).
    pub class: Option<String>,
    /// Its top classes were within the tie margin (one view's vote by default); `class` is
    /// the one the scene's class confusions make likeliest.
    pub near_tie: bool,
    pub votes: NamedVotes,
    /// Where it is: the mean and the bounds (least and greatest x, y, z) of its Gaussians'
    /// centers, in the scene's coordinates.
    pub center: [f32; 3],
    pub bounds: [[f32; 3]; 2],
    /// Per class, the views (camera names) that gave it most of the segment's observations:
    /// the frames to look at, most views first.
    pub views_by_class: Vec<(String, Vec<String>)>,
}

/// The segments given one class, and what their views said.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClassSplit {
    pub class: String,
    pub segments: usize,
    pub gaussians: usize,
    /// Votes summed over those segments: the share not for `class` is how often the views
    /// called these objects something else.
    pub votes: NamedVotes,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentReport {
    /// Segments of at least `min_segment` Gaussians.
    pub segments: usize,
    /// Of those, the ones no class was decided for (their votes tied): `per_class` lists
    /// the others.
    pub undecided: usize,
    /// Gaussians whose class came from their segment, those of small segments that took
    /// their neighbours' segments' class, those decided by their own views (a tie left them
    /// without a class) and those no view observed: every Gaussian; and of the last, those
    /// that took their neighbours' class.
    pub from_segment: usize,
    pub from_neighbour_segments: usize,
    pub from_own_views: usize,
    pub unobserved: usize,
    pub from_neighbours: usize,
    /// Observed Gaussians of small segments whose class their neighbours' classes then
    /// changed.
    pub smoothed: usize,
    /// Flagged segments, largest first: check these objects' labels.
    pub flagged: Vec<SegmentSplit>,
    pub per_class: Vec<ClassSplit>,
}

/// The report of `consensus`; `names[c]` names compact class c, `cameras[v]` view v, `means`
/// are the Gaussians' centers, and segments of fewer than `min_segment` Gaussians are not
/// counted.
pub fn segment_report(
    consensus: &Consensus,
    names: &[String],
    cameras: &[String],
    means: &[[f32; 3]],
    min_segment: usize,
) -> SegmentReport {
    assert_eq!(
        means.len(),
        consensus.segment.len(),
        "a center per Gaussian"
    );
    // Votes given as (class, votes).
    let named = |votes: &mut dyn Iterator<Item = (usize, f64)>| -> NamedVotes {
        let mut out: NamedVotes = votes
            .filter(|&(_, v)| v > 0.0)
            // Shares of views summed in floating point: 23 reads 22.999999999999595.
            .map(|(c, v)| (names[c].clone(), (v * 1e3).round() / 1e3))
            .collect();
        out.sort_by(|a, b| b.1.total_cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
        out
    };
    let places = flagged_places(consensus, means);
    let mut flagged: Vec<SegmentSplit> = flagged_ids(&consensus.segments)
        .into_iter()
        .zip(places)
        .map(|(s, (center, bounds))| {
            let seg = &consensus.segments[s as usize];
            SegmentSplit {
                segment: s,
                gaussians: seg.gaussians,
                views: seg.views,
                class: seg.class.map(|c| names[c].clone()),
                near_tie: seg.near_tie,
                votes: named(&mut seg.split.iter().map(|&(c, v)| (c as usize, v))),
                center,
                bounds,
                views_by_class: views_by_class(&seg.view_classes, names, cameras),
            }
        })
        .collect();
    flagged.sort_by_key(|s| (std::cmp::Reverse(s.gaussians), s.segment));
    SegmentReport {
        segments: (consensus.segments.iter())
            .filter(|s| s.gaussians >= min_segment)
            .count(),
        undecided: (consensus.segments.iter())
            .filter(|s| s.gaussians >= min_segment && s.class.is_none())
            .count(),
        from_segment: consensus.from_segment,
        from_neighbour_segments: consensus.from_neighbour_segments,
        from_own_views: consensus.from_own_views,
        unobserved: consensus.unobserved,
        from_neighbours: consensus.from_neighbours,
        smoothed: consensus.smoothed,
        flagged,
        per_class: class_splits(consensus, names.len(), min_segment)
            .map(|(c, (segments, gaussians, votes))| ClassSplit {
                class: names[c].clone(),
                segments,
                gaussians,
                votes: named(&mut votes.iter().copied().enumerate()),
            })
            .collect(),
    }
}

/// Per class decided for any segment of at least `min_segment` Gaussians: (class, (those
/// segments, their Gaussians, their votes summed)), by class.
fn class_splits(
    consensus: &Consensus,
    classes: usize,
    min_segment: usize,
) -> impl Iterator<Item = (usize, (usize, usize, Vec<f64>))> {
    // A row of votes only for the classes decided (a table of every class by every class
    // held 215 MB for 5,191 classes).
    let mut per_class = vec![(0, 0, Vec::new()); classes];
    let sized = (consensus.segments.iter()).filter(|s| s.gaussians >= min_segment);
    for seg in sized {
        if let Some(c) = seg.class {
            let (segments, gaussians, votes) = &mut per_class[c];
            *segments += 1;
            *gaussians += seg.gaussians;
            votes.resize(classes, 0.0);
            for &(l, v) in &seg.split {
                votes[l as usize] += v;
            }
        }
    }
    (per_class.into_iter().enumerate()).filter(|(_, e)| e.0 > 0)
}

/// Per flagged segment, in id order: the mean and the bounds of its Gaussians' centers. A
/// flagged segment has Gaussians (`flag_min_gaussians`); one without would read as the
/// origin with bounds of +-infinity.
fn flagged_places(consensus: &Consensus, means: &[[f32; 3]]) -> Vec<([f32; 3], [[f32; 3]; 2])> {
    let members = Groups::by_key(&consensus.segment, consensus.segments.len());
    let place = |s: u32| {
        let (mut sum, mut bounds) = ([0.0f64; 3], [[f32::INFINITY; 3], [f32::NEG_INFINITY; 3]]);
        let centers = members.group(s as usize).iter().map(|&g| means[g as usize]);
        for m in centers {
            for a in 0..3 {
                sum[a] += m[a] as f64;
                bounds[0][a] = bounds[0][a].min(m[a]);
                bounds[1][a] = bounds[1][a].max(m[a]);
            }
        }
        let n = members.group(s as usize).len().max(1) as f64;
        (sum.map(|x| (x / n) as f32), bounds)
    };
    flagged_ids(&consensus.segments)
        .into_iter()
        .map(place)
        .collect()
}

/// A flagged segment's (view, class) pairs as camera names per class name, the class with
/// most views first (ties: by name).
fn views_by_class(
    view_classes: &[(u32, u32)],
    names: &[String],
    cameras: &[String],
) -> Vec<(String, Vec<String>)> {
    let mut by_class: Vec<(String, Vec<String>)> = Vec::new();
    for &(view, class) in view_classes {
        let camera = cameras
            .get(view as usize)
            .unwrap_or_else(|| panic!("view {view} of {} cameras named", cameras.len()));
        let class = &names[class as usize];
        match by_class.iter_mut().find(|(c, _)| c == class) {
            Some((_, views)) => views.push(camera.clone()),
            None => by_class.push((class.clone(), vec![camera.clone()])),
        }
    }
    by_class.sort_by(|a, b| b.1.len().cmp(&a.1.len()).then_with(|| a.0.cmp(&b.0)));
    by_class
}
