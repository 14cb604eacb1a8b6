//! Segment consensus, near ties: a segment whose top classes are within one view's vote (a
//! large segment: within one standard deviation of a coin flip) is decided by how the
//! scene's views confuse classes, estimated from the segments the votes decide clearly (a
//! Dawid-Skene step with the segments as items).
//!
//! Why: a segmenter's mistakes are not symmetric. In the synthetic rooms' flicker (a fixed
//! list of look-alikes per class) a dining table is taken for the coffee table, while a
//! coffee table is taken for a dining table or a side table; so a segment voted 10 : 10
//! between the two, with no side-table vote, is far likelier a dining table. Counting views
//! alone leaves such a segment to a coin flip, and a large one (a whole table) moves the
//! mean IoU by points. Deciding every segment this way instead was measured and dropped:
//! clear majorities are better left to the votes (likely, not checked: the estimate also
//! carries the views' correlated mistakes, as of a wall behind a picture).

use super::consensus_decide::{ConsensusParams, SegmentVotes};
use super::shared_counts::{count_of, SparseCounts, SumsByGaussian};

/// Per class, how the views of the segments decided as that class voted (each view's votes
/// are shares of the segment's observations, so a row sums to the views counted), and the
/// prior each row is smoothed toward ([`Confusions::prior`]). Kept by the votes given: a
/// table of every pair of classes cost K² values, three tables of 0.22 GB each at 5,191
/// classes, nearly all of them one value per row.
#[derive(Clone, Debug, PartialEq)]
struct Confusions {
    /// `votes[k]`: (l, votes for class l from the views of segments decided as class k), in
    /// class order.
    votes: Vec<Vec<(u32, f64)>>,
    /// `totals[k]`: row k's votes summed, once (each rate read it again: the table of K²
    /// rates cost K³, 140 s of a fusion at 5,000 classes).
    totals: Vec<f64>,
    /// `mistaken[k]`: the share of a k's views the prior expects to call it another class.
    mistaken: Vec<f64>,
    /// `taken_sum[k]`: [`Confusions::taken_for`] summed over every class, which the prior's
    /// share of k's mistakes for each class is divided by.
    taken_sum: Vec<f64>,
}

/// A class the views take for a label more often than this is one the label may be the
/// flicker of (under flicker 0.3 a look-alike is called so in 5-27% of the views, other
/// classes in under 2%): `--relabel`'s regions and a small segment's region votes relabel
/// a region only to such a class, or leave it its label (docs/robustness-log.md).
pub const LOOK_ALIKE_RATE: f64 = 0.03;

/// Spread over the other classes and added to every rate at which one class's views call
/// another ([`Confusions::prior`]), so a confusion no clear segment showed is unlikely, not
/// impossible; also the least share of a row's prior the other classes get.
const UNSEEN_CONFUSION: f64 = 0.01;

impl Confusions {
    /// From the segments decided clearly ([`clear_class`]).
    fn estimate(segments: &[SegmentVotes], classes: usize, p: &ConsensusParams) -> Self {
        let mut votes = SumsByGaussian::new(classes);
        for s in segments {
            if let Some(k) = clear_class(s, p) {
                for &(l, v) in &s.split {
                    votes.add(k, l, v);
                }
            }
        }
        let votes: Vec<Vec<(u32, f64)>> = votes.into_sorted_rows().collect();
        let totals: Vec<f64> = votes
            .iter()
            .map(|row| row.iter().map(|e| e.1).sum())
            .collect();
        let mut c = Confusions {
            votes,
            totals,
            mistaken: Vec::new(),
            taken_sum: Vec::new(),
        };
        (c.mistaken, c.taken_sum) = c.mirrored_prior();
        c
    }

    fn classes(&self) -> usize {
        self.votes.len()
    }

    /// Votes for class l from the views of segments decided as class k.
    fn vote(&self, k: usize, l: usize) -> f64 {
        count_of(&self.votes[k], l)
    }

    /// P(a view votes l | the segment is class k): row k's votes smoothed toward its prior
    /// with the weight of `prior_views` views, so a class seen in few clear segments is
    /// neither trusted nor ruled out.
    fn rate(&self, k: usize, l: usize, prior_views: f64) -> f64 {
        self.smoothed(k, self.vote(k, l), self.prior(k, l), prior_views)
    }

    /// Row k's `vote` for a class smoothed toward its `prior` ([`Confusions::rate`]).
    fn smoothed(&self, k: usize, vote: f64, prior: f64, prior_views: f64) -> f64 {
        (vote + prior_views * prior) / (self.totals[k] + prior_views)
    }

    /// ln P(split | the segment is class k): each vote an independent draw from row k.
    fn log_likelihood(&self, k: usize, split: &SparseCounts, prior_views: f64) -> f64 {
        (split.iter())
            .filter(|&&(_, v)| v > 0.0)
            .map(|&(l, v)| v * self.rate(k, l as usize, prior_views).ln())
            .sum()
    }

    /// The least share of k's mistakes the prior gives each other class.
    fn floor(&self) -> f64 {
        UNSEEN_CONFUSION / (self.classes() - 1) as f64
    }

    /// How often the views of the l's call them k (of the l's own votes; `floor` added), for
    /// l other than k: what k is taken for in the prior.
    fn taken_for(&self, k: usize, l: usize) -> f64 {
        match self.totals[l] > 0.0 {
            true => self.vote(l, k) / self.totals[l] + self.floor(),
            false => self.floor(),
        }
    }

    /// The prior of row k, P(a view says l | the segment is k) before the row's own votes,
    /// mirrored: a view of a k calls it l in proportion to how often views of the l's call
    /// them k (look-alikes are mutual: where ceilings are called wall, walls are called
    /// ceiling), and k for the rest (`mistaken`). So a class seen in no clear segment (the
    /// ceiling, when its one large segment is the near tie) is expected to be called what
    /// its look-alikes are called, and its near ties go by the votes and the other classes'
    /// confusions. With the prior's confusions spread evenly over the other classes
    /// instead, such a class rarely expects any one of them, and loses its close votes
    /// against a well-seen class (office seed 3 at flicker 0.3: a ceiling of 27,006
    /// Gaussians voted 12 : 11 went to the wall).
    fn prior(&self, k: usize, l: usize) -> f64 {
        match (self.classes() < 2, l == k) {
            (true, _) => 1.0, // nothing to be taken for
            (false, true) => 1.0 - self.mistaken[k],
            (false, false) => self.share_of_mistakes(k, self.taken_for(k, l)),
        }
    }

    /// The prior's share of k's mistakes for a class k is `taken_for` that often.
    fn share_of_mistakes(&self, k: usize, taken_for: f64) -> f64 {
        self.mistaken[k] * taken_for / self.taken_sum[k]
    }

    /// Per class k, the share of its views the mirrored prior expects to call it another
    /// class, and what it is taken for summed over the classes ([`Confusions::prior`]).
    ///
    /// The mirrored rates say which classes a k is taken for, not how often: a k is mistaken
    /// as often as the classes it is taken for are (their rows' disagreement, weighted by
    /// those rates; the scene's for a class with no clear segment; at least
    /// `UNSEEN_CONFUSION`), and that share goes to them. A class with one look-alike takes
    /// all its mistakes there, though that look-alike, having several, is taken for it
    /// rarely (office seed 2 at flicker 0.3: the desks, labelled cabinet in 15 of their 28
    /// views, against a cabinet labelled desk in 2 of 21; with the cabinet's rate as the
    /// desk's share the desks stayed cabinet). The scene's disagreement alone would make a
    /// ceiling beside often-confused walls in a room of rarely confused furniture rarely
    /// called wall.
    fn mirrored_prior(&self) -> (Vec<f64>, Vec<f64>) {
        let (classes, rows) = (self.classes(), &self.totals);
        if classes < 2 {
            return (Vec::new(), Vec::new());
        }
        let own: f64 = (0..classes).map(|k| self.vote(k, k)).sum();
        let all: f64 = rows.iter().sum();
        let scene_mistaken = if all > 0.0 { 1.0 - own / all } else { 0.0 };
        let mistaken: Vec<f64> = (0..classes)
            .map(|l| match rows[l] > 0.0 {
                true => 1.0 - self.vote(l, l) / rows[l],
                false => scene_mistaken,
            })
            .collect();
        // Row k's taken_for in full, from the votes' column k (the l's that called a k).
        let columns = self.columns();
        let mut taken_for = vec![0.0; classes];
        let (mut k_mistaken, mut taken_sum) = (Vec::new(), Vec::new());
        for (k, column) in columns.iter().enumerate() {
            taken_for.fill(self.floor());
            for &(l, _) in column.iter().filter(|&&(l, _)| l as usize != k) {
                taken_for[l as usize] = self.taken_for(k, l as usize);
            }
            taken_for[k] = 0.0;
            let sum: f64 = taken_for.iter().sum();
            let mistaken_k = (0..classes)
                .map(|l| taken_for[l] * mistaken[l] / sum)
                .sum::<f64>()
                .max(UNSEEN_CONFUSION);
            k_mistaken.push(mistaken_k);
            taken_sum.push(sum);
        }
        (k_mistaken, taken_sum)
    }

    /// Per class k, the classes l whose views voted for it: (l, votes), in class order.
    fn columns(&self) -> Vec<Vec<(u32, f64)>> {
        let mut columns = vec![Vec::new(); self.classes()];
        for (l, row) in self.votes.iter().enumerate() {
            for &(k, v) in row {
                columns[k as usize].push((l as u32, v));
            }
        }
        columns
    }

    /// Every rate ([`Confusions::rate`]) as [`ConfusionRates`]: per row k, the rates of the
    /// classes its views or its look-alikes' voted for, and one for all the others (their
    /// votes and their `taken_for` alike: none and `floor`).
    fn rates(&self, prior_views: f64) -> ConfusionRates {
        let columns = self.columns();
        let mut rows = Vec::with_capacity(self.classes());
        for (k, column) in columns.iter().enumerate() {
            let mut named: Vec<u32> = (self.votes[k].iter().chain(column))
                .map(|e| e.0)
                .chain([k as u32])
                .collect();
            named.sort_unstable();
            named.dedup();
            let rates = (named.iter())
                .map(|&l| (l, self.rate(k, l as usize, prior_views)))
                .collect();
            // No vote, and taken for it no more than `floor`.
            let others = match self.classes() < 2 {
                true => 1.0,
                false => {
                    let prior = self.share_of_mistakes(k, self.floor());
                    self.smoothed(k, 0.0, prior, prior_views)
                }
            };
            rows.push(RateRow { rates, others });
        }
        ConfusionRates { rows }
    }
}

/// P(a view votes l | its segment is class k) for every pair of classes, as the scene's
/// clearly decided segments show it (the rates the near ties are decided by). `--relabel`
/// reads it to tell a label region that may show a whole object relabeled (its Gaussians'
/// class is one the views take for the region's label) from one whose edge was drawn a few
/// pixels off ([`RelabelRule::max_edge_confusion`](super::consensus_relabel::RelabelRule)).
#[derive(Clone, Debug, PartialEq)]
pub struct ConfusionRates {
    /// Per class k.
    rows: Vec<RateRow>,
}

/// One class's rates: those listed, the same one for every other label.
#[derive(Clone, Debug, PartialEq)]
struct RateRow {
    /// (label, rate), in label order.
    rates: Vec<(u32, f64)>,
    others: f64,
}

impl ConfusionRates {
    /// From a row-major [classes][classes] table.
    pub fn from_rows(classes: usize, rates: Vec<f64>) -> Self {
        assert_eq!(rates.len(), classes * classes, "a [classes][classes] table");
        let row = |k: usize| RateRow {
            rates: (0..classes)
                .map(|l| (l as u32, rates[k * classes + l]))
                .collect(),
            others: 1.0, // every label listed
        };
        ConfusionRates {
            rows: (0..classes).map(row).collect(),
        }
    }

    /// None known: every class may be taken for every label.
    pub fn unknown() -> Self {
        ConfusionRates::from_rows(0, Vec::new())
    }

    /// P(a view votes `label` | the segment is `class`); 1 where either is outside the
    /// table (nothing known rules a confusion out).
    pub fn rate(&self, class: usize, label: usize) -> f64 {
        let classes = self.rows.len();
        if class >= classes || label >= classes {
            return 1.0;
        }
        let row = &self.rows[class];
        match row.rates.binary_search_by_key(&(label as u32), |e| e.0) {
            Ok(i) => row.rates[i].1,
            Err(_) => row.others,
        }
    }
}

/// A segment's class where its votes decide it clearly: at least `min_segment` Gaussians,
/// at least `confusion_min_views` views, the class holding at least `confusion_min_share` of
/// the votes, and not a near tie. What the confusions are estimated from, and what a label
/// region says of the small segments in it (src/fuse/consensus_region_votes.rs).
pub(crate) fn clear_class(s: &SegmentVotes, p: &ConsensusParams) -> Option<usize> {
    let k = s.class?;
    let clear = s.gaussians >= p.min_segment
        && s.views >= p.confusion_min_views
        && s.votes_for(k) >= p.confusion_min_share * s.total()
        && tied_classes(s, p).len() < 2;
    clear.then_some(k)
}

/// The classes near a segment's top: within `tie_margin` votes of it, and in a segment of at
/// least `large_tie_gaussians` also within `large_tie_z` sqrt(top + theirs), the standard
/// deviation of the difference a fair coin would give over those votes (none where nothing
/// was voted).
pub(crate) fn tied_classes(s: &SegmentVotes, p: &ConsensusParams) -> Vec<usize> {
    let top = s.split.iter().map(|&(_, v)| v).fold(0.0f64, f64::max);
    let large = s.gaussians >= p.large_tie_gaussians;
    let margin = |votes: f64| match large {
        true => p.tie_margin.max(p.large_tie_z * (top + votes).sqrt()),
        false => p.tie_margin,
    };
    (s.split.iter())
        .filter(|&&(_, v)| v > 0.0 && v >= top - margin(v))
        .map(|&(c, _)| c as usize)
        .collect()
}

/// Decides the near ties of segments of at least `min_segment` Gaussians by the
/// confusions estimated from the others; a segment keeps its class where the likelihoods
/// tie. Returns the confusions' rates.
pub fn decide_near_ties(
    segments: &mut [SegmentVotes],
    classes: usize,
    p: &ConsensusParams,
) -> ConfusionRates {
    let confusions = Confusions::estimate(segments, classes, p);
    for s in segments.iter_mut().filter(|s| s.gaussians >= p.min_segment) {
        let tied = tied_classes(s, p);
        if tied.len() < 2 {
            continue;
        }
        let likelihood: Vec<f64> = tied
            .iter()
            .map(|&k| confusions.log_likelihood(k, &s.split, p.confusion_prior_views))
            .collect();
        let best = likelihood.iter().cloned().fold(f64::MIN, f64::max);
        let at_best: Vec<usize> = (0..tied.len()).filter(|&i| likelihood[i] == best).collect();
        s.near_tie = true;
        if let [only] = at_best[..] {
            let k = tied[only];
            if confusions.totals[k] > 0.0 || prior_may_decide(s, k, p) {
                s.class = Some(k);
            }
        }
    }
    confusions.rates(p.confusion_prior_views)
}

/// Of a large segment's near-tie margin, the share within which a class no clear segment
/// showed may take the segment against its votes.
const PRIOR_ONLY_MARGIN_SHARE: f64 = 2.0 / 3.0;

/// Whether a near tie may go to `k` against the segment's votes where `k`'s confusions are
/// prior alone (no clear segment showed it): where `k` is within one view's vote of the
/// votes' class, or within two thirds of a large segment's margin (of a standard deviation
/// of a coin flip's difference). A prior is enough to decide what is nearly a coin flip
/// (desks voted desk 13 : cabinet 15, 0.38 of one, the desks' one segment the near tie;
/// 5 : 7, 0.58), not a lean of a whole standard deviation (a wall of a room without a
/// ceiling, voted wall 6 : ceiling 3, had gone to the ceiling; 5 : 3, 0.71).
fn prior_may_decide(s: &SegmentVotes, k: usize, p: &ConsensusParams) -> bool {
    let Some(voted) = s.class.filter(|&c| c != k) else {
        return true; // not against the votes
    };
    let (top, theirs) = (s.votes_for(voted), s.votes_for(k));
    let half_margin = PRIOR_ONLY_MARGIN_SHARE * p.large_tie_z * (top + theirs).sqrt();
    let margin = match s.gaussians >= p.large_tie_gaussians {
        true => p.tie_margin.max(half_margin),
        false => p.tie_margin,
    };
    top - theirs <= margin
}

#[cfg(test)]
mod tests {
    use super::*;

    fn segment(split: &[f64], class: Option<usize>) -> SegmentVotes {
        SegmentVotes {
            gaussians: 50,
            views: split.iter().sum::<f64>().round() as usize,
            split: (split.iter().enumerate())
                .filter(|&(_, &v)| v != 0.0)
                .map(|(c, &v)| (c as u32, v))
                .collect(),
            class,
            near_tie: false,
            flagged: false,
            view_classes: Vec::new(),
        }
    }

    /// Classes a, b, c: a is taken for b in 3 of 10 views; b for a and for c in 1.5 each.
    fn scene(tied: &[f64], tied_class: Option<usize>) -> Vec<SegmentVotes> {
        let mut s = vec![segment(tied, tied_class)];
        for _ in 0..3 {
            s.push(segment(&[7.0, 3.0, 0.0], Some(0)));
            s.push(segment(&[1.5, 7.0, 1.5], Some(1)));
            s.push(segment(&[0.0, 1.0, 9.0], Some(2)));
        }
        s
    }

    #[test]
    fn estimate_counts_only_clear_segments() {
        let p = ConsensusParams::default();
        let mut s = scene(&[5.0, 5.0, 0.0], Some(1));
        s.push(segment(&[3.0, 2.0, 0.0], Some(0))); // a near tie (60%, five views)
        s.push(segment(&[3.0, 0.0, 0.0], Some(0))); // three views
        s.push(segment(&[5.5, 4.0, 0.5], Some(0))); // a 55% share
        let mut few = segment(&[9.0, 1.0, 0.0], Some(0));
        few.gaussians = p.min_segment - 1;
        s.push(few);
        let c = Confusions::estimate(&s, 3, &p);
        let row = |k| (0..3).map(|l| c.vote(k, l)).collect::<Vec<f64>>();
        assert_eq!(row(0), vec![21.0, 9.0, 0.0]);
        assert_eq!(row(1), vec![4.5, 21.0, 4.5]);
        assert_eq!(row(2), vec![0.0, 3.0, 27.0]);
        for k in 0..3 {
            assert!(((0..3).map(|l| c.prior(k, l)).sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    /// The rates kept by the classes voted give every pair of classes its rate, on a scene
    /// of many classes each confused with a few: the prior's rows sum to 1, and most rates
    /// are the row's one for the classes not listed.
    #[test]
    fn rates_kept_by_the_votes_are_every_pairs_rate() {
        let (p, classes, mut rng) = (ConsensusParams::default(), 40, crate::util::Rng::new(5));
        let segments: Vec<SegmentVotes> = (0..300)
            .map(|_| {
                let k = rng.below(classes as u64) as usize;
                let mut split = vec![0.0; classes];
                split[k] = 8.0 + rng.below(4) as f64;
                for _ in 0..2 {
                    split[(k + 1 + rng.below(3) as usize) % classes] += rng.below(3) as f64;
                }
                segment(&split, Some(k))
            })
            .collect();
        let c = Confusions::estimate(&segments, classes, &p);
        let pv = p.confusion_prior_views;
        let rates = c.rates(pv);
        let mut listed = 0;
        for k in 0..classes {
            let prior: f64 = (0..classes).map(|l| c.prior(k, l)).sum();
            assert!(
                (prior - 1.0).abs() < 1e-12,
                "row {k}'s prior sums to {prior}"
            );
            for l in 0..classes {
                assert_eq!(rates.rate(k, l), c.rate(k, l, pv), "({k}, {l})");
            }
            listed += rates.rows[k].rates.len();
        }
        assert!(listed < classes * classes / 4, "{listed} rates listed");
        assert_eq!(rates.rate(classes, 0), 1.0, "outside the table");
    }

    /// The likelihood against the formula written out for one case: row a of 30 views
    /// smoothed by 10 prior views. In the prior b and c share a's mistakes as often as b's
    /// and c's views call them a (4.5 of 30, never; plus 0.01 / 2 each), and a is mistaken
    /// as often as they are, weighted the same (b's views give b 21 of 30, c's c 27 of 30).
    #[test]
    fn likelihood_is_the_smoothed_row() {
        let p = ConsensusParams::default();
        let c = Confusions::estimate(&scene(&[5.0, 5.0, 0.0], None), 3, &p);
        let (b, c_): (f64, f64) = (4.5 / 30.0 + 0.005, 0.0 / 30.0 + 0.005);
        let mistaken = (b * 9.0 / 30.0 + c_ * 3.0 / 30.0) / (b + c_);
        let prior = [
            1.0 - mistaken,
            mistaken * b / (b + c_),
            mistaken * c_ / (b + c_),
        ];
        let p_aa = (21.0 + 10.0 * prior[0]) / 40.0;
        let p_ab = (9.0 + 10.0 * prior[1]) / 40.0;
        let p_ac = (0.0 + 10.0 * prior[2]) / 40.0;
        let expected = 2.0 * p_aa.ln() + 3.0 * p_ab.ln() + 0.5 * p_ac.ln();
        let got = c.log_likelihood(0, &[(0, 2.0), (1, 3.0), (2, 0.5)], 10.0);
        assert!((got - expected).abs() < 1e-12, "{got} against {expected}");
    }

    /// A large wall segment (0) voted 6 : 3 against the ceiling (1), a class no clear
    /// segment shows (the room has none; its views call walls ceiling now and then): near
    /// by a large segment's margin, and the likelihood favours the ceiling (the walls'
    /// mistakes spread over three classes, the ceiling's row, prior alone, puts all of its
    /// on the wall); the votes stand. A coin flip (5 : 4) the prior decides; and once a
    /// ceiling segment is seen clearly, its row is evidence and the 6 : 3 goes by it.
    #[test]
    fn a_near_tie_goes_against_a_majority_only_toward_a_class_seen_clearly() {
        let p = ConsensusParams::default();
        let decided = |split: &[f64], clear_ceiling: bool| {
            let mut tied = segment(split, Some(0));
            tied.gaussians = p.large_tie_gaussians;
            let mut s = vec![tied];
            for _ in 0..3 {
                s.push(segment(&[6.0, 1.0, 1.5, 1.5], Some(0)));
                s.push(segment(&[1.0, 0.0, 9.0, 0.0], Some(2)));
                s.push(segment(&[1.0, 0.0, 0.0, 9.0], Some(3)));
            }
            if clear_ceiling {
                s.push(segment(&[3.0, 7.0, 0.0, 0.0], Some(1)));
            }
            let c = Confusions::estimate(&s, 4, &p);
            let likelihood = |k| c.log_likelihood(k, &s[0].split, p.confusion_prior_views);
            assert!(
                likelihood(1) > likelihood(0),
                "the confusions favour the ceiling"
            );
            decide_near_ties(&mut s, 4, &p);
            assert!(s[0].near_tie);
            s[0].class
        };
        assert_eq!(
            decided(&[6.0, 3.0, 0.0, 0.0], false),
            Some(0),
            "the majority stands"
        );
        assert_eq!(
            decided(&[5.0, 4.0, 0.0, 0.0], false),
            Some(1),
            "a coin flip"
        );
        assert_eq!(
            decided(&[6.0, 3.0, 0.0, 0.0], true),
            Some(1),
            "a ceiling seen clearly"
        );
    }

    /// A 5 : 5 split between a and b, no vote for c: a (taken for b in 30% of views) is
    /// likelier than b (taken for a in 15%, and for c as often, which no view did), whatever
    /// the votes' own tie-break gave.
    #[test]
    fn a_near_tie_goes_to_the_class_whose_confusions_explain_it() {
        let p = ConsensusParams::default();
        for before in [Some(1), None] {
            let mut s = scene(&[5.0, 5.0, 0.0], before);
            decide_near_ties(&mut s, 3, &p);
            assert_eq!(s[0].class, Some(0));
            assert!(s[0].near_tie);
            assert!(
                s[1..].iter().all(|s| !s.near_tie),
                "clear segments untouched"
            );
        }
        // Within one view's vote is near; more than that is the votes' to decide.
        let mut s = scene(&[4.0, 5.0, 0.0], Some(1));
        decide_near_ties(&mut s, 3, &p);
        assert_eq!((s[0].class, s[0].near_tie), (Some(0), true));
        let mut s = scene(&[3.9, 5.0, 0.0], Some(1));
        decide_near_ties(&mut s, 3, &p);
        assert_eq!((s[0].class, s[0].near_tie), (Some(1), false));
    }

    /// A class with no clear segment of its own (a ceiling whose one large segment is the
    /// near tie) against a well-seen class whose views call it that class now and then, in
    /// a room of twelve classes: its prior expects it to be called the wall about as often
    /// as walls are called ceiling (mirrored), so 12 : 11 goes to the ceiling. With the
    /// prior's confusions spread evenly over the eleven other classes it went to the wall.
    #[test]
    fn a_class_without_clear_segments_is_not_ruled_out() {
        let p = ConsensusParams::default();
        let (wall, ceiling, door, classes) = (0, 1, 2, 12);
        let votes = |pairs: &[(usize, f64)]| {
            let mut split = vec![0.0; classes];
            pairs.iter().for_each(|&(c, v)| split[c] = v);
            split
        };
        let mut s = vec![segment(
            &votes(&[(wall, 11.0), (ceiling, 12.0)]),
            Some(wall),
        )];
        for _ in 0..3 {
            let wall_views = votes(&[(wall, 7.0), (ceiling, 1.5), (door, 1.5)]);
            s.push(segment(&wall_views, Some(wall)));
            s.push(segment(&votes(&[(wall, 3.0), (door, 7.0)]), Some(door)));
            for other in 3..classes {
                s.push(segment(&votes(&[(other, 10.0)]), Some(other)));
            }
        }
        decide_near_ties(&mut s, classes, &p);
        assert_eq!((s[0].class, s[0].near_tie), (Some(ceiling), true));
    }

    /// Symmetric confusions say nothing: the segment keeps what its votes gave it (also
    /// undecided), never the lower class id.
    #[test]
    fn a_tie_of_likelihoods_keeps_the_class() {
        let p = ConsensusParams::default();
        for before in [Some(1), None] {
            let mut s = vec![segment(&[5.0, 5.0], before)];
            for _ in 0..3 {
                s.push(segment(&[8.0, 2.0], Some(0)));
                s.push(segment(&[2.0, 8.0], Some(1)));
            }
            decide_near_ties(&mut s, 2, &p);
            assert_eq!((s[0].class, s[0].near_tie), (before, true));
        }
    }

    /// A room of desk, cabinet and shelf: the cabinet, well seen, is labelled shelf and desk
    /// in 3 of 20 views each; no desk segment is clear. A desk's only look-alike is the
    /// cabinet, so its prior gives the cabinet all of its mistakes, as many as the cabinet
    /// makes (30%), not the cabinet's 15% of being called desk; a large segment voted
    /// cabinet 7 : desk 5 (a near tie for its size) is then likelier a desk, whose views call
    /// it cabinet, than a cabinet called desk in five of twelve views.
    #[test]
    fn a_class_with_one_look_alike_takes_all_its_mistakes_there() {
        let p = ConsensusParams::default();
        let (desk, cabinet) = (0, 1);
        let mut s = vec![segment(&[5.0, 7.0, 0.0], Some(cabinet))];
        s[0].gaussians = p.large_tie_gaussians;
        for _ in 0..3 {
            s.push(segment(&[3.0, 14.0, 3.0], Some(cabinet)));
            s.push(segment(&[0.0, 3.0, 17.0], Some(2)));
        }
        let c = Confusions::estimate(&s, 3, &p);
        let (by_cabinet, by_shelf): (f64, f64) = (3.0 / 20.0 + 0.005, 0.005);
        let mistaken = (by_cabinet * 0.3 + by_shelf * 0.15) / (by_cabinet + by_shelf);
        assert!((c.prior(desk, desk) - (1.0 - mistaken)).abs() < 1e-12);
        let to_cabinet = mistaken * by_cabinet / (by_cabinet + by_shelf);
        assert!((c.prior(desk, cabinet) - to_cabinet).abs() < 1e-12);
        assert!(c.prior(desk, cabinet) > 0.28);
        decide_near_ties(&mut s, 3, &p);
        assert_eq!((s[0].class, s[0].near_tie), (Some(desk), true));
    }

    /// Ties by size: at `large_tie_gaussians` a split is near within one standard deviation
    /// of a fair coin's difference (9 : 7 over 16 votes, within 4), below it within one
    /// view; 11 : 5 is clear at any size.
    #[test]
    fn a_large_segment_is_near_within_a_coin_flips_spread() {
        let p = ConsensusParams::default();
        let near = |split: &[f64], gaussians: usize| {
            let mut s = segment(split, None);
            s.gaussians = gaussians;
            tied_classes(&s, &p).len() > 1
        };
        let large = p.large_tie_gaussians;
        assert!(near(&[9.0, 7.0], large) && near(&[10.0, 6.0], large));
        assert!(!near(&[11.0, 5.0], large) && !near(&[9.0, 7.0], large - 1));
        assert!(near(&[9.0, 8.0], large - 1) && !near(&[9.0, 7.9], large - 1));
    }
}
