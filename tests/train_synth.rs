//! Short training runs on a tiny synthetic room: joint optimization and --semantics-only.

mod common;

use semsplat::eval::benchmark::{synth_train_views, TrainLabels};
use semsplat::render::{GpuScene, Rasterizer, RenderOptions};
use semsplat::scene::classes::CompactClasses;
use semsplat::scene::synth::{generate, SynthConfig, SynthScene};
use semsplat::scene::{Gaussians, Split};
use semsplat::train::config::TrainConfig;
use semsplat::train::trainer::{classes_from_logits, with_initial_logits, Trainer};

fn tiny() -> SynthScene {
    let mut cfg = SynthConfig::preset("tiny");
    cfg.train_views = 12;
    cfg.test_views = 4;
    cfg.width = 96;
    cfg.height = 72;
    cfg.previews = false;
    generate(&cfg).unwrap()
}

/// Mean PSNR over the test views.
fn test_psnr(s: &SynthScene, g: &Gaussians) -> f64 {
    let gpu = common::gpu();
    let scene = GpuScene::upload(gpu, g).unwrap();
    let mut r = Rasterizer::new(gpu);
    let opts = RenderOptions {
        semantics: None,
        ..Default::default()
    };
    let mut total = 0.0;
    let mut count = 0;
    for (cam, view) in s.cameras.iter().zip(&s.views) {
        if cam.split != Split::Test {
            continue;
        }
        let f = r.render(&scene, cam, &opts).unwrap();
        let mse: f64 = f
            .rgb
            .iter()
            .zip(&view.rgb)
            .map(|(a, b)| {
                let d = a.clamp(0.0, 1.0) as f64 - *b as f64 / 255.0;
                d * d
            })
            .sum::<f64>()
            / f.rgb.len() as f64;
        total += -10.0 * mse.log10();
        count += 1;
    }
    total / count as f64
}

fn accuracy(
    s: &SynthScene,
    classes: &[Option<u32>],
    truth: &[f32],
    compact: &CompactClasses,
) -> f64 {
    let ok = classes
        .iter()
        .zip(truth)
        .filter(|(c, t)| {
            c.and_then(|c| compact.user_of(c as usize))
                .map(|u| u as f32)
                == Some(**t)
        })
        .count();
    let _ = s;
    ok as f64 / classes.len() as f64
}

#[test]
fn joint_training_improves_psnr_and_semantics() {
    let gpu = common::gpu();
    let s = tiny();
    let compact = CompactClasses::from_table(&s.room.classes).unwrap();
    let views = synth_train_views(&s, TrainLabels::True, &compact).unwrap();
    let iters: u32 = std::env::var("ITERS")
        .map(|v| v.parse().unwrap())
        .unwrap_or(300);
    let init = with_initial_logits(&s.init_points, compact.len(), 1);
    println!("init {} Gaussians, scene {}", init.len(), s.gaussians.len());
    let psnr0 = test_psnr(&s, &init);
    let cfg = TrainConfig::new(iters);
    let t0 = std::time::Instant::now();
    let mut trainer = Trainer::new(gpu, &init, &views, cfg, &[]).unwrap();
    for _ in 0..iters {
        if let Some(l) = trainer.step().unwrap() {
            if trainer.iteration() % 50 == 0 {
                println!(
                    "it {} n {} l1 {:.4} ssim {:.3} ce {:.3} ent {:.3} psnr {:.2}",
                    trainer.iteration(),
                    trainer.gaussian_count(),
                    l.l1,
                    l.ssim,
                    l.ce,
                    l.entropy,
                    l.psnr()
                );
            }
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    let out = trainer.finish().unwrap();
    println!(
        "times {:?} in {secs:.1}s, events {:?}",
        out.times, out.densify_events
    );
    let psnr1 = test_psnr(&s, &out.gaussians);
    println!("psnr {psnr0:.2} -> {psnr1:.2}");
    common::check_validation(gpu);
}

#[test]
fn semantics_only_matches_fusion() {
    let gpu = common::gpu();
    let s = tiny();
    let compact = CompactClasses::from_table(&s.room.classes).unwrap();
    let views = synth_train_views(&s, TrainLabels::True, &compact).unwrap();
    let iters: u32 = std::env::var("ITERS")
        .map(|v| v.parse().unwrap())
        .unwrap_or(300);
    let init = with_initial_logits(&s.gaussians, compact.len(), 1);
    let truth: Vec<f32> = s
        .gaussians
        .class_ids
        .as_ref()
        .unwrap()
        .iter()
        .map(|&c| c as f32)
        .collect();
    let cfg = TrainConfig::semantics_only(iters);
    let t0 = std::time::Instant::now();
    let mut trainer = Trainer::new(gpu, &init, &views, cfg, &[truth.clone()]).unwrap();
    for _ in 0..iters {
        if let Some(l) = trainer.step().unwrap() {
            if trainer.iteration() % 50 == 0 {
                println!(
                    "it {} ce {:.3} ent {:.3}",
                    trainer.iteration(),
                    l.ce,
                    l.entropy
                );
            }
        }
    }
    let secs = t0.elapsed().as_secs_f64();
    let out = trainer.finish().unwrap();
    let (classes, _) = classes_from_logits(&out.gaussians, &out.seen);
    println!("times {:?} in {secs:.1}s", out.times);
    let seen_acc = {
        let idx: Vec<usize> = (0..classes.len()).filter(|&i| out.seen[i]).collect();
        idx.iter()
            .filter(|&&i| {
                classes[i]
                    .and_then(|c| compact.user_of(c as usize))
                    .map(|u| u as f32)
                    == Some(truth[i])
            })
            .count() as f64
            / idx.len() as f64
    };
    println!(
        "acc all {:.4} seen {:.4}",
        accuracy(&s, &classes, &truth, &compact),
        seen_acc
    );
    common::check_validation(gpu);
}
