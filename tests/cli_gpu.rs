//! The GPU-facing commands end to end, and device choice, including the failure paths:
//! no device, a device lacking a feature, an override that matches nothing.

use std::process::Command;

mod common;

use semsplat::gpu::context::choose_device;
use semsplat::gpu::{list_devices, GpuError};
use semsplat::scene::labels::{read_label_png, LabelMap};

fn semsplat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_semsplat"))
}

#[test]
fn no_vulkan_device_is_one_clear_error() {
    for args in [vec!["info"], vec!["bench", "sort", "--n", "100"]] {
        let out = semsplat()
            .args(&args)
            .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded without a device");
        assert!(
            stderr.contains("no Vulkan device") && stderr.contains("tools/setup.sh"),
            "{args:?}: {stderr}"
        );
        assert!(
            !stderr.contains("panicked") && !stderr.contains("RUST_BACKTRACE"),
            "{args:?}: {stderr}"
        );
        assert_eq!(
            stderr.trim().lines().count(),
            1,
            "{args:?}: expected one line, got {stderr}"
        );
    }
}

#[test]
fn device_override_that_matches_nothing_lists_the_devices() {
    let out = semsplat()
        .args(["bench", "sort", "--n", "100"])
        .env("SEMSPLAT_DEVICE", "no-such-gpu")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("no-such-gpu") && stderr.contains("[0]"),
        "{stderr}"
    );
}

/// The testing knobs' values that mean nothing are named, and the run goes on with the
/// device's own setting.
#[test]
fn testing_knobs_of_no_meaning_are_warned_of() {
    for (knob, value) in [
        ("SEMSPLAT_MAX_BINDING", "64k"),
        ("SEMSPLAT_CPU_FORMS", "yes"),
    ] {
        let out = semsplat()
            .args(["bench", "sort", "--n", "100", "--iters", "1"])
            .env(knob, value)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{knob}={value}: {stderr}");
        assert!(
            stderr.contains(&format!("warning: {knob}={value}")),
            "{knob}={value}: {stderr}"
        );
    }
}

#[test]
fn device_choice_prefers_discrete_and_names_missing_features() {
    let real = list_devices().unwrap();
    let mut cpu = real[0].clone();
    cpu.index = 0;
    cpu.caps.device_type = ash::vk::PhysicalDeviceType::CPU;
    cpu.missing.clear();
    let mut discrete = cpu.clone();
    discrete.index = 1;
    discrete.caps.device_type = ash::vk::PhysicalDeviceType::DISCRETE_GPU;
    discrete.caps.name = "Fancy GPU".into();
    let cands = vec![cpu.clone(), discrete.clone()];
    assert_eq!(choose_device(&cands, None).unwrap(), 1);
    assert_eq!(choose_device(&cands, Some("0")).unwrap(), 0);
    assert_eq!(choose_device(&cands, Some("fancy")).unwrap(), 1);

    // A discrete GPU lacking a feature is skipped; chosen explicitly, it is an error that
    // names what is missing.
    discrete.missing = vec!["VK_KHR_push_descriptor".into()];
    let cands = vec![cpu.clone(), discrete];
    assert_eq!(choose_device(&cands, None).unwrap(), 0);
    let err = choose_device(&cands, Some("1")).unwrap_err();
    assert!(matches!(err, GpuError::NoSuitableDevice(_)));
    let msg = err.to_string();
    assert!(
        msg.contains("VK_KHR_push_descriptor") && msg.contains("tools/setup.sh"),
        "{msg}"
    );

    // No usable device at all.
    cpu.missing = vec!["Vulkan 1.3 (device reports 1.1)".into()];
    let err = choose_device(&[cpu], None).unwrap_err();
    assert!(err.to_string().contains("Vulkan 1.3"), "{err}");
    assert!(matches!(choose_device(&[], None), Err(GpuError::NoDevice)));
}

#[test]
fn bench_sort_json_has_the_documented_fields() {
    let out = semsplat()
        .args([
            "bench", "sort", "--n", "20000", "--bits", "13", "--iters", "2", "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["n"], 20000);
    assert_eq!(v["bits"], 13);
    assert_eq!(v["verified"], true);
    for key in ["gpu_pairs_per_s", "cpu_pairs_per_s", "ratio"] {
        let x = v[key].as_f64().unwrap_or_else(|| panic!("{key} missing"));
        assert!(x.is_finite() && x > 0.0, "{key} = {x}");
    }
    let ratio = v["gpu_pairs_per_s"].as_f64().unwrap() / v["cpu_pairs_per_s"].as_f64().unwrap();
    assert!((ratio - v["ratio"].as_f64().unwrap()).abs() < 1e-9 * ratio);
    assert!(!v["device"].as_str().unwrap().is_empty());
    assert!(v["kernels"].as_array().unwrap().iter().any(|k| k["kernel"]
        .as_str()
        .is_some_and(|name| name.starts_with("sort/scatter"))));
}

#[test]
fn bench_sort_rejects_bad_bits() {
    let out = semsplat()
        .args(["bench", "sort", "--n", "10", "--bits", "33"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("33"));
}

#[test]
fn info_json_lists_the_selected_device() {
    let out = semsplat().args(["info", "--json"]).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let devices = v.as_array().unwrap();
    assert_eq!(devices.iter().filter(|d| d["selected"] == true).count(), 1);
    let d = &devices[0];
    for key in [
        "name",
        "driver_name",
        "vulkan_version",
        "subgroup_size",
        "float_atomic_add",
        "int64_atomics",
        "float64",
        "heaps",
    ] {
        assert!(!d[key].is_null(), "{key} missing from {d}");
    }
    // The text form says the same of float64 (what the projection computes in).
    let text = semsplat().arg("info").output().unwrap();
    let text = String::from_utf8_lossy(&text.stdout);
    let float64 = match d["float64"].as_bool().unwrap() {
        true => "float64:           yes",
        false => "float64:           no",
    };
    assert!(text.contains(float64), "{text}");
}

#[test]
fn bench_fuse_json_times_every_method_against_the_forward_render() {
    let v = bench_fuse_json(semsplat().args([
        "bench", "fuse", "--n", "3000", "--views", "3", "--width", "96", "--height", "64",
    ]));
    assert_eq!(v["views"], 3);
    assert_eq!(v["n"], 3000);
    assert_eq!(v["goal_ratio"], 1.3);
    assert!(v["host_threads"].as_u64().is_some_and(|t| t >= 1), "{v}");
    let positive = |x: &serde_json::Value, key: &str| {
        let t = x[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} missing in {x}"));
        assert!(t.is_finite() && t > 0.0, "{key} = {t}");
        t
    };
    let fwd_gpu = positive(&v["forward"], "gpu_ms");
    let fwd_wall = positive(&v["forward"], "wall_s");
    let methods = v["methods"].as_array().unwrap();
    let keys: Vec<&str> = methods.iter().map(|m| m["key"].as_str().unwrap()).collect();
    assert_eq!(
        keys,
        [
            "vote",
            "vote-occlusion",
            "vote-weighted",
            "flashsplat",
            "flashsplat-per-view",
            "segment-consensus",
            "segment-consensus-relabel"
        ]
    );
    for m in methods {
        let (gpu, wall) = (positive(m, "gpu_ms"), positive(m, "wall_s"));
        positive(m, "views_per_s");
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b;
        assert!(close(positive(m, "gpu_ratio"), gpu / fwd_gpu), "{m}");
        assert!(close(positive(m, "wall_ratio"), wall / fwd_wall), "{m}");
        assert_eq!(m["passes"], 1);
        // The label maps' readers were timed (random blocks drawn, not read: still work);
        // the tiled methods' staging too (the consensus stages its maps on its lanes, and
        // `--relabel` stages none where it kept every view's footprints).
        positive(m, "label_read_s");
        let consensus = m["key"].as_str().unwrap().starts_with("segment-consensus");
        if !consensus {
            positive(m, "label_stage_s");
        }
        if consensus {
            // The observation pass's parts are each timed and lie within the views' time
            // on each of its lanes (summed over them: they overlap).
            let o = &m["observe"];
            let parts = ["render_s", "regions_s", "gather_s"].map(|k| positive(o, k));
            // The regions' GPU time is part of the method's (0 where the host finds them).
            let regions_gpu_ms = o["regions_gpu_ms"].as_f64().expect("regions_gpu_ms");
            assert!(
                (0.0..=positive(m, "gpu_ms")).contains(&regions_gpu_ms),
                "{m}"
            );
            let lanes = positive(m, "views_in_flight");
            assert!((1.0..=2.0).contains(&lanes), "{m}");
            assert!(
                parts.iter().sum::<f64>() <= lanes * positive(m, "view_s"),
                "{m}"
            );
            // The clustering's parts lie within segments_s, and its counts add up.
            let c = &m["clustering"];
            let parts = ["neighbours_s", "pairs_s", "pieces_s", "joins_s"].map(|k| positive(c, k));
            assert!(
                parts.iter().sum::<f64>() <= positive(m, "segments_s"),
                "{m}"
            );
            let count = |k: &str| {
                c[k].as_u64()
                    .unwrap_or_else(|| panic!("{k} missing in {c}"))
            };
            assert_eq!(count("pieces") - count("joins"), count("segments"), "{m}");
            assert!(count("segments") > 0 && count("pieces") <= 3000, "{m}");
            let pieces = ["outright_s", "adjacency_s", "piece_regions_s"].map(|k| positive(c, k));
            assert!(pieces.iter().sum::<f64>() <= positive(c, "pieces_s"), "{m}");
            // Every join was tested, every test popped from the queue.
            let queue = ["joins", "tested", "popped"].map(count);
            assert!(queue[0] <= queue[1] && queue[1] <= queue[2], "{m}");
            // The decision's steps lie within decide_s.
            let d = &m["decision"];
            let steps = [
                "votes_s",
                "segments_s",
                "kept_s",
                "region_votes_s",
                "gaussians_s",
                "fill_s",
                "smooth_s",
                "posteriors_s",
            ];
            let steps = steps.map(|k| positive(d, k));
            assert!(steps.iter().sum::<f64>() <= positive(m, "decide_s"), "{m}");
        }
    }
}

/// `bench fuse ... --json` run with the validation layer on: its JSON, once the run
/// succeeded with the layer silent.
fn bench_fuse_json(bench: &mut Command) -> serde_json::Value {
    let out = bench
        .arg("--json")
        .env("SEMSPLAT_VALIDATION", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("[vulkan"), "validation layer: {stderr}");
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `--labels`: a scene folder's own label maps instead of random blocks; the views take
/// the maps' size and the classes are those the maps hold.
#[test]
fn bench_fuse_reads_a_scene_folders_label_maps() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("room");
    common::cli::synth_tiny(&dir, 3, (32, 24));
    let labels = dir.join("labels");
    let mut present = std::collections::BTreeSet::new();
    for entry in std::fs::read_dir(&labels).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "png") {
            let map = read_label_png(&path).unwrap();
            present.extend(map.labels.into_iter().filter(|&l| l != LabelMap::IGNORE));
        }
    }
    let mut bench = semsplat();
    bench.args(["bench", "fuse", "--scene"]).arg(&dir);
    bench.arg("--labels").arg(&labels);
    bench.args([
        "--views",
        "4",
        "--width",
        "640",
        "--height",
        "480",
        "--classes",
        "16",
    ]);
    let v = bench_fuse_json(bench.args(["--methods", "vote,segment-consensus"]));
    // The maps' size and classes, not the flags'.
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(32), Some(24)),
        "{v}"
    );
    assert_eq!(v["classes"].as_u64(), Some(present.len() as u64), "{v}");
    assert_eq!(v["views"], 4);
    // Segment consensus's clustering saw the scene's regions: more than one segment, and
    // fewer than the Gaussians.
    let c = &v["methods"][1]["clustering"];
    let segments = c["segments"].as_u64().unwrap();
    assert!(segments > 1 && segments < v["n"].as_u64().unwrap(), "{c}");
}

#[test]
fn bench_fuse_rejects_bad_input() {
    for (args, needle) in [
        (vec!["--views", "0"], "--views"),
        (vec!["--n", "0"], "--n"),
        (vec!["--classes", "0"], "--classes"),
        (vec!["--classes", "65536"], "--classes"),
        (vec!["--methods", "vote,joint"], "unknown method 'joint'"),
        (vec!["--labels", "/nonexistent"], "--scene"),
    ] {
        let out = semsplat()
            .args(["bench", "fuse"])
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

fn kernels_of(v: &serde_json::Value) -> Vec<serde_json::Value> {
    v["kernels"].as_array().unwrap().clone()
}

/// `bench train --json`: one entry per kernel over the iteration's two submissions (the
/// loss's reduction runs in both: three sums, then the entropy's), finite stage times, and
/// `--semantics-only` runs the semantic backward and Adam on the logits alone, with
/// `--without-images` no SSIM; `--without-images` alone is refused.
#[test]
fn bench_train_json_lists_each_kernel_once() {
    let bench = |extra: &[&str]| -> serde_json::Value {
        let mut args = vec!["bench", "train", "--n", "3000", "--width", "64", "--height"];
        args.extend(["48", "--channels", "3", "--iters", "1", "--json"]);
        args.extend(extra);
        let out = semsplat().args(&args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let runs = [
        (bench(&[]), false),
        (bench(&["--semantics-only"]), true),
        (bench(&["--semantics-only", "--without-images"]), true),
    ];
    for (v, semantics_only) in runs {
        assert_eq!(v["semantics_only"], semantics_only);
        // Without a target image the loss has no SSIM, and its reductions lose the
        // photometric sums (three before the entropy's, then one).
        let images = v["images"].as_bool().unwrap();
        let ssim = |k: &serde_json::Value| k["kernel"].as_str().unwrap().contains("ssim");
        assert_eq!(kernels_of(&v).iter().any(ssim), images, "{v}");
        for key in [
            "iter_ms",
            "forward_ms",
            "loss_ms",
            "backward_ms",
            "optimizer_ms",
        ] {
            let ms = v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"));
            assert!(ms.is_finite() && ms > 0.0, "{key} = {ms}");
        }
        let kernels = kernels_of(&v);
        let dispatches = |name: &str| {
            let of = kernels.iter().filter(|k| k["kernel"] == name);
            let counts: Vec<u64> = of.map(|k| k["dispatches"].as_u64().unwrap()).collect();
            assert!(counts.len() <= 1, "{name} listed {} times", counts.len());
            counts.first().copied().unwrap_or(0)
        };
        assert_eq!(dispatches("train/loss_reduce"), if images { 4 } else { 3 });
        assert_eq!(dispatches("train/entropy"), 1);
        let (adam, project_backward) = match semantics_only {
            true => (1, 0),
            false => (6, 1),
        };
        assert_eq!(dispatches("train/adam"), adam);
        assert_eq!(dispatches("raster/project_backward"), project_backward);
    }
    let out = semsplat()
        .args(["bench", "train", "--n", "100", "--without-images"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--semantics-only"));
}
