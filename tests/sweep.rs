//! `semsplat sweep` end to end on the tiny room (consistent mislabeling; several seeds; other
//! noise beside the swept kind), and the instance-oracle bound against a direct computation.
#![allow(clippy::needless_range_loop)] // index loops mirror the plain transcription

use std::collections::BTreeMap;
use std::path::Path;

mod common;

use common::cli::{fails, ok, read_json};
use semsplat::experiment::{instance_oracle_classes, ORACLE_NAME};
use semsplat::scene::labels::LabelMap;
use semsplat::scene::Split;
use semsplat::synth::{generate, RoomSource, SynthConfig, SynthScene};

#[test]
fn sweep_charts_every_method_and_reports_how_mislabels_are_followed() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    let report = sweep(
        &[
            "--noise",
            "consistent",
            "--levels",
            "0,1",
            "--preset",
            "tiny",
            "--views",
            "6",
            "--test-views",
            "2",
            "--width",
            "96",
            "--height",
            "72",
            "--semantics-only-iters",
            "25",
            "--joint-iters",
            "25",
        ],
        out,
    );
    let chart = image::open(out.join("robustness_consistent.png")).unwrap();
    assert_eq!(
        (chart.width(), chart.height()),
        semsplat::eval::chart::CHART_SIZE
    );
    let levels = report["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 2);
    // 9 methods and the oracle.
    assert_eq!(levels[0]["methods"].as_array().unwrap().len(), 10);
    assert_eq!(report["breaks_at"].as_array().unwrap().len(), 10);
    let runs = report["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 1);
    let run_levels = runs[0]["levels"].as_array().unwrap();
    // With the object wrong in every train view, every method follows the majority: most of
    // its Gaussians take the wrong class (Gaussian Semantics' stated limitation).
    for (method, follows) in run_levels[1]["mislabeled"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (&m[0], &m[1]))
    {
        let f = &follows.as_array().unwrap()[0];
        assert_eq!(f["wrong_view_rate"].as_f64().unwrap(), 1.0, "{method}");
        assert!(f["assigned_wrong"].as_f64().unwrap() > 0.5, "{method}: {f}");
        // Only segment consensus flags segments: whether it flagged the object, and how many
        // other segments it flagged.
        let has_flags = method
            .as_str()
            .is_some_and(|m| m.starts_with("segment-consensus"));
        let flags = (f["flagged"].is_boolean(), f["false_flags"].is_u64());
        assert_eq!(flags, (has_flags, has_flags), "{method}: {f}");
        // The views a flag names are counted only where a flagged segment lies on the
        // object (here none: every view agrees on the wrong class).
        let named = (
            f["wrong_views_named"].is_u64(),
            f["other_views_named"].is_u64(),
        );
        let on_object = f["flagged"] == true;
        assert_eq!(named, (on_object, on_object), "{method}: {f}");
    }
}

/// Two seeds of flicker with plain vote: per run figures, and per level the mean, min and max
/// over the runs equal to those of the per-run figures; the oracle and clean references.
#[test]
fn sweep_over_seeds_reports_spread_oracle_and_named_classes() {
    let report = tiny_vote_sweep(&["--noise", "flicker", "--levels", "0,0.5", "--seeds", "1,2"]);
    let runs = report["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!(report["seeds"], serde_json::json!([1, 2]));
    assert_eq!(report["presets"], serde_json::json!(["tiny"]));
    for (l, level) in report["levels"].as_array().unwrap().iter().enumerate() {
        let methods = level["methods"].as_array().unwrap();
        assert_eq!(methods.len(), 2, "vote and the oracle");
        assert_eq!(methods[1]["method"], ORACLE_NAME);
        // Each under the name --methods takes too.
        assert_eq!(
            (&methods[0]["key"], &methods[1]["key"]),
            (&"vote".into(), &"oracle".into())
        );
        for (k, m) in methods.iter().enumerate() {
            for metric in ["miou", "gaussian_accuracy"] {
                let per_run: Vec<f64> = runs
                    .iter()
                    .map(|r| {
                        let lv = &r["levels"][l];
                        let fig = if k == 0 {
                            &lv["methods"][0]
                        } else {
                            &lv["oracle"]
                        };
                        fig[metric].as_f64().unwrap()
                    })
                    .collect();
                let mean = (per_run[0] + per_run[1]) / 2.0;
                let s = &m[metric];
                assert!((s["mean"].as_f64().unwrap() - mean).abs() < 1e-12, "{m}");
                assert_eq!(s["min"].as_f64().unwrap(), per_run[0].min(per_run[1]));
                assert_eq!(s["max"].as_f64().unwrap(), per_run[0].max(per_run[1]));
            }
        }
    }
    let clean = &report["clean_reference"];
    assert_eq!(clean["method"], report["levels"][0]["methods"][0]["method"]);
    assert_eq!(
        clean["miou"],
        report["levels"][0]["methods"][0]["miou"]["mean"]
    );
    // Per-class IoU carries the room's class names.
    let per_class = runs[0]["levels"][0]["methods"][0]["per_class"]
        .as_array()
        .unwrap();
    assert!(!per_class.is_empty());
    assert!(
        per_class.iter().all(|c| c["name"].is_string()),
        "{per_class:?}"
    );
}

/// `semsplat sweep --noise KIND ...` (`args`, which start so) writing into `out`: its JSON
/// report.
fn sweep(args: &[&str], out: &Path) -> serde_json::Value {
    let out_arg = out.to_str().unwrap();
    ok(&[&["sweep"], args, &["--out", out_arg]].concat());
    read_json(&out.join(format!("robustness_{}.json", args[1])))
}

/// [`sweep`] on the tiny room with vote alone, the chart checked written.
fn tiny_vote_sweep(args: &[&str]) -> serde_json::Value {
    let tmp = tempfile::tempdir().unwrap();
    let tiny = "--preset tiny --methods vote --views 6 --test-views 2 --width 64 --height 48";
    let all: Vec<&str> = args
        .iter()
        .copied()
        .chain(tiny.split_whitespace())
        .collect();
    let report = sweep(&all, tmp.path());
    let chart = tmp.path().join(format!("robustness_{}.png", args[1]));
    assert!(chart.exists());
    report
}

/// The run's figures (vote, then the oracle) at its only level.
fn only_level_figures(report: &serde_json::Value) -> Vec<f64> {
    let level = &report["runs"][0]["levels"][0];
    [&level["methods"][0], &level["oracle"]]
        .iter()
        .flat_map(|m| {
            [
                m["miou"].as_f64().unwrap(),
                m["gaussian_accuracy"].as_f64().unwrap(),
            ]
        })
        .collect()
}

/// `--base-noise` is added to every level: flicker 0.5 swept over salt 0.3 labels the room
/// as salt 0.3 swept over flicker 0.5 does (the same figures, vote's and the oracle's), and
/// not as flicker alone; the report names it.
#[test]
fn base_noise_joins_the_swept_level() {
    let flicker_on_salt = tiny_vote_sweep(&[
        "--noise",
        "flicker",
        "--levels",
        "0.5",
        "--base-noise",
        "salt=0.3",
        "--seed",
        "4",
    ]);
    let salt_on_flicker = tiny_vote_sweep(&[
        "--noise",
        "salt",
        "--levels",
        "0.3",
        "--base-noise",
        "flicker=0.5",
        "--seed",
        "4",
    ]);
    let flicker_alone = tiny_vote_sweep(&["--noise", "flicker", "--levels", "0.5", "--seed", "4"]);
    assert_eq!(flicker_on_salt["base_noise"], "salt=0.3");
    assert_eq!(flicker_alone["base_noise"], serde_json::Value::Null);
    let figures = only_level_figures(&flicker_on_salt);
    assert_eq!(figures, only_level_figures(&salt_on_flicker));
    assert_ne!(figures, only_level_figures(&flicker_alone));
}

fn tiny_room(seed: u64, noise: &str) -> SynthScene {
    let mut cfg = SynthConfig::new(RoomSource::from_arg("tiny").unwrap());
    cfg.train_views = 8;
    cfg.test_views = 1;
    (cfg.width, cfg.height) = (64, 48);
    cfg.seed = seed;
    cfg.noise = Some(noise.parse().unwrap());
    generate(&cfg).unwrap()
}

/// The oracle written out plainly: per instance, per train view, the class covering most of
/// its mask gets the view's vote (split on a tie); most votes, then most pixels, wins.
fn oracle_by_hand(s: &SynthScene) -> Vec<i32> {
    let noisy = &s.noisy.as_ref().unwrap().maps;
    let ids = s.gaussians.instance_ids.as_ref().unwrap();
    let mut decided: BTreeMap<i32, i32> = BTreeMap::new();
    let mut instances: Vec<i32> = ids.iter().copied().filter(|&i| i >= 0).collect();
    instances.sort();
    instances.dedup();
    for inst in instances {
        // class -> (votes, pixels)
        let mut tally: BTreeMap<u16, (f64, u64)> = BTreeMap::new();
        for v in 0..s.cameras.len() {
            if s.cameras[v].split != Split::Train {
                continue;
            }
            let mut counts: BTreeMap<u16, u64> = BTreeMap::new();
            for p in 0..s.views[v].instances.len() {
                let label = noisy[v][p];
                if s.views[v].instances[p] as i32 == inst && label != LabelMap::IGNORE {
                    *counts.entry(label).or_insert(0) += 1;
                }
            }
            let top = counts.values().copied().max().unwrap_or(0);
            let winners = counts.values().filter(|&&n| n == top).count() as f64;
            for (&c, &n) in &counts {
                let t = tally.entry(c).or_insert((0.0, 0));
                t.1 += n;
                if n == top {
                    t.0 += 1.0 / winners;
                }
            }
        }
        let best = tally
            .values()
            .copied()
            .fold((-1.0, 0), |a, b| if b > a { b } else { a });
        let at_best: Vec<u16> = tally
            .iter()
            .filter(|(_, &t)| (t.0 - best.0).abs() < 1e-9 && t.1 == best.1)
            .map(|(&c, _)| c)
            .collect();
        decided.insert(
            inst,
            if at_best.len() == 1 {
                at_best[0] as i32
            } else {
                -1
            },
        );
    }
    ids.iter()
        .map(|i| decided.get(i).copied().unwrap_or(-1))
        .collect()
}

#[test]
fn instance_oracle_matches_a_direct_computation() {
    for (seed, noise) in [(3, "flicker=0.4"), (4, "salt=0.3"), (5, "consistent=0.75")] {
        let s = tiny_room(seed, noise);
        let oracle = instance_oracle_classes(&s).unwrap();
        assert_eq!(oracle, oracle_by_hand(&s), "seed {seed}, {noise}");
        assert!(oracle.iter().any(|&c| c >= 0), "seed {seed}, {noise}");
    }
}

#[test]
fn instance_oracle_on_clean_labels_gives_every_seen_object_its_true_class() {
    let s = tiny_room(6, "flicker=0");
    let oracle = instance_oracle_classes(&s).unwrap();
    let truth = s.gaussians.class_ids.as_ref().unwrap();
    let decided = oracle.iter().filter(|&&c| c >= 0).count();
    assert!(decided > oracle.len() / 2, "{decided} of {}", oracle.len());
    for (i, (&o, &t)) in oracle.iter().zip(truth).enumerate() {
        assert!(o < 0 || o == t, "Gaussian {i}: oracle {o}, truth {t}");
    }
}

/// A sweep's lists are checked before its first run: a level the noise cannot take, an item
/// named twice (the same work run and drawn twice), a room that does not exist.
#[test]
fn sweep_refuses_bad_lists_before_any_run() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sweep");
    let out = out.to_str().unwrap();
    let small = [
        "sweep",
        "--views",
        "2",
        "--test-views",
        "1",
        "--width",
        "16",
        "--height",
        "12",
    ];
    let cases: [(&[&str], &str); 5] = [
        (
            &["--noise", "boundary", "--levels", "0,0.5"],
            "whole number of pixels",
        ),
        (
            &["--noise", "flicker", "--levels", "0,0.2,-0"],
            "--levels names '0' twice",
        ),
        (
            &["--noise", "flicker", "--methods", "vote,vote"],
            "--methods names 'vote' twice",
        ),
        (
            &["--noise", "flicker", "--seeds", "1,1"],
            "--seeds names '1' twice",
        ),
        (
            &["--noise", "flicker", "--presets", "tiny,bogus"],
            "unknown preset 'bogus'",
        ),
    ];
    for (extra, expected) in cases {
        let mut args = small.to_vec();
        args.extend(extra);
        args.extend(["--out", out]);
        let e = fails(&args);
        assert!(e.contains(expected), "{extra:?}: {e}");
        assert!(!e.contains("seed "), "{extra:?} ran before refusing: {e}");
        assert!(!Path::new(out).exists(), "{extra:?} wrote its output");
    }
}
