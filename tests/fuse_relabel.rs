//! `segment-consensus --relabel`: every view's label regions relabeled with the consensus
//! classes, then FlashSplat on the relabeled views (issue 16).
#![allow(clippy::needless_range_loop)] // index loops mirror the plain transcription

mod common;

use common::consensus::{input, noisy_maps};
use common::regions::{flood_regions, on_edge};
use common::{check_validation, gpu};
use semsplat::dataset::CompactClasses;
use semsplat::fuse::consensus::{consensus_run, ConsensusRun, Kept};
use semsplat::fuse::consensus_confusion::ConfusionRates;
use semsplat::fuse::consensus_relabel::{
    edge_depth, fuse_relabeled_by, relabel_view, RelabelRule, RelabeledSums, RelabeledViews,
};
use semsplat::fuse::regions_gpu::{RegionFinder, MAX_GPU_REACH};
use semsplat::fuse::{
    accumulate, assign_semantic_near, lift_by_consensus, Assignment, ClassScores, ConsensusLift,
    ConsensusParams, FuseConfig, LabelSource, Method, NO_LABEL,
};
use semsplat::render::rasterizer::SplitSizes;
use semsplat::render::GpuScene;
use semsplat::synth::{generate, RoomSource, SynthConfig, SynthScene};
use semsplat::util::Rng;
use std::collections::BTreeMap;
use std::sync::Mutex;

/// A pixel's depth written plainly: the city-block distance to the nearest edge pixel of
/// its region, capped at `cap` (`cap` where the region has no edge).
fn depth_by_hand(regions: &[u32], w: usize, p: usize, cap: u32) -> u32 {
    let manhattan = |q: usize| ((p % w).abs_diff(q % w) + (p / w).abs_diff(q / w)) as u32;
    (0..regions.len())
        .filter(|&q| regions[q] == regions[p] && on_edge(regions, w, q))
        .map(manhattan)
        .fold(cap, u32::min)
}

/// The rule written plainly: per region, the seeds at least `rule.depth` inside it (its
/// deepest if none is); a class holding `rule.min_share` of them takes the region, unless
/// it is not the region's label and half or more of its seeds lie within `rule.near` of a
/// pixel labeled it (the view labels it beside the region); else, if
/// the region's own label holds `rule.keep_share` of them, and `rule.min_share` with the
/// seeds of other classes that lie within `rule.near` (city-block) of a pixel labeled their
/// class, it keeps its label; so it does if the seeds of classes whose rate of being taken
/// for its label exceeds `rule.max_edge_confusion` fall short of `1 - rule.min_share` of
/// them; else it is unlabeled. Regions without seeds keep their labels.
fn relabel_by_hand(
    map: &[u32],
    w: usize,
    seeds: &[(u32, u32)],
    rule: &RelabelRule,
    rates: &ConfusionRates,
) -> Vec<u32> {
    let regions = flood_regions(map, w);
    // Each region's edge pixels, listed once: a seed's depth is its distance to the
    // nearest (as `depth_by_hand` finds scanning every pixel).
    let mut edges: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for q in (0..map.len()).filter(|&q| regions[q] != NO_LABEL && on_edge(&regions, w, q)) {
        edges.entry(regions[q]).or_default().push(q);
    }
    let depth = |p: usize| {
        let manhattan = |q: &usize| ((p % w).abs_diff(q % w) + (p / w).abs_diff(q / w)) as u32;
        let edge = edges.get(&regions[p]).map_or(&[][..], Vec::as_slice);
        edge.iter().map(manhattan).fold(rule.depth, u32::min)
    };
    // (depth, class, pixel) of every seed on a labeled pixel, by region, in seed order.
    let mut in_region: BTreeMap<u32, Vec<(u32, u32, usize)>> = BTreeMap::new();
    for &(p, c) in seeds.iter().filter(|s| regions[s.0 as usize] != NO_LABEL) {
        let p = p as usize;
        in_region
            .entry(regions[p])
            .or_default()
            .push((depth(p), c, p));
    }
    let mut new_class: BTreeMap<u32, u32> = BTreeMap::new();
    for (&r, placed) in &in_region {
        let deepest = placed.iter().map(|s| s.0).max().expect("a seed");
        let counted: Vec<(u32, u32, usize)> =
            placed.iter().copied().filter(|s| s.0 == deepest).collect();
        new_class.insert(r, region_class_by_hand(map, w, &counted, rule, rates));
    }
    (0..map.len())
        .map(|p| *new_class.get(&regions[p]).unwrap_or(&map[p]))
        .collect()
}

/// The class a region of `map` takes by the rule, from its counted seeds (depth, class,
/// pixel): the deepest ones.
fn region_class_by_hand(
    map: &[u32],
    w: usize,
    counted: &[(u32, u32, usize)],
    rule: &RelabelRule,
    rates: &ConfusionRates,
) -> u32 {
    let votes = |c: u32| counted.iter().filter(|s| s.1 == c).count();
    let top = counted
        .iter()
        .map(|s| s.1)
        .max_by_key(|&c| votes(c))
        .unwrap();
    // The region's label: a seed's pixel's, as every pixel of the region has it.
    let own = map[counted[0].2];
    // Seeds of another class than `own` lying near a pixel of their class: the pixels in
    // the square of side 2 near + 1 around it, within `near` city-block.
    let near = |c: u32, p: usize| {
        let (h, reach) = (map.len() / w, rule.near as usize);
        let (x, y) = (p % w, p / w);
        let xs = x.saturating_sub(reach)..(x + reach + 1).min(w);
        let ys = y.saturating_sub(reach)..(y + reach + 1).min(h);
        ys.flat_map(|qy| xs.clone().map(move |qx| (qx, qy)))
            .any(|(qx, qy)| map[qy * w + qx] == c && x.abs_diff(qx) + y.abs_diff(qy) <= reach)
    };
    let near_seeds = counted
        .iter()
        .filter(|s| s.1 != own && near(s.1, s.2))
        .count();
    let holds = |n: usize, share: f64| n as f64 >= share * counted.len() as f64;
    let top_near = counted
        .iter()
        .filter(|s| s.1 == top && near(top, s.2))
        .count();
    let beside = top != own && top_near * 2 >= votes(top);
    let look_alikes = counted
        .iter()
        .filter(|s| s.1 != own && rates.rate(s.1 as usize, own as usize) > rule.max_edge_confusion)
        .count();
    let kept_by_own =
        holds(votes(own), rule.keep_share) && holds(votes(own) + near_seeds, rule.min_share);
    let kept_by_confusions = holds(counted.len() - look_alikes, rule.min_share);
    if holds(votes(top), rule.min_share) && !beside {
        top
    } else if kept_by_own || kept_by_confusions {
        own
    } else {
        NO_LABEL
    }
}

/// A rule with the given shares, depth and near radius, which keeps no region by the
/// scene's confusions (the footprint mass plays no part in relabeling).
fn rule(min_share: f64, depth: u32, keep_share: f64, near: u32) -> RelabelRule {
    RelabelRule {
        min_share,
        depth,
        keep_share,
        near,
        min_mass: 1.0,
        max_edge_confusion: 0.0,
    }
}

/// Rules over both shares, four depths, three near radii and two confusion thresholds
/// (against rates drawn uniformly: none or about half of the pairs rule flicker out); a
/// keep share above 1 never keeps a mixed region by its own seeds.
const RULES: [(f64, u32, f64, u32, f64); 7] = [
    (0.75, 1, 2.0, 8, 0.0),
    (0.6, 1, 0.25, 1, 0.0),
    (1.0, 1, 0.25, 3, 0.5),
    (0.75, 2, 2.0, 3, 0.5),
    (0.75, 3, 0.25, 3, 0.0),
    (0.75, 6, 0.4, 8, 0.5),
    (0.75, 3, 0.25, 8, 0.5),
];

/// A rule of [`RULES`].
fn rule_of(
    (min_share, depth, keep_share, near, max_edge_confusion): (f64, u32, f64, u32, f64),
) -> RelabelRule {
    RelabelRule {
        max_edge_confusion,
        ..rule(min_share, depth, keep_share, near)
    }
}

/// Rates at which the views take each of 4 classes for each other, drawn uniformly.
fn random_rates(rng: &mut Rng) -> ConfusionRates {
    ConfusionRates::from_rows(4, (0..16).map(|_| rng.f64()).collect())
}

/// A label map of rectangles of 4 classes over a background, some pixels unlabeled, and
/// seeds: mostly one class per region (often not its label), another class sometimes
/// (mixed regions), several on one pixel now and then.
fn random_case(seed: u64, w: usize, h: usize) -> (Vec<u32>, Vec<(u32, u32)>) {
    let mut rng = Rng::new(seed);
    let mut map = vec![0u32; w * h];
    for _ in 0..6 {
        let (x0, y0) = (rng.next_u32() as usize % w, rng.next_u32() as usize % h);
        let (rw, rh) = (
            1 + rng.next_u32() as usize % 9,
            1 + rng.next_u32() as usize % 7,
        );
        let class = rng.next_u32() % 4;
        for y in y0..(y0 + rh).min(h) {
            for x in x0..(x0 + rw).min(w) {
                map[y * w + x] = class;
            }
        }
    }
    for _ in 0..w * h / 20 {
        map[rng.next_u32() as usize % (w * h)] = NO_LABEL;
    }
    // Each region's "consensus" class: often not its label (flicker undone).
    let regions = flood_regions(&map, w);
    let consensus: Vec<u32> = (0..w * h).map(|_| rng.next_u32() % 4).collect();
    let mut seeds = Vec::new();
    for _ in 0..w * h / 4 {
        let p = rng.next_u32() % (w * h) as u32;
        if map[p as usize] == NO_LABEL {
            continue;
        }
        let class = match rng.next_u32() % 10 {
            0..=7 => consensus[regions[p as usize] as usize],
            _ => rng.next_u32() % 4,
        };
        seeds.push((p, class));
        if rng.next_u32().is_multiple_of(8) {
            seeds.push((p, rng.next_u32() % 4));
        }
    }
    (map, seeds)
}

#[test]
fn relabeling_matches_a_plain_transcription() {
    let (mut relabeled, mut unlabeled, mut kept, mut kept_by_near) = (0, 0, 0, 0);
    let (mut not_taken_beside, mut kept_by_confusions) = (0, 0);
    for seed in 0..40 {
        let (w, h) = (24, 18);
        let (map, seeds) = random_case(seed, w, h);
        let rates = random_rates(&mut Rng::new(seed + 1000));
        let regions = flood_regions(&map, w);
        let depth = edge_depth(&regions, w, 3);
        for p in (0..map.len()).filter(|&p| map[p] != NO_LABEL) {
            assert_eq!(
                depth[p],
                depth_by_hand(&regions, w, p, 3),
                "seed {seed}, pixel {p}"
            );
        }
        for rule in RULES.map(rule_of) {
            let mut got = map.clone();
            relabel_view(&mut got, w, seeds.iter().copied(), &rule, &rates);
            let want = relabel_by_hand(&map, w, &seeds, &rule, &rates);
            assert_eq!(got, want, "seed {seed}, {rule:?}");
            let by_hand = |rule: &RelabelRule| relabel_by_hand(&map, w, &seeds, rule, &rates);
            let never_kept = by_hand(&RelabelRule {
                keep_share: 2.0,
                max_edge_confusion: 0.0,
                ..rule
            });
            let no_confusions = by_hand(&RelabelRule {
                max_edge_confusion: 0.0,
                ..rule
            });
            // No seed of another class lies within 0 pixels of its class's label.
            let none_near = by_hand(&RelabelRule {
                near: 0,
                max_edge_confusion: 0.0,
                ..rule
            });
            for p in (0..map.len()).filter(|&p| map[p] != NO_LABEL) {
                relabeled += usize::from(want[p] != map[p] && want[p] != NO_LABEL);
                unlabeled += usize::from(want[p] == NO_LABEL);
                kept += usize::from(want[p] == map[p] && never_kept[p] == NO_LABEL);
                kept_by_near += usize::from(want[p] == map[p] && none_near[p] == NO_LABEL);
                kept_by_confusions +=
                    usize::from(want[p] == map[p] && no_confusions[p] == NO_LABEL);
                // With no seed near its class's label no class counts as labeled beside.
                let taken = |l: u32| l != map[p] && l != NO_LABEL;
                not_taken_beside += usize::from(taken(none_near[p]) && !taken(want[p]));
            }
        }
    }
    // The cases exercise every branch: regions relabeled, unlabeled, and mixed but kept,
    // some of them only through seeds near their class's label, some only because their
    // seeds' classes are not taken for their label, and regions not taken by a class
    // labeled beside them.
    assert!(
        relabeled > 1000
            && unlabeled > 1000
            && kept > 200
            && kept_by_near > 100
            && kept_by_confusions > 100
            && not_taken_beside > 100,
        "{relabeled} {unlabeled} {kept} {kept_by_near} {kept_by_confusions} {not_taken_beside}"
    );
}

/// The GPU's relabeling (regions, the seeds' depths and near flags found there, the pixels
/// rewritten there) against the same plain transcription, on maps of several sizes; a view
/// with more seeds than the finder holds Gaussians, or a depth or near radius past the GPU's
/// search, is relabeled on the host, to the same result.
#[test]
fn gpu_relabeling_matches_the_plain_transcription() {
    let gpu = gpu();
    let sizes = [(24, 18), (24, 18), (7, 31), (64, 48), (160, 120)];
    let most_seeds = 160 * 120 / 4 + 160 * 120 / 32;
    let mut finder = RegionFinder::new(gpu, most_seeds).unwrap();
    let mut relabeled = 0usize;
    for (seed, &(w, h)) in (100..).zip(sizes.iter().cycle().take(25)) {
        let (map, seeds) = random_case(seed, w, h);
        let rates = random_rates(&mut Rng::new(seed + 1000));
        for rule in RULES.map(rule_of) {
            let got = finder
                .relabel(&map, w as u32, &seeds, &rule, &rates)
                .unwrap();
            let want = relabel_by_hand(&map, w, &seeds, &rule, &rates);
            assert_eq!(got, want, "seed {seed} ({w}x{h}), {rule:?}");
            relabeled += (0..map.len()).filter(|&p| want[p] != map[p]).count();
        }
    }
    assert!(relabeled > 10_000, "{relabeled} pixels changed");
    assert_eq!(finder.stats.host_fallbacks, 0, "views left to the host");
    // Too many seeds for the finder: the host relabels the view.
    let (map, seeds) = random_case(7, 24, 18);
    let rates = random_rates(&mut Rng::new(7));
    let by_hand = |rule: &RelabelRule| relabel_by_hand(&map, 24, &seeds, rule, &rates);
    let mut small = RegionFinder::new(gpu, seeds.len() - 1).unwrap();
    let shallow = rule_of((0.75, 3, 0.25, 8, 0.5));
    let got = small.relabel(&map, 24, &seeds, &shallow, &rates).unwrap();
    assert_eq!(got, by_hand(&shallow));
    assert_eq!(small.stats.host_fallbacks, 1);
    // Deeper than region_depth searches: the host relabels the view.
    let deep = rule(0.75, MAX_GPU_REACH + 1, 0.25, 8);
    let got = finder.relabel(&map, 24, &seeds, &deep, &rates).unwrap();
    assert_eq!(got, by_hand(&deep));
    assert_eq!(finder.stats.host_fallbacks, 1);
    // A near radius past region_near's search: the host again.
    let far = rule(0.75, 3, 0.25, MAX_GPU_REACH + 1);
    let got = finder.relabel(&map, 24, &seeds, &far, &rates).unwrap();
    assert_eq!(got, by_hand(&far));
    assert_eq!(finder.stats.host_fallbacks, 2);
    check_validation(gpu);
}

/// A `w` x `h` map labeled 1 inside the rectangle `xs` x `ys`, 0 around it.
fn rectangle(
    w: usize,
    h: usize,
    xs: std::ops::Range<usize>,
    ys: std::ops::Range<usize>,
) -> Vec<u32> {
    (0..w * h)
        .map(|p| u32::from(xs.contains(&(p % w)) && ys.contains(&(p / w))))
        .collect()
}

/// `map` with pixel `p` labeled 2.
fn with_2_at(map: &[u32], p: usize) -> Vec<u32> {
    let mut labels = map.to_vec();
    labels[p] = 2;
    labels
}

/// `labels` with every pixel labeled 1 labeled `to`.
fn ones_to(labels: &[u32], to: u32) -> Vec<u32> {
    labels
        .iter()
        .map(|&l| if l == 1 { to } else { l })
        .collect()
}

/// At depth 1, edge seeds count only where a region has no interior seed; a split below
/// the share unlabels the region; a region without seeds keeps its label.
#[test]
fn a_region_takes_its_interior_seeds_class() {
    let w = 9;
    let mut map = vec![5u32; w];
    map[4] = 7; // regions 0..4 (class 5), 4 (class 7), 5..9 (class 5); 3, 4, 5 on edges
    let mut got = map.clone();
    let seeds = [(0, 2), (1, 2), (2, 2), (3, 6), (6, 4)];
    relabel_view(
        &mut got,
        w,
        seeds.into_iter(),
        &rule(0.75, 1, 2.0, 8),
        &ConfusionRates::unknown(),
    );
    assert_eq!(got, [2, 2, 2, 2, 7, 4, 4, 4, 4]);
    let mut got = map.clone();
    let seeds = [(0, 2), (1, 3), (5, 1), (4, 1)];
    relabel_view(
        &mut got,
        w,
        seeds.into_iter(),
        &rule(0.75, 1, 2.0, 8),
        &ConfusionRates::unknown(),
    );
    let x = NO_LABEL;
    assert_eq!(got, [x, x, x, x, 1, 1, 1, 1, 1]);
}

/// A label edge drawn two pixels off puts a neighbour's Gaussians (class 2) just inside a
/// region whose own Gaussians (class 1) lie deep in it: at depth 3 the deep ones decide
/// and the region keeps class 1; at depth 1 the region counts as mixed: unlabeled, unless
/// its own label holds the keep share and, with the class-2 seeds lying within the near
/// radius of a pixel labeled 2, the min share.
#[test]
fn deep_seeds_outvote_a_shifted_edge() {
    let (w, h) = (12, 9);
    let map = rectangle(w, h, 1..11, 1..8);
    // Region 1 spans x 1..=10, y 1..=7: (5, 4) is 3 deep, (4, 4) 3 deep, x = 2 one deep.
    let seeds = [
        (4 * w + 5, 1),
        (4 * w + 4, 1),
        (3 * w + 2, 2),
        (4 * w + 2, 2),
        (5 * w + 2, 2),
    ]
    .map(|(p, c)| (p as u32, c));
    let mut got = map.clone();
    relabel_view(
        &mut got,
        w,
        seeds.into_iter(),
        &rule(0.75, 3, 2.0, 8),
        &ConfusionRates::unknown(),
    );
    assert_eq!(got, map, "the deep seeds keep class 1");
    // At depth 1 the region is mixed, two of five seeds its own class 1, three class 2.
    // A pixel labeled 2 beside the region at (0, 4): 2 from the seed at (2, 4), 3 from
    // those at (2, 3) and (2, 5). Or far, at (11, 4): 9 from (2, 4), 10 from the others.
    let (beside, far) = (with_2_at(&map, 4 * w), with_2_at(&map, 4 * w + 11));
    let cases = [
        (&map, 0.4, 8, false, "no pixel labeled 2"),
        (&beside, 0.4, 3, true, "every class-2 seed near a 2"),
        (
            &beside,
            0.4,
            2,
            false,
            "one class-2 seed near: 3 of 5 under the min share",
        ),
        (&beside, 0.5, 3, false, "its own class under the keep share"),
        (&far, 0.4, 8, false, "class 2 too far"),
        (&far, 0.4, 9, false, "one class-2 seed within 9"),
        (&far, 0.4, 10, true, "every class-2 seed within 10"),
    ];
    for (labels, keep_share, near, kept, what) in cases {
        let mut got = labels.clone();
        let rule = rule(0.75, 1, keep_share, near);
        relabel_view(
            &mut got,
            w,
            seeds.into_iter(),
            &rule,
            &ConfusionRates::unknown(),
        );
        let want = if kept {
            labels.clone()
        } else {
            ones_to(labels, NO_LABEL)
        };
        assert_eq!(got, want, "{what}");
    }
}

/// A region labeled 1 whose Gaussians the consensus gave class 2 takes class 2 where no
/// pixel near them is labeled 2 (flicker: the view called the object 1); where the view
/// labels 2 right beside it (an edge the segmenter drew: a small object whose Gaussians
/// the consensus gave its neighbour's class) it is unlabeled, and keeps its label where
/// its own Gaussians hold the keep share.
#[test]
fn a_region_does_not_take_a_class_labeled_beside_it() {
    let (w, h) = (12, 9);
    // Region 1 spans x 3..=8, y 2..=6 over a background of 0.
    let map = rectangle(w, h, 3..9, 2..7);
    // Four seeds of class 2 at depth 2 (x 5..=6, y 4: 2 from the region's edge).
    let twos = [(4 * w + 5) as u32, (4 * w + 6) as u32];
    let seeds = [(twos[0], 2), (twos[1], 2), (twos[0], 2), (twos[1], 2)];
    // A 2 at (2, 4), just left of the region: 3 and 4 from the seeds; or at (11, 0): far.
    let (beside, far) = (with_2_at(&map, 4 * w + 2), with_2_at(&map, 11));
    let relabeled = |labels: &[u32], rule: &RelabelRule, seeds: &[(u32, u32)]| {
        let mut got = labels.to_vec();
        relabel_view(
            &mut got,
            w,
            seeds.iter().copied(),
            rule,
            &ConfusionRates::unknown(),
        );
        got
    };
    let rule8 = rule(0.75, 2, 0.25, 8);
    assert_eq!(
        relabeled(&far, &rule8, &seeds),
        ones_to(&far, 2),
        "no 2 near"
    );
    assert_eq!(
        relabeled(&map, &rule8, &seeds),
        ones_to(&map, 2),
        "no 2 at all"
    );
    assert_eq!(
        relabeled(&beside, &rule8, &seeds),
        ones_to(&beside, NO_LABEL),
        "a 2 beside"
    );
    // Within 3 of one seed pixel of two: half the class's seeds near still counts.
    let rule3 = rule(0.75, 2, 0.25, 3);
    assert_eq!(
        relabeled(&beside, &rule3, &seeds),
        ones_to(&beside, NO_LABEL)
    );
    // Within 2 of none: taken.
    let rule2 = rule(0.75, 2, 0.25, 2);
    assert_eq!(relabeled(&beside, &rule2, &seeds), ones_to(&beside, 2));
    // One seed of its own among five, at the keep share of 0.2: kept.
    let mut five = seeds.to_vec();
    five.push((twos[0], 1));
    let keep_a_fifth = rule(0.75, 2, 0.2, 8);
    assert_eq!(relabeled(&beside, &keep_a_fifth, &five), beside);
}

/// A region labeled 1 holding only Gaussians of class 2, which the view labels right
/// beside it: undecided where the scene's views take class 2 for class 1 more often than
/// `max_edge_confusion` (a flickered object beside one of its own class), kept as 1 where
/// they do not (an edge drawn off: the label cannot be class 2's flicker); a threshold of 0
/// never keeps it, and neither does a threshold where a third of its seeds are class 3,
/// which the views take for 1 (under the `1 - min_share` a region may hold).
#[test]
fn a_region_keeps_a_label_its_gaussians_are_never_taken_for() {
    let (w, h) = (12, 9);
    let map = rectangle(w, h, 3..9, 2..7);
    let twos = [(4 * w + 5) as u32, (4 * w + 6) as u32];
    let mut seeds = vec![(twos[0], 2), (twos[1], 2), (twos[0], 2), (twos[1], 2)];
    let beside = with_2_at(&map, 4 * w + 2);
    // Rates [class][label] over classes 0..4: 2 is taken for 1 at `rate`, 3 for 1 at 0.2.
    let rates = |rate: f64| {
        let mut rows = vec![0.001; 16];
        (rows[2 * 4 + 1], rows[3 * 4 + 1]) = (rate, 0.2);
        ConfusionRates::from_rows(4, rows)
    };
    let relabeled = |seeds: &[(u32, u32)], max_edge_confusion: f64, rate: f64| {
        let rule = RelabelRule {
            max_edge_confusion,
            ..rule(0.75, 2, 0.25, 8)
        };
        let mut got = beside.clone();
        relabel_view(&mut got, w, seeds.iter().copied(), &rule, &rates(rate));
        got
    };
    let undecided = ones_to(&beside, NO_LABEL);
    assert_eq!(
        relabeled(&seeds, 0.03, 0.01),
        beside,
        "2 rarely taken for 1"
    );
    assert_eq!(relabeled(&seeds, 0.03, 0.1), undecided, "2 taken for 1");
    assert_eq!(relabeled(&seeds, 0.0, 0.01), undecided, "threshold 0");
    seeds.extend([(twos[0], 3); 2]); // two of six: 3 is taken for 1
    assert_eq!(
        relabeled(&seeds, 0.03, 0.01),
        undecided,
        "a look-alike's third"
    );
    seeds.extend([(twos[1], 2); 3]); // two of nine, under 1 - 0.75
    assert_eq!(
        relabeled(&seeds, 0.03, 0.01),
        beside,
        "a look-alike's two ninths"
    );
}

/// The office under flicker 0.3 at 96x72: its noisy maps in compact ids, the scene on the
/// GPU and its segment consensus.
struct Flickered {
    s: SynthScene,
    classes: usize,
    noisy: Vec<Option<Vec<u32>>>,
    scene: GpuScene,
    run: ConsensusRun,
}

fn flickered_office(views: usize, seed: u64) -> Flickered {
    noisy_office(views, seed, "flicker=0.3")
}

/// [`flickered_office`] with other noise.
fn noisy_office(views: usize, seed: u64, noise: &str) -> Flickered {
    let mut cfg = SynthConfig::new(RoomSource::from_arg("office").unwrap());
    cfg.train_views = views;
    cfg.test_views = 0;
    (cfg.width, cfg.height) = (96, 72);
    cfg.seed = seed;
    cfg.noise = Some(noise.parse().unwrap());
    let s = generate(&cfg).unwrap();
    let compact = CompactClasses::from_table(&s.room.classes).unwrap();
    let noisy = noisy_maps(&s, &compact);
    let scene = GpuScene::upload(gpu(), &s.gaussians).unwrap();
    let run = consensus_run(
        &input(gpu(), &scene, &s, &noisy, compact.len()),
        &FuseConfig::default(),
        &ConsensusParams::default(),
        Kept::CenterPixels,
        &mut |_, _| {},
    )
    .unwrap();
    Flickered {
        s,
        classes: compact.len(),
        noisy,
        scene,
        run,
    }
}

/// Flicker relabels whole objects in a view; the consensus classes put most of them back:
/// the relabeled views disagree with the true labels on far fewer pixels than the noisy
/// views do. The GPU relabels every view as the host does, and with an undecided channel
/// the pixels the relabeling unlabeled (and only those) carry it. The default rule asks 85%
/// of a region's deciding centers, so about a fifth of the pixels are left undecided (18%
/// at 75%, before the undecided pixels counted for the consensus).
#[test]
fn relabeled_views_undo_most_flicker() {
    let Flickered { s, noisy, run, .. } = flickered_office(24, 7);
    let classes = CompactClasses::from_table(&s.room.classes).unwrap();
    let params = ConsensusParams::default();
    let relabeled = |finder, undecided| RelabeledViews {
        inner: &noisy,
        centers: &run.centers,
        class: &run.consensus.assignment.class,
        rule: params.relabel,
        confusions: &run.consensus.confusions,
        finder,
        undecided,
    };
    let finder = || {
        Some(Mutex::new(
            RegionFinder::new(gpu(), s.gaussians.len()).unwrap(),
        ))
    };
    let channel = classes.len() as u32;
    let on_gpu = relabeled(finder(), None);
    let with_channel = [
        relabeled(None, Some(channel)),
        relabeled(finder(), Some(channel)),
    ];
    let relabeled = relabeled(None, None);
    let (mut noisy_wrong, mut relabeled_wrong, mut unlabeled, mut labeled) = (0, 0, 0, 0);
    for (v, cam) in s.cameras.iter().enumerate() {
        let truth = classes.compact_labels(&s.views[v].labels);
        let before = noisy[v].as_ref().unwrap();
        let after = relabeled.labels(v, cam).unwrap().unwrap();
        assert_eq!(on_gpu.labels(v, cam).unwrap().unwrap(), after, "view {v}");
        let undecided = |p: usize| before[p] != NO_LABEL && after[p] == NO_LABEL;
        let want: Vec<u32> = (0..after.len())
            .map(|p| if undecided(p) { channel } else { after[p] })
            .collect();
        for source in &with_channel {
            assert_eq!(source.labels(v, cam).unwrap().unwrap(), want, "view {v}");
        }
        for p in 0..truth.len() {
            if truth[p] == NO_LABEL || before[p] == NO_LABEL {
                continue;
            }
            labeled += 1;
            noisy_wrong += usize::from(before[p] != truth[p]);
            match after[p] {
                NO_LABEL => unlabeled += 1,
                c => relabeled_wrong += usize::from(c != truth[p]),
            }
        }
    }
    eprintln!(
        "of {labeled} pixels: noisy wrong {noisy_wrong}, relabeled wrong {relabeled_wrong}, \
         unlabeled {unlabeled}"
    );
    assert!(
        noisy_wrong * 10 > labeled,
        "flicker should relabel >10% of pixels"
    );
    assert!(
        relabeled_wrong * 8 < noisy_wrong,
        "relabeling left {relabeled_wrong} of {noisy_wrong} wrong pixels"
    );
    assert!(
        unlabeled * 4 < labeled,
        "{unlabeled} of {labeled} unlabeled"
    );
    check_validation(gpu());
}

/// Lifts the office by segment consensus with relabeling twice; asserts both lifts give the
/// same classes, confidences, evidence and consensus, the consensus of `f.run`.
fn lift_twice_alike(f: &Flickered, params: &ConsensusParams) -> ConsensusLift {
    let cfg = FuseConfig {
        method: Method::SegmentConsensusRelabel,
        ..Default::default()
    };
    let lift = || {
        lift_by_consensus(
            &input(gpu(), &f.scene, &f.s, &f.noisy, f.classes),
            &cfg,
            params,
            &mut |_, _| {},
        )
        .unwrap()
    };
    let (a, b) = (lift(), lift());
    assert_eq!(a.assignment, b.assignment);
    assert_eq!(a.evidence, b.evidence);
    assert_eq!(a.consensus, b.consensus);
    assert_eq!(&a.consensus, &f.run.consensus);
    a
}

/// Per view, the pixels `relabeled` left undecided (labeled before, unlabeled after) as
/// class 0 and every other pixel unlabeled.
fn undecided_pixel_maps(f: &Flickered, relabeled: &RelabeledViews) -> Vec<Option<Vec<u32>>> {
    let mut undecided_only: Vec<Option<Vec<u32>>> = Vec::new();
    for (v, cam) in f.s.cameras.iter().enumerate() {
        let before = f.noisy[v].as_ref().unwrap();
        let after = relabeled.labels(v, cam).unwrap().unwrap();
        let only = (0..after.len()).map(|p| match before[p] != NO_LABEL && after[p] == NO_LABEL {
            true => 0,
            false => NO_LABEL,
        });
        undecided_only.push(Some(only.collect()));
    }
    undecided_only
}

/// A plain accumulation (FlashSplat's footprints) of `labels` over the office's views.
fn footprint(f: &Flickered, labels: &dyn LabelSource, classes: usize) -> ClassScores {
    let fs = FuseConfig::default();
    accumulate(
        gpu(),
        &f.scene,
        &f.s.cameras,
        labels,
        classes,
        &fs,
        |_, _| {},
    )
    .unwrap()
    .0
}

/// The relabel rule's FlashSplat side, rebuilt from two plain accumulations.
struct RuleByHand {
    /// The relabeled views' footprints, each Gaussian's undecided mass added to its
    /// consensus class.
    footprints: ClassScores,
    /// FlashSplat's classes over `footprints`, neighbours breaking ties.
    by_pixels: Assignment,
    /// Gaussians that cover an undecided pixel.
    undecided_gaussians: usize,
    /// Gaussians whose class the undecided pixels change.
    folding_decides: usize,
}

/// Accumulates the relabeled views (undecided pixels unlabeled) and the maps of the
/// undecided pixels alone, and counts the latter for each Gaussian's consensus class `cons`.
fn rule_by_hand(
    f: &Flickered,
    relabeled: &dyn LabelSource,
    undecided_only: &dyn LabelSource,
    cons: &[Option<usize>],
    params: &ConsensusParams,
) -> RuleByHand {
    let mut footprints = footprint(f, relabeled, f.classes);
    let k = params.neighbours;
    // The consensus's graph (searched on the centers in space: ties between equally far
    // neighbours go by that numbering), in the scene's numbering.
    let knn = f.run.order.neighbours_to_scene(&f.run.knn, k);
    let unfolded = assign_semantic_near(&footprints, Some((&knn, k)));
    let undecided_mass = footprint(f, undecided_only, 1);
    let mut undecided_gaussians = 0;
    for g in 0..footprints.n {
        if let Some(c) = cons[g] {
            footprints.data[c * footprints.n + g] += undecided_mass.get(0, g);
            undecided_gaussians += usize::from(undecided_mass.get(0, g) > 0.0);
        }
    }
    let by_pixels = assign_semantic_near(&footprints, Some((&knn, k)));
    let folding_decides = (0..footprints.n)
        .filter(|&g| by_pixels.class[g] != unfolded.class[g])
        .count();
    RuleByHand {
        footprints,
        by_pixels,
        undecided_gaussians,
        folding_decides,
    }
}

/// Each of the lift's classes is FlashSplat's where the Gaussian's footprint reaches
/// `min_mass`, else its consensus class; both happen to many Gaussians. Its evidence is
/// the footprints' where FlashSplat decided, else the consensus counts.
fn check_classes_follow_the_rule(
    lift: &ConsensusLift,
    rule: &RuleByHand,
    cons: &[Option<usize>],
    classes: usize,
    params: &ConsensusParams,
) {
    let RuleByHand {
        footprints,
        by_pixels,
        ..
    } = rule;
    let (mut moved, mut kept) = (0, 0);
    for g in 0..footprints.n {
        let mass: f64 = (0..classes).map(|c| footprints.get(c, g)).sum();
        let f = by_pixels.class[g];
        let want = match f.is_some() && mass >= params.relabel.min_mass {
            true => f,
            false => cons[g],
        };
        assert_eq!(lift.assignment.class[g], want, "Gaussian {g}");
        let evidence = match f.is_some() && mass >= params.relabel.min_mass {
            true => (0..classes).map(|c| footprints.get(c, g)).collect(),
            false => lift.consensus.evidence.dense(g),
        };
        assert_eq!(lift.evidence.dense(g), evidence, "Gaussian {g}'s evidence");
        if want != cons[g] {
            moved += 1;
        } else {
            kept += 1;
        }
    }
    assert!(moved > 100 && kept > 1000, "{moved} moved, {kept} kept");
}

/// The whole method twice gives the same classes, confidences and evidence; each class is
/// the one FlashSplat gives over the relabeled views where the Gaussian's footprint there
/// reaches `min_mass`, else the consensus class (the rule rebuilt here from its parts). The
/// pixels the relabeling left undecided count for each Gaussian's consensus class: rebuilt
/// from two plain accumulations, one over the relabeled views (undecided pixels unlabeled)
/// and one over maps of the undecided pixels alone. Seed 1: its relabeling leaves pixels
/// undecided, which seeds 2, 3 and 6 of this small office no longer do since the
/// clustering's ties go by segment size.
#[test]
fn relabel_is_deterministic_and_follows_its_rule() {
    let f = flickered_office(8, 1);
    let params = ConsensusParams::default();
    let a = lift_twice_alike(&f, &params);
    let cons = &f.run.consensus.assignment.class;
    let relabeled = RelabeledViews {
        inner: &f.noisy,
        centers: &f.run.centers,
        class: cons,
        rule: params.relabel,
        confusions: &f.run.consensus.confusions,
        // The lift relabeled on the GPU: the host's relabeling must give its classes.
        finder: None,
        undecided: None,
    };
    let undecided_only = undecided_pixel_maps(&f, &relabeled);
    let rule = rule_by_hand(&f, &relabeled, &undecided_only, cons, &params);
    check_classes_follow_the_rule(&a, &rule, cons, f.classes, &params);
    let (undecided_gaussians, folding_decides) = (rule.undecided_gaussians, rule.folding_decides);
    assert!(
        undecided_gaussians > 100 && folding_decides > 0,
        "{undecided_gaussians} Gaussians cover an undecided pixel, \
         {folding_decides} take another class for it"
    );
    check_validation(gpu());
}

/// `--relabel`'s sums from the footprints its observation pass keeps per label region are
/// FlashSplat's over the relabeled views, bit for bit: the same consensus (the walk's median
/// depth gives the observations the median depth's own kernel does), classes, confidences
/// and evidence as walking the relabeled views again, in both forms of the kernels (the CPU
/// drivers' and the GPUs'), and in the CPU drivers' with windows of 50 entries and a tile
/// row a dispatch, and with lists of 20,000 pairs (the views past it binned in bands of
/// tile rows, whose lists reuse one buffer: each walked again instead; a tile row holds up
/// to 10,562). `fuse --relabel` takes the footprints in the CPU drivers' form only.
#[test]
fn footprints_give_the_relabeled_views_sums() {
    let f = flickered_office(8, 1);
    // With holes in the label maps: the walk writes the depths of unlabeled pixels too.
    let holed = noisy_office(8, 1, "flicker=0.3,missing=0.2");
    let params = ConsensusParams::default();
    let windows = SplitSizes {
        window_len: Some(50),
        band_rows: Some(1),
        ..Default::default()
    };
    let lists = SplitSizes {
        list_capacity: Some(20_000),
        ..Default::default()
    };
    // The windows and banded lists only in the CPU drivers' form (a GPU walks a list in one
    // window; the other form would add time, not a path).
    let cases = [
        (&f, false, SplitSizes::default()),
        (&f, true, SplitSizes::default()),
        (&f, true, windows),
        (&f, true, lists),
        (&holed, true, SplitSizes::default()),
        (&holed, true, windows),
    ];
    for (f, cpu_forms, split) in cases {
        let gpu = common::gpu_with_cpu_forms(cpu_forms);
        let scene = GpuScene::upload(gpu, &f.s.gaussians).unwrap();
        let inp = input(gpu, &scene, &f.s, &f.noisy, f.classes);
        let cfg = FuseConfig {
            method: Method::SegmentConsensusRelabel,
            split,
            ..Default::default()
        };
        let lift = |sums| fuse_relabeled_by(&inp, &cfg, &params, sums, &mut |_, _| {});
        let kept = lift(RelabeledSums::FromFootprints).unwrap();
        let again = lift(RelabeledSums::WalkAgain).unwrap();
        let holes = std::ptr::eq(f, &holed);
        let case = format!("holes {holes}, cpu forms {cpu_forms}, {split:?}");
        let (walked_again, banded) = (kept.stats.walked_again, split.list_capacity.is_some());
        assert!(
            banded == (walked_again > 0),
            "{case}: {walked_again} walked again"
        );
        assert_eq!(again.stats.walked_again, 0, "{case}");
        assert!(
            kept.assignment == again.assignment,
            "{case}: classes differ"
        );
        assert!(kept.evidence == again.evidence, "{case}: evidence differs");
        // The walk's median and opaque depths are the median depth kernel's, of unlabeled
        // pixels too (the visibility test reads a center's 3x3 pixels): the same
        // observations.
        assert!(
            kept.consensus == again.consensus,
            "{case}: the consensus differs"
        );
        if split.list_capacity.is_none() && split.window_len.is_none() {
            // `fuse --relabel` keeps footprints where the device takes the CPU forms, and on
            // a GPU walks the relabeled views again (reading the sums back costs more there).
            let chosen = lift_by_consensus(&inp, &cfg, &params, &mut |_, _| {}).unwrap();
            let walked_once = (chosen.stats.kernels.iter())
                .any(|k| k.kernel.starts_with("fuse/region_footprint"));
            assert_eq!(walked_once, cpu_forms, "{case}: the footprints' walk");
            assert!(
                chosen.evidence == again.evidence,
                "{case}: evidence differs"
            );
        }
        check_validation(gpu);
    }
}

/// `fuse --report` of a room whose plant `synth` labeled lamp in 11 of its 19 views: the
/// flagged segment on the plant names, under lamp, the views `synth` records as mislabeled,
/// and under plant only others; its bounds hold its center.
#[test]
fn fuse_report_names_the_views_of_a_consistently_mislabeled_object() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let p = |f: &str| common::cli::arg_in(d, f);
    let words = |line: &str| {
        line.split_whitespace()
            .map(String::from)
            .collect::<Vec<_>>()
    };
    let mut synth = words("synth --preset office --views 40 --test-views 0 --width 96");
    synth.extend(words(
        "--height 72 --seed 5 --noise consistent=0.6 --no-previews --out",
    ));
    synth.push(p(""));
    common::cli::ok(&synth.iter().map(String::as_str).collect::<Vec<_>>());
    let mut fuse = words("fuse --method segment-consensus");
    for (option, file) in [
        ("--scene", "scene.ply"),
        ("--cameras", "cameras.json"),
        ("--labels", "labels_noisy"),
        ("--classes", "classes.json"),
        ("--out", "fused.ply"),
        ("--report", "report.json"),
    ] {
        fuse.extend([option.to_string(), p(file)]);
    }
    let said = common::cli::ok(&fuse.iter().map(String::as_str).collect::<Vec<_>>());
    // The summary says a segment was flagged and where the report lists it.
    assert!(
        said.contains("1 segment(s) flagged") && said.contains("report.json"),
        "{said}"
    );
    let noise = common::cli::read_json(&d.join("labels_noisy/noise.json"));
    let planted = &noise["consistent"][0];
    let report = common::cli::read_json(&d.join("report.json"));
    let flagged = report["segments"]["flagged"].as_array().unwrap();
    let views_of = |f: &serde_json::Value, class: &serde_json::Value| {
        let listed = f["views_by_class"].as_array().unwrap().iter();
        let mut found = listed.filter(|e| e[0] == *class);
        found.next().map(|e| e[1].clone()).unwrap_or_default()
    };
    let on_plant: Vec<_> = flagged
        .iter()
        .filter(|f| views_of(f, &planted["wrong_class_name"]) == planted["wrong_views"])
        .collect();
    assert_eq!(
        on_plant.len(),
        1,
        "{flagged:?}; mislabeled in {}",
        planted["wrong_views"]
    );
    let right = views_of(on_plant[0], &planted["true_class_name"]);
    let wrong = planted["wrong_views"].as_array().unwrap();
    assert!(!right.as_array().unwrap().is_empty());
    assert!(
        right.as_array().unwrap().iter().all(|v| !wrong.contains(v)),
        "{right}"
    );
    let (center, bounds) = (&on_plant[0]["center"], &on_plant[0]["bounds"]);
    for a in 0..3 {
        let at = |v: &serde_json::Value| v.as_f64().unwrap();
        assert!(at(&bounds[0][a]) <= at(&center[a]) && at(&center[a]) <= at(&bounds[1][a]));
    }
}

/// `fuse --method segment-consensus [--relabel]` writes each Gaussian's entropy and segment
/// beside its class, and the segments' vote splits in the report; the consensus methods
/// refuse --shard (segments need every view at once).
#[test]
fn fuse_cli_writes_entropy_segments_and_the_segment_report() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    common::cli::synth_tiny(d, 6, (64, 48));
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    for (extra, name) in [
        (vec![], "segment-consensus"),
        (vec!["--relabel"], "segment-consensus --relabel"),
    ] {
        let mut args = vec!["--method", "segment-consensus", "--out", "", "--report", ""];
        let (out, report) = (p(&format!("{}.ply", extra.len())), p("report.json"));
        (args[3], args[5]) = (out.as_str(), report.as_str());
        args.extend(extra);
        common::cli::fuse_synth(d, &args);
        let g = semsplat::scene::ply::read_ply(std::path::Path::new(&out)).unwrap();
        let classes = g.class_ids.as_ref().unwrap();
        let conf = g.class_conf.as_ref().unwrap();
        let entropy = g.class_entropy.as_ref().expect("class_entropy");
        let segment = g.segment_ids.as_ref().expect("segment");
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
        assert_eq!(report["method"], name);
        // Segment consensus counts views on the host: no accumulation to name.
        let accumulation = (name != "segment-consensus").then_some("fixed_point");
        assert_eq!(report["accumulation"].as_str(), accumulation, "{name}");
        // Their memory is measured, as the other methods' is (it read 0).
        let stats = &report["stats"];
        for field in ["scene_device_bytes", "peak_host_bytes"] {
            let bytes = stats[field].as_u64().unwrap();
            assert!(bytes > 0, "{name}: {field} {bytes}");
        }
        let table_len = report["classes"].as_u64().unwrap() as f32;
        for i in 0..g.len() {
            assert!((0.0..=1.0).contains(&conf[i]), "{name}: conf {}", conf[i]);
            assert!(
                entropy[i] >= 0.0 && entropy[i] <= table_len.ln() + 1e-5,
                "{name}: entropy {}",
                entropy[i]
            );
            assert!(segment[i] >= 0, "{name}: every Gaussian has a segment");
            // Undecided Gaussians are -1 with confidence 0 and the entropy of no evidence.
            if classes[i] == -1 {
                assert_eq!(conf[i], 0.0);
            }
        }
        let segments = &report["segments"];
        let per_class = segments["per_class"].as_array().unwrap();
        assert!(segments["segments"].as_u64().unwrap() > 0, "{segments}");
        assert!(!per_class.is_empty() && segments["flagged"].is_array());
        for flagged in segments["flagged"].as_array().unwrap() {
            assert!(flagged["near_tie"].is_boolean(), "{flagged}");
        }
        // A class's segments vote for it more than for anything else on true labels.
        for c in per_class {
            assert_eq!(c["votes"][0][0], c["class"], "{c}");
        }
    }
    let err = common::cli::fuse_synth_fails(
        d,
        &[
            "--method",
            "segment-consensus",
            "--shard",
            "0/2",
            "--out",
            &p("part.npy"),
        ],
    );
    assert!(err.contains("cannot be split"), "{err}");
    assert!(!d.join("part.npy").exists());
    let err = common::cli::fuse_synth_fails(
        d,
        &["--method", "flashsplat", "--relabel", "--out", &p("x.ply")],
    );
    assert!(
        err.contains("--relabel is a variant of --method segment-consensus"),
        "{err}"
    );
}
