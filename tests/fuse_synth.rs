//! Fusion on a procedural office with exact per-Gaussian truth: every method's accuracy on
//! true and on flickering labels, printed for the record, with regression floors set from
//! measurement. The targets (FlashSplat >= 0.98 on true labels, and no worse than
//! vote under flicker) are not met on this untrained synthetic scene: see README, Fusion.

mod common;

use common::{check_validation, gpu};
use semsplat::fuse::{accumulate, assign_semantic, FuseConfig, Method, NO_LABEL};
use semsplat::render::GpuScene;
use semsplat::scene::classes::CompactClasses;
use semsplat::scene::synth::{generate, SynthConfig, SynthScene};

fn office() -> SynthScene {
    let mut cfg = SynthConfig::preset("office");
    cfg.width = 400;
    cfg.height = 300;
    cfg.train_views = 12;
    cfg.test_views = 0;
    cfg.noise = Some("flicker=0.2".parse().unwrap());
    generate(&cfg).unwrap()
}

fn compact_maps(maps: &[&[u16]], classes: &CompactClasses) -> Vec<Option<Vec<u32>>> {
    maps.iter()
        .map(|m| {
            Some(
                m.iter()
                    .map(|&l| classes.compact_of(l as u32).map_or(NO_LABEL, u32::from))
                    .collect(),
            )
        })
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

#[test]
fn office_accuracy_of_every_method_clean_and_under_flicker() {
    let gpu = gpu();
    let s = office();
    let truth = s.gaussians.class_ids.clone().unwrap();
    let classes = CompactClasses::from_ids(truth.iter().map(|&c| c as u32)).unwrap();
    let scene = GpuScene::upload(gpu, &s.gaussians).unwrap();
    let clean = compact_maps(
        &s.views.iter().map(|v| &v.labels[..]).collect::<Vec<_>>(),
        &classes,
    );
    let noisy_maps = &s.noisy.as_ref().unwrap().maps;
    let noisy = compact_maps(
        &noisy_maps.iter().map(|m| &m[..]).collect::<Vec<_>>(),
        &classes,
    );
    let fuse = |maps: &Vec<Option<Vec<u32>>>, method| {
        let cfg = FuseConfig {
            method,
            ..Default::default()
        };
        accumulate(
            gpu,
            &scene,
            &s.cameras,
            maps,
            classes.len(),
            &cfg,
            |_, _| {},
        )
        .unwrap()
        .0
    };

    // The Gaussians that contribute to some pixel of some view (the population).
    let a = fuse(&clean, Method::FlashSplat);
    let contributes: Vec<bool> = (0..a.n)
        .map(|g| (0..a.classes).any(|e| a.get(e, g) > 0.0))
        .collect();
    let seen = contributes.iter().filter(|&&c| c).count();
    assert!(
        seen > a.n * 3 / 4,
        "most Gaussians are seen ({seen} of {})",
        a.n
    );
    eprintln!(
        "office: {} Gaussians, {seen} contribute to some pixel of {} views",
        a.n,
        s.cameras.len()
    );

    let mut results = Vec::new();
    for method in [
        Method::Vote,
        Method::VoteOcclusion,
        Method::VoteWeighted,
        Method::FlashSplat,
    ] {
        let acc_clean = accuracy(
            &assign_semantic(&fuse(&clean, method)).class,
            &truth,
            &classes,
            &contributes,
        );
        let acc_noisy = accuracy(
            &assign_semantic(&fuse(&noisy, method)).class,
            &truth,
            &classes,
            &contributes,
        );
        eprintln!("{method:?}: accuracy clean {acc_clean:.4}, flicker=0.2 {acc_noisy:.4}");
        results.push((method, acc_clean, acc_noisy));
    }
    // Measured at this size (seed 0): clean 0.90-0.94, flicker 0.82-0.84 across methods.
    // Floors a little below, so a regression in any method fails; flicker must cost every
    // method accuracy, or the noisy labels are not reaching it.
    for (method, acc_clean, acc_noisy) in results {
        assert!(
            acc_clean >= 0.88,
            "{method:?}: clean accuracy {acc_clean:.4}"
        );
        assert!(
            acc_noisy >= 0.78,
            "{method:?}: accuracy under flicker {acc_noisy:.4}"
        );
        assert!(
            acc_noisy < acc_clean,
            "{method:?}: flicker did not lower accuracy"
        );
    }
    check_validation(gpu);
}
