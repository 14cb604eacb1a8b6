//! `semsplat synth | fuse | render` end to end on a tiny room, and their bad input.

mod common;

use std::path::Path;

use common::cli::{
    arg_in, fails, fuse_synth, fuse_synth_args, ok, read_json, semsplat, semsplat_with_env,
    strings, synth_tiny,
};
use semsplat::scene::Gaussians;

/// The scene file `f` in the folder `d`.
fn read_scene(d: &Path, f: &str) -> Gaussians {
    semsplat::scene::ply::read_ply(&d.join(f)).unwrap()
}

#[test]
fn fuse_writes_classes_reassigns_from_saved_evidence_and_extracts() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 4, (64, 48));
    let p = |f: &str| arg_in(d, f);
    fuse_synth(
        d,
        &[
            "--out",
            &p("fused.ply"),
            "--report",
            &p("report.json"),
            "--save-contrib",
            &p("A.npy"),
            "--palette-ply",
            &p("palette.ply"),
        ],
    );
    let g = read_scene(d, "fused.ply");
    let truth = read_scene(d, "scene.ply");
    check_fused_classes(&g, &truth);
    check_report_and_side_outputs(d);
    check_per_view_agrees(d, g.class_ids.as_ref().unwrap());
    check_passes_are_noted(d, truth.len());
    check_eval_scores(d);
    check_rendered_views_and_membership(d, truth.len());
    check_reassigned_from_saved_evidence(d, &g);
    check_extract_and_remove_add_up(d, truth.len());
    check_scene_folder_and_its_cameras(d);
}

/// The synth folder itself as --scene, its cameras.json read without --cameras (and said
/// so): the same classes as the files named one by one.
fn check_scene_folder_and_its_cameras(d: &Path) {
    let p = |f: &str| arg_in(d, f);
    let args = ["fuse", "--scene", &p(""), "--labels", &p("labels")];
    let err = ok(&[&args[..], &["--out", &p("folder.ply")]].concat());
    assert!(err.contains("cameras.json"), "{err}");
    let (named, folder) = (read_scene(d, "fused.ply"), read_scene(d, "folder.ply"));
    assert_eq!(named.class_ids, folder.class_ids);
    assert_eq!(named.class_conf, folder.class_conf);
}

/// Unseen Gaussians are -1 (never 0) with confidence 0; seen ones have a label id. Four
/// 64x48 views leave many Gaussians unseen; those seen are mostly right.
fn check_fused_classes(g: &Gaussians, truth: &Gaussians) {
    let classes = g.class_ids.as_ref().unwrap();
    let conf = g.class_conf.as_ref().unwrap();
    assert_eq!(classes.len(), truth.len());
    for (c, p) in classes.iter().zip(conf) {
        assert!(*c >= -1);
        assert_eq!(*c == -1, *p == 0.0);
    }
    let seen = classes.iter().filter(|&&c| c >= 0).count();
    let right = classes
        .iter()
        .zip(truth.class_ids.as_ref().unwrap())
        .filter(|(a, b)| a == b)
        .count();
    assert!(seen > classes.len() / 4, "{seen} of {} seen", classes.len());
    assert!(
        right as f64 > 0.8 * seen as f64,
        "{right} of {seen} seen Gaussians right"
    );
}

/// The report names the method and its speed and memory; the class table and the palette
/// scene are written beside it.
fn check_report_and_side_outputs(d: &Path) {
    let report = read_json(&d.join("report.json"));
    assert_eq!(report["method"], "flashsplat");
    assert_eq!(report["accumulation"], "fixed_point");
    assert!(report["stats"]["views_per_s"].as_f64().unwrap() > 0.0);
    assert!(report["stats"]["peak_device_bytes"].as_u64().unwrap() > 0);
    assert!(d.join("A.classes.json").is_file() && d.join("palette.ply").is_file());
}

/// A budget of two class rows (vote's 4 bytes an entry) takes several passes over the views,
/// and fuse says so before them; the same classes as in one pass.
fn check_passes_are_noted(d: &Path, gaussians: usize) {
    let p = |f: &str| arg_in(d, f);
    let budget = (2 * 4 * gaussians).to_string();
    let vote = ["--method", "vote", "--out"];
    let report = p("passes.json");
    let budget = ["--mem-budget", &budget, "--report", &report];
    let err = fuse_synth(d, &[&vote[..], &[&p("passes.ply")], &budget].concat());
    assert!(
        err.contains("passes over the views (2 classes a pass") && err.contains("--mem-budget"),
        "{err}"
    );
    // Views a second count each view once, however many passes took it.
    let stats =
        &serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(&report).unwrap())
            .unwrap()["stats"];
    let (views, wall_s) = (
        stats["views"].as_f64().unwrap(),
        stats["wall_s"].as_f64().unwrap(),
    );
    assert!(stats["passes"].as_u64().unwrap() > 1, "{stats}");
    let per_s = stats["views_per_s"].as_f64().unwrap();
    assert!((per_s * wall_s - views).abs() < 0.01 * views, "{stats}");
    let err = fuse_synth(d, &[&vote[..], &[&p("one_pass.ply")]].concat());
    assert!(!err.contains("passes over the views"), "{err}");
    let classes = |f: &str| read_scene(d, f).class_ids.unwrap();
    assert_eq!(classes("passes.ply"), classes("one_pass.ply"));
}

/// The per-view variant runs end to end and says so; it agrees with plain FlashSplat's
/// `classes` on most Gaussians of these true labels.
fn check_per_view_agrees(d: &Path, classes: &[i32]) {
    let p = |f: &str| arg_in(d, f);
    let err = fuse_synth(
        d,
        &[
            "--per-view",
            "--out",
            &p("per_view.ply"),
            "--report",
            &p("per_view.json"),
        ],
    );
    // The room's one test view is fused too, and the note says how to hold it out.
    assert!(
        err.contains("1 camera marked \"test\" is fused too; --train-only"),
        "{err}"
    );
    let per_view = read_json(&d.join("per_view.json"));
    assert_eq!(per_view["method"], "flashsplat --per-view");
    let pv = read_scene(d, "per_view.ply");
    let same = pv
        .class_ids
        .as_ref()
        .unwrap()
        .iter()
        .zip(classes)
        .filter(|(a, b)| a == b)
        .count();
    assert!(same as f64 > 0.9 * classes.len() as f64, "{same} agree");
}

/// Scores on the views, with 3D accuracy against the synth truth.
fn check_eval_scores(d: &Path) {
    let p = |f: &str| arg_in(d, f);
    let out = semsplat(&[
        "eval",
        "--scene",
        &p("fused.ply"),
        "--cameras",
        &p("cameras.json"),
        "--labels",
        &p("labels"),
        "--views",
        "all",
        "--truth",
        &p("scene.ply"),
        "--json",
        &p("eval.json"),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let eval = read_json(&d.join("eval.json"));
    let miou = eval["miou"].as_f64().unwrap();
    assert!(miou > 0.5 && miou <= 1.0, "{eval}");
    assert!(eval["gaussian_accuracy"].as_f64().unwrap() > 0.2);
}

/// `fuse` of the room's scene from the evidence saved in `A.npy` instead of rendering the
/// views for it, with `extra` options.
fn fuse_from_saved_evidence(d: &Path, extra: &[&str]) {
    let (scene, contrib) = (arg_in(d, "scene.ply"), arg_in(d, "A.npy"));
    let mut args = vec!["fuse", "--scene", &scene, "--contrib", &contrib];
    args.extend_from_slice(extra);
    ok(&args);
}

/// Label maps rendered from the fused scene, and the multi-instance membership of the
/// scene's `gaussians` Gaussians (0 or 1, some 1).
fn check_rendered_views_and_membership(d: &Path, gaussians: usize) {
    let p = |f: &str| arg_in(d, f);
    fuse_from_saved_evidence(
        d,
        &[
            "--cameras",
            &p("cameras.json"),
            "--render-views",
            &p("views"),
            "--save-membership",
            &p("S.npy"),
            "--gamma",
            "0.1",
            "--out",
            &p("v.ply"),
        ],
    );
    let cams = semsplat::scene::cameras::load_cameras(&d.join("cameras.json")).unwrap();
    for c in &cams {
        assert!(d
            .join("views")
            .join(format!("{}.labels.png", c.name))
            .is_file());
        assert!(d
            .join("views")
            .join(format!("{}.palette.png", c.name))
            .is_file());
    }
    let s_bytes = std::fs::read(d.join("S.npy")).unwrap();
    let s_npy = npyz::NpyFile::new(&s_bytes[..]).unwrap();
    assert_eq!(s_npy.shape()[1], gaussians as u64);
    let s_vals: Vec<f32> = s_npy.into_vec().unwrap();
    assert!(s_vals.iter().all(|&v| v == 0.0 || v == 1.0) && s_vals.contains(&1.0));
}

/// Reassigning from the saved matrix gives the same classes as the fused scene `g`
/// without rendering.
fn check_reassigned_from_saved_evidence(d: &Path, g: &Gaussians) {
    fuse_from_saved_evidence(d, &["--out", &arg_in(d, "again.ply")]);
    let again = read_scene(d, "again.ply");
    assert_eq!(again.class_ids, g.class_ids);
}

/// Extract and remove one class: the two parts add up to the scene's `gaussians`.
fn check_extract_and_remove_add_up(d: &Path, gaussians: usize) {
    let p = |f: &str| arg_in(d, f);
    let table = semsplat::scene::classes::read_class_table(&d.join("A.classes.json")).unwrap();
    let name = &table.classes[0].name;
    for (what, out) in [("--extract", "only.ply"), ("--remove", "rest.ply")] {
        fuse_from_saved_evidence(d, &[what, name, "--out", &p(out)]);
    }
    let only = read_scene(d, "only.ply");
    let rest = read_scene(d, "rest.ply");
    assert!(!only.is_empty());
    assert_eq!(only.len() + rest.len(), gaussians);
}

/// Writes `d`'s scene.ply with semantic logits, one-hot from the true classes, as sem.ply;
/// returns the number of channels.
fn write_one_hot_logits_scene(d: &Path) -> usize {
    let mut g = semsplat::scene::ply::read_ply(&d.join("scene.ply")).unwrap();
    let ids = g.class_ids.clone().unwrap();
    let c = (*ids.iter().max().unwrap() + 1) as usize;
    let mut logits = vec![0.0f32; g.len() * c];
    for (i, &id) in ids.iter().enumerate() {
        logits[i * c + id as usize] = 10.0;
    }
    g.semantics = Some(semsplat::scene::SemanticLogits {
        channels: c,
        logits,
    });
    semsplat::scene::ply::write_ply(&d.join("sem.ply"), &g).unwrap();
    c
}

#[test]
fn render_writes_images_labels_and_raw_arrays() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 4, (64, 48));
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    let c = write_one_hot_logits_scene(d);
    let cams = semsplat::scene::cameras::load_cameras(&d.join("cameras.json")).unwrap();
    let view = cams[0].name.clone();
    ok(&[
        "render",
        "--scene",
        &p("sem.ply"),
        "--cameras",
        &p("cameras.json"),
        "--views",
        &view,
        "--out",
        &p("out"),
        "--semantics",
        "--raw",
    ]);
    let out = d.join("out");
    for suffix in [
        ".png",
        ".labels.png",
        ".palette.png",
        ".rgb.npy",
        ".alpha.npy",
        ".depth.npy",
        ".sem.npy",
        ".sem_norm.npy",
    ] {
        assert!(
            out.join(format!("{view}{suffix}")).is_file(),
            "{view}{suffix} missing"
        );
    }
    let sem = std::fs::read(out.join(format!("{view}.sem_norm.npy"))).unwrap();
    let npy = npyz::NpyFile::new(&sem[..]).unwrap();
    assert_eq!(npy.shape(), &[48, 64, c as u64]);
    // Rendered labels agree with the ray-cast truth on most pixels.
    let rendered =
        semsplat::scene::labels::read_label_png(&out.join(format!("{view}.labels.png"))).unwrap();
    let truth =
        semsplat::scene::labels::read_label_png(&d.join("labels").join(format!("{view}.png")))
            .unwrap();
    let agree = rendered
        .labels
        .iter()
        .zip(&truth.labels)
        .filter(|(a, b)| a == b)
        .count();
    assert!(
        agree as f64 > 0.8 * truth.labels.len() as f64,
        "{agree} of {} pixels agree",
        truth.labels.len()
    );

    // A scene of classes without logits (synth's, a fused one): --raw writes every array
    // but the semantic ones, and says so; --softmax, which blends logits, is refused.
    let classes_only = |extra: &str| {
        let args = [
            "render",
            "--scene",
            &p("scene.ply"),
            "--cameras",
            &p("cameras.json"),
        ];
        let rest = [
            "--views",
            &view,
            "--out",
            &p("classes"),
            "--semantics",
            extra,
        ];
        semsplat(&[&args[..], &rest].concat())
    };
    let r = classes_only("--raw");
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        r.status.success() && err.contains("no .sem and .sem_norm"),
        "{err}"
    );
    let written = |suffix: &str| d.join("classes").join(format!("{view}{suffix}")).is_file();
    assert!([".labels.png", ".rgb.npy", ".alpha.npy", ".depth.npy"].map(written) == [true; 4]);
    assert!(!written(".sem.npy") && !written(".sem_norm.npy"));
    let r = classes_only("--softmax");
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        !r.status.success() && err.contains("--softmax blends logits"),
        "{err}"
    );
}

#[test]
fn bad_input_is_one_clear_error_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 4, (64, 48));
    for (args, needle) in bad_fuse_inputs(d).into_iter().chain(bad_render_inputs(d)) {
        assert_one_clear_error(&args, needle);
    }
    assert!(
        !d.join("x.ply").exists() && !d.join("r").exists(),
        "a failed run left output behind"
    );
}

/// `args` fails with an error that mentions `needle`, not a panic.
fn assert_one_clear_error(args: &[String], needle: &str) {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = semsplat(&refs);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{refs:?} succeeded");
    assert!(
        err.contains(needle),
        "{refs:?}: error does not mention {needle}: {err}"
    );
    assert!(!err.contains("panicked"), "{refs:?}: {err}");
}

/// `fuse` runs into x.ply in `d` with a missing, wrong or conflicting input, each with what
/// its error must mention.
fn bad_fuse_inputs(d: &Path) -> Vec<(Vec<String>, &'static str)> {
    let p = |f: &str| arg_in(d, f);
    // `fuse` from a saved matrix (here a file that is none) into x.ply, with `extra` options.
    let contrib_with = |extra: &[&str]| -> Vec<String> {
        let (scene, contrib, out) = (p("scene.ply"), p("cameras.json"), p("x.ply"));
        let args = [
            "fuse",
            "--scene",
            &scene,
            "--contrib",
            &contrib,
            "--out",
            &out,
        ];
        strings(&[&args[..], extra].concat())
    };
    // A complete `fuse` command writing x.ply, with `extra` options.
    let fuse_with = |extra: &[&str]| -> Vec<String> {
        let mut args = fuse_synth_args(d, extra);
        args.extend(["--out".into(), p("x.ply")]);
        args
    };
    vec![
        (
            strings(&[
                "fuse",
                "--scene",
                &p("missing.ply"),
                "--cameras",
                &p("cameras.json"),
                "--labels",
                &p("labels"),
                "--out",
                &p("x.ply"),
            ]),
            "missing.ply",
        ),
        (
            strings(&[
                "fuse",
                "--scene",
                &p("scene.ply"),
                "--cameras",
                &p("cameras.json"),
                "--labels",
                &p("images"),
                "--out",
                &p("x.ply"),
            ]),
            "images",
        ),
        (
            strings(&["fuse", "--scene", &p("scene.ply"), "--out", &p("x.ply")]),
            "--cameras",
        ),
        (fuse_with(&["--gamma", "3"]), "gamma"),
        (
            fuse_with(&["--method", "vote", "--per-view"]),
            "--per-view is a variant of --method flashsplat",
        ),
        (contrib_with(&[]), "cameras.json"),
        // The saved matrix is assigned on the host: a device budget would not apply.
        (contrib_with(&["--mem-budget", "1G"]), "--mem-budget"),
        // Its rows are named by the table saved beside it.
        (
            contrib_with(&["--classes", &p("classes.json")]),
            "--classes",
        ),
    ]
}

/// `render` runs into r in `d` with input it cannot draw, each with what its error must
/// mention.
fn bad_render_inputs(d: &Path) -> Vec<(Vec<String>, &'static str)> {
    let p = |f: &str| arg_in(d, f);
    vec![
        (
            // init.ply has neither logits nor classes (scene.ply's classes would be drawn).
            strings(&[
                "render",
                "--scene",
                &p("init.ply"),
                "--cameras",
                &p("cameras.json"),
                "--out",
                &p("r"),
                "--semantics",
            ]),
            "sem_",
        ),
        (
            strings(&[
                "render",
                "--scene",
                &p("scene.ply"),
                "--cameras",
                &p("cameras.json"),
                "--out",
                &p("r"),
                "--views",
                "nope",
            ]),
            "nope",
        ),
    ]
}

/// `bench render --scene` draws the folder's scene from its first camera at that camera's
/// size, reports the scene's Gaussians (not the random scene's unused `--n`), and refuses
/// the random scene's size options beside it.
#[test]
fn bench_render_times_a_scene_folder_from_its_first_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 2, (40, 30));
    let gaussians = semsplat::scene::ply::read_ply(&d.join("scene.ply"))
        .unwrap()
        .len();
    let folder = d.to_str().unwrap();
    let bench = [
        "bench", "render", "--scene", folder, "--iters", "1", "--json",
    ];
    let out = semsplat(&bench);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["gaussians"], gaussians as u64, "{v}");
    assert!(v.get("n").is_none(), "{v}");
    assert_eq!(
        (v["width"].clone(), v["height"].clone()),
        (40.into(), 30.into())
    );
    let err = fails(&["bench", "render", "--scene", folder, "--n", "5"]);
    assert!(err.contains("--n"), "{err}");
    // A scene without its cameras beside it: named as that, for every bench of a scene.
    std::fs::remove_file(d.join("cameras.json")).unwrap();
    for bench in ["render", "train", "fuse"] {
        let err = fails(&["bench", bench, "--scene", folder, "--iters", "1"]);
        assert!(
            err.contains("no cameras.json beside the scene"),
            "{bench}: {err}"
        );
    }
}

/// `bench fuse --scene` times a folder's scene on its first `--views` cameras, scaled to the
/// asked size, and reports where the GPU time went per kernel.
#[test]
fn bench_fuse_times_a_scene_folder_on_its_cameras() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 3, (40, 30));
    let scene = d.join("scene.ply");
    let gaussians = semsplat::scene::ply::read_ply(&scene).unwrap().len();
    let bench = |extra: &[&str]| {
        let mut args = vec![
            "bench",
            "fuse",
            "--scene",
            d.to_str().unwrap(),
            "--methods",
            "vote,flashsplat,segment-consensus,segment-consensus-relabel",
        ];
        args.extend_from_slice(extra);
        std::process::Command::new(env!("CARGO_BIN_EXE_semsplat"))
            .args(&args)
            .env("SEMSPLAT_VALIDATION", "1")
            .output()
            .unwrap()
    };
    // Asked for more views than the folder has cameras (3 train + 1 test): all four.
    let out = bench(&["--views", "9", "--width", "80", "--height", "60", "--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("[vulkan"), "validation layer: {stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["n"], gaussians as u64);
    assert_eq!(v["views"], 4);
    assert_eq!(
        (v["width"].clone(), v["height"].clone()),
        (80.into(), 60.into())
    );
    for m in v["methods"].as_array().unwrap() {
        let kernels = m["kernels"].as_array().unwrap();
        let names: Vec<&str> = kernels
            .iter()
            .map(|k| k["kernel"].as_str().unwrap())
            .collect();
        // The consensus's observation pass renders the median depth and looks up the
        // centers; `--relabel`'s, where the device takes the CPU drivers' forms (as the CLI
        // opens it), walks each view as FlashSplat does, keeping each Gaussian's weights
        // per label region and writing the median depth; on a GPU it walks the relabeled
        // views again by FlashSplat's pass.
        let relabel: &[&str] = match common::gpu().caps().cpu_forms {
            true => &["fuse/region_footprint", "fuse/center_pixel"],
            false => &[
                "raster/blend_median_depth",
                "fuse/center_pixel",
                "fuse/contrib_fixed",
            ],
        };
        let wanted: &[&str] = match m["key"].as_str().unwrap() {
            "vote" => &["fuse/vote"],
            "flashsplat" => &["fuse/contrib_fixed"],
            "segment-consensus" => &["raster/blend_median_depth", "fuse/center_pixel"],
            "segment-consensus-relabel" => relabel,
            key => panic!("method {key} not asked for"),
        };
        for want in wanted {
            // Either form of the kernel (its `_wide` one on CPU devices).
            let wide = format!("{want}_wide");
            assert!(
                names.iter().any(|n| n == want || *n == wide),
                "{}: {want} not in {names:?}",
                m["key"]
            );
        }
        // Each kernel's time ends at its own timestamp: together at most the views' time.
        let sum: f64 = kernels.iter().map(|k| k["ns"].as_f64().unwrap()).sum();
        let gpu_ms = m["gpu_ms"].as_f64().unwrap();
        assert!(
            sum > 0.0 && sum * 1e-6 <= gpu_ms * (1.0 + 1e-9),
            "{sum} ns of {gpu_ms} ms"
        );
    }
    // A folder without cameras.json, and --scene with a random-scene option, are refused.
    std::fs::remove_file(d.join("cameras.json")).unwrap();
    let out = bench(&["--views", "2"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("cameras.json"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    let out = bench(&["--n", "10"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--n"));
}

/// Render and fuse a scene whose per-Gaussian buffers pass one binding (here forced by a
/// lower binding limit, as a 9M-Gaussian scene passes lavapipe's 128 MiB with its 16-byte
/// projected attributes): the same bytes as without a limit. The projection runs in parts
/// of Gaussians and the kernels that index Gaussians at random (binning, blending, the
/// FlashSplat accumulation, the vote, the assignment's evidence rows) reach them by
/// address; only arrays of 4 bytes per Gaussian (sort keys, scans) must fit.
#[test]
fn render_and_fuse_past_one_binding_write_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 3, (64, 48));
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    // The room with logits (its class one-hot, times 4), so --semantics blends channels.
    let mut g = semsplat::scene::ply::read_ply(&d.join("scene.ply")).unwrap();
    let classes = g.class_ids.take().unwrap();
    let channels = 1 + *classes.iter().max().unwrap() as usize;
    let logits = classes
        .iter()
        .flat_map(|&c| (0..channels).map(move |k| if k as i32 == c { 4.0 } else { 0.0 }))
        .collect();
    g.semantics = Some(semsplat::scene::SemanticLogits { channels, logits });
    g.class_conf = None;
    semsplat::scene::ply::write_ply(&d.join("logits.ply"), &g).unwrap();
    let limit = 2 * g.len() as u64;
    assert!(4 * g.len() as u64 > limit && channels > 4);
    let run = |args: &[&str], limited: bool| {
        let env: Vec<(&str, String)> = if limited {
            vec![("SEMSPLAT_MAX_BINDING", limit.to_string())]
        } else {
            Vec::new()
        };
        let r = semsplat_with_env(args, &env);
        assert!(
            r.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&r.stderr)
        );
    };
    let cameras = p("cameras.json");
    for limited in [false, true] {
        let out = p(if limited { "limited" } else { "whole" });
        let render = |scene: &str, into: &str, extra: &[&str]| {
            let into = format!("{out}/{into}");
            let mut args = vec![
                "render",
                "--scene",
                scene,
                "--cameras",
                &cameras,
                "--out",
                &into,
                "--semantics",
            ];
            args.extend(extra);
            run(&args, limited);
        };
        render(&p("logits.ply"), "logits", &["--raw"]);
        for method in ["flashsplat", "vote"] {
            let fused = format!("{out}/{method}.ply");
            let args = fuse_synth_args(d, &["--method", method, "--out", &fused]);
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            run(&args, limited);
        }
        // The fused classes, rendered as labels (the blend reads each Gaussian's class).
        render(&format!("{out}/flashsplat.ply"), "labels", &[]);
    }
    let compared = assert_same_files(
        &d.join("whole"),
        &d.join("limited"),
        &["", "logits", "labels"],
    );
    assert!(compared >= 10, "{compared} files compared");
}

/// A label map larger than one binding (here forced by a lower limit, as an 8192x4200 map
/// passes lavapipe's 128 MiB at 4 bytes a pixel): the methods that hold a view's pixels in
/// one binding fail with what to do, the tiled ones fuse it.
#[test]
fn a_view_over_one_binding_names_the_tiled_methods() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 2, (320, 240));
    let limit = ("SEMSPLAT_MAX_BINDING", (320 * 240 * 4 - 1024).to_string());
    for (method, tiled) in [
        (&["vote"][..], false),
        (&["segment-consensus"], false),
        (&["flashsplat"], true),
        (&["vote", "--weighted"], true),
    ] {
        let out = d.join(format!("{}.ply", method.join("")));
        let mut extra = vec!["--out", out.to_str().unwrap(), "--method"];
        extra.extend(method);
        let args = fuse_synth_args(d, &extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = semsplat_with_env(&args, std::slice::from_ref(&limit));
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.success(), tiled, "{method:?}: {stderr}");
        assert_eq!(out.exists(), tiled, "{method:?}");
        if !tiled {
            assert!(
                stderr.contains("binding limit")
                    && stderr.contains("holds a whole view's pixels in one binding")
                    && stderr.contains("--method flashsplat")
                    && !stderr.contains("fewer classes"),
                "{method:?}: {stderr}"
            );
        }
    }
}

/// Every file in the folders `subs` of `whole` has the same bytes as its namesake under
/// `limited`; returns how many files were compared.
fn assert_same_files(whole: &Path, limited: &Path, subs: &[&str]) -> usize {
    let mut compared = 0;
    for sub in subs {
        for entry in std::fs::read_dir(whole.join(sub)).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                continue;
            }
            let name = path.file_name().unwrap();
            let limited = std::fs::read(limited.join(sub).join(name)).unwrap();
            assert!(
                std::fs::read(&path).unwrap() == limited,
                "{path:?} differs under the limit"
            );
            compared += 1;
        }
    }
    compared
}

/// Options the chosen method does not read are noted, and the run is what it is without
/// them; an option the method reads is not.
#[test]
fn options_without_effect_are_noted() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 3, (40, 30));
    let out = arg_in(d, "f.ply");
    let err = fuse_synth(
        d,
        &[
            "--method",
            "flashsplat",
            "--depth-tol",
            "0.2",
            "--gamma",
            "0.1",
            "--clustering",
            "rounds",
            "--out",
            &out,
        ],
    );
    assert!(
        err.contains("note: --depth-tol has no effect with flashsplat"),
        "{err}"
    );
    assert!(
        err.contains("note: --clustering has no effect with flashsplat"),
        "{err}"
    );
    assert!(err.contains("note: --gamma has no effect without"), "{err}");
    let plain = arg_in(d, "plain.ply");
    fuse_synth(d, &["--method", "flashsplat", "--out", &plain]);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&plain).unwrap());

    // Segment consensus selects by its decided classes: --gamma does not move it.
    let consensus = [
        "--method",
        "segment-consensus",
        "--gamma",
        "0.5",
        "--extract",
        "1",
    ];
    let err = fuse_synth(d, &[&consensus[..], &["--out", &out]].concat());
    assert!(
        err.contains("note: --gamma has no effect with segment-consensus"),
        "{err}"
    );

    // Segment consensus reads --clustering: a run in rounds writes its classes and segments.
    let rounds = ["--method", "segment-consensus", "--clustering", "rounds"];
    let err = fuse_synth(d, &[&rounds[..], &["--out", &out]].concat());
    assert!(!err.contains("no effect"), "{err}");
    let fused = read_scene(d, "f.ply");
    assert!(fused.segment_ids.is_some() && fused.class_ids.is_some());

    let occlusion = ["--method", "vote", "--occlusion", "--depth-tol", "0.2"];
    let err = fuse_synth(d, &[&occlusion[..], &["--out", &out]].concat());
    assert!(!err.contains("no effect"), "{err}");

    // Three small views leave many Gaussians' centers unseen: a vote says why they have no
    // class and which methods classify them; FlashSplat classifies them, and says nothing.
    let weighted = ["--method", "vote", "--weighted", "--out", &out];
    let err = fuse_synth(d, &weighted);
    let left: usize = (err.split(" Gaussians left without a class").next())
        .and_then(|head| head.rsplit('(').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count of Gaussians without a class: {err}"));
    assert!(
        err.contains(&format!("note: {left} of the "))
            && err.contains(
                "vote --weighted classifies only Gaussians whose centers fall on labeled pixels \
             and are visible there"
            ),
        "{err}"
    );
    let err = fuse_synth(d, &["--method", "flashsplat", "--out", &out]);
    assert!(!err.contains("have no class"), "{err}");
}
