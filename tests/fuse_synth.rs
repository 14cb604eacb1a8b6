//! Fusion on the procedural office with exact per-Gaussian truth (issue #5): every method's
//! accuracy on true and on flickering labels over the Gaussians that contribute to some
//! pixel, printed for the record. Asserted: FlashSplat >= 0.98 on true labels (the issue's
//! target), the per-view variant's gain under flicker, and regression floors for the rest.
//! Not asserted, because it does not hold: FlashSplat at least as accurate as vote under
//! flicker (README, Fusion).

mod common;

use common::{check_validation, gpu};
use semsplat::dataset::CompactClasses;
use semsplat::fuse::{accumulate, assign_semantic, ClassScores, FuseConfig, Method};
use semsplat::gpu::Gpu;
use semsplat::render::GpuScene;
use semsplat::synth::{generate, SynthConfig, SynthScene};

/// `synth --preset office --noise flicker=0.2` at its defaults (24 views at 640x480), without
/// held-out views: the scene stands in for a 3DGS trained on the labeled views.
fn office() -> SynthScene {
    let mut cfg = SynthConfig::preset("office");
    cfg.test_views = 0;
    cfg.noise = Some("flicker=0.2".parse().unwrap());
    generate(&cfg).unwrap()
}

fn compact_maps(maps: &[&[u16]], classes: &CompactClasses) -> Vec<Option<Vec<u32>>> {
    maps.iter()
        .map(|m| Some(classes.compact_labels(m)))
        .collect()
}

/// Accuracy over the Gaussians in `mask`, against the true classes.
fn accuracy(pred: &[Option<usize>], truth: &[i32], classes: &CompactClasses, mask: &[bool]) -> f64 {
    let (mut right, mut total) = (0usize, 0usize);
    for ((p, &t), &m) in pred.iter().zip(truth).zip(mask) {
        if m {
            total += 1;
            right += usize::from(p.and_then(|c| classes.user_of(c)) == Some(t as u32));
        }
    }
    right as f64 / total as f64
}

/// Vote's expected accuracy if its ties were broken at random: `assign_semantic` gives a
/// tie to the lower class index, which in the presets is floor, wall or ceiling, the
/// commonest classes, so tied Gaussians there are right more often than chance.
fn fair_tie_accuracy(
    votes: &ClassScores,
    truth: &[i32],
    classes: &CompactClasses,
    mask: &[bool],
) -> f64 {
    let (mut right, mut total) = (0.0, 0usize);
    for g in (0..votes.n).filter(|&g| mask[g]) {
        total += 1;
        let top = (0..votes.classes)
            .map(|e| votes.get(e, g))
            .fold(0.0, f64::max);
        if top > 0.0 {
            let tied: Vec<usize> = (0..votes.classes)
                .filter(|&e| votes.get(e, g) == top)
                .collect();
            if tied
                .iter()
                .any(|&e| classes.user_of(e) == Some(truth[g] as u32))
            {
                right += 1.0 / tied.len() as f64;
            }
        }
    }
    right / total as f64
}

/// Every fusion method, in the order the assertions index them (3: FlashSplat, 4: its
/// per-view variant).
const METHODS: [Method; 5] = [
    Method::Vote,
    Method::VoteOcclusion,
    Method::VoteWeighted,
    Method::FlashSplat,
    Method::FlashSplatPerView,
];

/// Each of `METHODS`' evidence on the true labels and on the flickering labels of `s`.
fn fuse_every_method(
    gpu: &Gpu,
    s: &SynthScene,
    scene: &GpuScene,
    classes: &CompactClasses,
) -> Vec<(ClassScores, ClassScores)> {
    let clean = compact_maps(
        &s.views.iter().map(|v| &v.labels[..]).collect::<Vec<_>>(),
        classes,
    );
    let noisy_maps = &s.noisy.as_ref().unwrap().maps;
    let noisy = compact_maps(
        &noisy_maps.iter().map(|m| &m[..]).collect::<Vec<_>>(),
        classes,
    );
    let fuse = |maps: &Vec<Option<Vec<u32>>>, method| {
        let cfg = FuseConfig {
            method,
            ..Default::default()
        };
        accumulate(gpu, scene, &s.cameras, maps, classes.len(), &cfg, |_, _| {})
            .unwrap()
            .0
    };
    METHODS
        .iter()
        .map(|&m| (fuse(&clean, m), fuse(&noisy, m)))
        .collect()
}

/// The Gaussians that contribute to some pixel of some view (the population), read
/// from FlashSplat's evidence `a`; asserts that nearly every Gaussian of the scene is one.
fn contributing_gaussians(a: &ClassScores, views: usize) -> Vec<bool> {
    let contributes: Vec<bool> = (0..a.n)
        .map(|g| (0..a.classes).any(|e| a.get(e, g) > 0.0))
        .collect();
    let seen = contributes.iter().filter(|&&c| c).count();
    assert!(
        seen > a.n * 9 / 10,
        "nearly every Gaussian of the scene is seen ({seen} of {})",
        a.n
    );
    eprintln!(
        "office: {} Gaussians, {seen} contribute to some pixel of {views} views",
        a.n
    );
    contributes
}

/// Each method's accuracy over the contributing Gaussians, on true labels and under
/// flicker (by `METHODS`), printed with vote's fair-tie expectation for the record.
fn accuracies_of_every_method(
    evidence: &[(ClassScores, ClassScores)],
    truth: &[i32],
    classes: &CompactClasses,
    contributes: &[bool],
) -> (Vec<f64>, Vec<f64>) {
    let acc = |e: &ClassScores| accuracy(&assign_semantic(e).class, truth, classes, contributes);
    let mut clean_acc = Vec::new();
    let mut noisy_acc = Vec::new();
    for (method, (c, n)) in METHODS.iter().zip(evidence) {
        clean_acc.push(acc(c));
        noisy_acc.push(acc(n));
        eprintln!(
            "{:<22} true labels {:.4}   flicker=0.2 {:.4}",
            method.name(),
            clean_acc.last().unwrap(),
            noisy_acc.last().unwrap()
        );
    }
    let fair = |e: &ClassScores| fair_tie_accuracy(e, truth, classes, contributes);
    eprintln!(
        "vote with ties broken at random (expected): true labels {:.4}   flicker=0.2 {:.4}",
        fair(&evidence[0].0),
        fair(&evidence[0].1)
    );
    (clean_acc, noisy_acc)
}

/// FlashSplat's targets: the accuracy on true labels, and the per-view variant's
/// gain under flicker at little cost on true labels.
fn check_flashsplat_targets(clean_acc: &[f64], noisy_acc: &[f64]) {
    // The target on true labels.
    assert!(
        clean_acc[3] >= 0.98,
        "flashsplat on true labels: {:.4}",
        clean_acc[3]
    );
    // Per-view normalization is for flicker: it must help there and cost little on true labels.
    assert!(
        noisy_acc[4] > noisy_acc[3] + 0.005,
        "flashsplat --per-view under flicker {:.4}, plain {:.4}",
        noisy_acc[4],
        noisy_acc[3]
    );
    assert!(
        clean_acc[4] >= clean_acc[3] - 0.005,
        "flashsplat --per-view on true labels {:.4}, plain {:.4}",
        clean_acc[4],
        clean_acc[3]
    );
}

/// Measured (seed 0): true labels 0.955-0.984, flicker 0.92-0.94 across methods. Floors
/// a little below, so a regression in any method fails; flicker must cost every method
/// accuracy, or the noisy labels are not reaching it.
fn check_regression_floors(clean_acc: &[f64], noisy_acc: &[f64]) {
    for (k, method) in METHODS.iter().enumerate() {
        assert!(
            clean_acc[k] >= 0.94,
            "{}: accuracy on true labels {:.4}",
            method.name(),
            clean_acc[k]
        );
        assert!(
            noisy_acc[k] >= 0.90,
            "{}: accuracy under flicker {:.4}",
            method.name(),
            noisy_acc[k]
        );
        assert!(
            noisy_acc[k] < clean_acc[k],
            "{}: flicker did not lower accuracy",
            method.name()
        );
    }
}

#[test]
fn office_accuracy_of_every_method_clean_and_under_flicker() {
    let gpu = gpu();
    let s = office();
    let truth = s.gaussians.class_ids.clone().unwrap();
    let classes = CompactClasses::from_ids(truth.iter().map(|&c| c as u32)).unwrap();
    let scene = GpuScene::upload(gpu, &s.gaussians).unwrap();
    let evidence = fuse_every_method(gpu, &s, &scene, &classes);
    let contributes = contributing_gaussians(&evidence[3].0, s.cameras.len());
    let (clean_acc, noisy_acc) =
        accuracies_of_every_method(&evidence, &truth, &classes, &contributes);
    check_flashsplat_targets(&clean_acc, &noisy_acc);
    check_regression_floors(&clean_acc, &noisy_acc);
    check_validation(gpu);
}
