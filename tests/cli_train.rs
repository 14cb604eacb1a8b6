//! `semsplat train` end to end on a tiny synth room, and its bad input.

mod common;

use common::cli::{fuse_synth, semsplat, synth_tiny};

use std::path::Path;
use std::process::Output;

use semsplat::scene::labels::{read_label_png, write_label_png, LabelMap};
use semsplat::scene::ply::read_ply;
use semsplat::scene::Gaussians;

/// `train` on the room `d`, from its init, into `out`.
fn train_args(d: &str, out: &str) -> Vec<String> {
    common::cli::train_args(d, &format!("{d}/init.ply"), out)
}

/// A tiny synth room of four views at 48x36 in a temp folder, and the room's path.
fn tiny_room() -> (tempfile::TempDir, String) {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("room");
    synth_tiny(&d, 4, (48, 36));
    let d = d.to_str().unwrap().to_string();
    (tmp, d)
}

fn run(args: &[String]) -> Output {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    semsplat(&refs)
}

/// Trains the tiny room `d` for 30 iterations (at most 8000 Gaussians, a checkpoint every
/// 10) into `out`, with its report at `report`; asserts that it succeeded.
fn train_30_iterations(d: &str, out: &Path, report: &Path) {
    let mut args = train_args(d, out.to_str().unwrap());
    args.extend(
        [
            "--iters",
            "30",
            "--max-gaussians",
            "8000",
            "--checkpoint-every",
            "10",
            "--report",
            report.to_str().unwrap(),
        ]
        .map(String::from),
    );
    let r = run(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
}

/// The trained scene `g` has logits, and every class it gives is one of the class table
/// `dir/trained.classes.json`'s, with a confidence in [0, 1]; some Gaussian has a class.
fn check_classes_against_the_table(g: &Gaussians, dir: &Path) {
    let sem = g.semantics.as_ref().expect("logits in the output");
    assert!(
        sem.channels >= 2 && sem.channels <= 6,
        "{} channels",
        sem.channels
    );
    let classes = g.class_ids.as_ref().unwrap();
    let conf = g.class_conf.as_ref().unwrap();
    let table: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("trained.classes.json")).unwrap()).unwrap();
    let ids: Vec<i64> = table["classes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["id"].as_i64().unwrap())
        .collect();
    for (c, p) in classes.iter().zip(conf) {
        assert!(
            *c == -1 || ids.contains(&(*c as i64)),
            "class {c} not in the table"
        );
        assert!((0.0..=1.0).contains(p));
    }
    assert!(classes.iter().any(|&c| c >= 0));
}

/// `eval` scores the trained scene `out` on the room `d`, RGB included.
fn check_eval_scores_the_trained_scene(d: &str, out: &Path) {
    let e = semsplat(&[
        "eval",
        "--scene",
        out.to_str().unwrap(),
        "--cameras",
        &format!("{d}/cameras.json"),
        "--labels",
        &format!("{d}/labels"),
        "--images",
        &format!("{d}/images"),
        "--views",
        "all",
    ]);
    assert!(e.status.success(), "{}", String::from_utf8_lossy(&e.stderr));
    let text = String::from_utf8_lossy(&e.stdout);
    assert!(text.contains("mIoU") && text.contains("PSNR"), "{text}");
}

/// The training report counts the init's Gaussians, has a log and finite stage timings.
fn check_train_report(report: &Path, init: &Gaussians) {
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(report).unwrap()).unwrap();
    assert_eq!(
        rep["initial_gaussians"].as_u64().unwrap() as usize,
        init.len()
    );
    assert!(!rep["log"].as_array().unwrap().is_empty());
    // Full training starts from Gaussian Semantics' small random logits.
    assert_eq!(rep["logits_start"], "random");
    for key in ["forward_ms", "loss_ms", "backward_ms", "optimizer_ms"] {
        let v = rep["stage_ms_per_iteration"][key].as_f64().unwrap();
        assert!(v.is_finite() && v >= 0.0, "{key}: {v}");
    }
}

#[test]
fn train_writes_classes_logits_checkpoints_and_a_report() {
    let (tmp, d) = tiny_room();
    let d = d.as_str();
    let out = tmp.path().join("trained.ply");
    let report = tmp.path().join("train.json");
    train_30_iterations(d, &out, &report);
    let g = read_ply(&out).unwrap();
    let init = read_ply(Path::new(&format!("{d}/init.ply"))).unwrap();
    assert!(g.len() <= 8000);
    check_classes_against_the_table(&g, tmp.path());
    // Checkpoints are read as the final scene is: classes from their logits, the table beside.
    for it in [10, 20] {
        let checkpoint = tmp.path().join(format!("trained.iter{it}.ply"));
        let c = read_ply(&checkpoint).unwrap();
        let classes = c.class_ids.as_ref().expect("a checkpoint's classes");
        assert!(classes.iter().any(|&k| k >= 0));
        assert!(tmp
            .path()
            .join(format!("trained.iter{it}.classes.json"))
            .is_file());
    }
    check_eval_scores_the_trained_scene(d, &out);
    check_train_report(&report, &init);
}

#[test]
fn semantics_only_keeps_the_geometry() {
    let (tmp, d) = tiny_room();
    let d = d.as_str();
    let out = tmp.path().join("sem.ply");
    let mut args = train_args(d, out.to_str().unwrap());
    args[8] = format!("{d}/scene.ply");
    let report = tmp.path().join("sem.json");
    args.extend(["--iters", "15", "--semantics-only", "--report"].map(String::from));
    args.push(report.to_str().unwrap().into());
    let r = run(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    // The logits alone start uniform (docs/joint-training.md).
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(rep["logits_start"], "uniform");
    let g = read_ply(&out).unwrap();
    let scene = read_ply(Path::new(&format!("{d}/scene.ply"))).unwrap();
    assert_eq!(g.means, scene.means);
    assert_eq!(g.log_scales, scene.log_scales);
    assert_eq!(g.sh, scene.sh);
    assert_eq!(g.opacity_logits, scene.opacity_logits);
}

/// `--semantics-only` without `--images`: the logits learn from the label maps alone, so
/// they come out bit for bit as with the images (deterministic accumulation; the photometric
/// loss reaches no logit), and the log's photometric values are null, not zeros.
#[test]
fn semantics_only_trains_without_images() {
    let (tmp, d) = tiny_room();
    let d = d.as_str();
    let train = |out: &str, images: bool, deterministic: bool| {
        let out = tmp.path().join(out);
        let report = out.with_extension("json");
        let mut args = train_args(d, out.to_str().unwrap());
        args[8] = format!("{d}/scene.ply");
        if !images {
            args.drain(1..3);
        }
        args.extend(["--iters", "12", "--semantics-only"].map(String::from));
        if deterministic {
            args.push("--deterministic".into());
        }
        args.extend(["--report".into(), report.to_str().unwrap().into()]);
        let r = run(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let rep: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
        (
            read_ply(&out).unwrap(),
            rep["log"].as_array().unwrap().clone(),
        )
    };
    let (with, with_log) = train("with.ply", true, true);
    let (without, without_log) = train("without.ply", false, true);
    let logits = |g: &Gaussians| g.semantics.as_ref().unwrap().logits.clone();
    assert_eq!(logits(&with), logits(&without));
    assert_eq!(with.class_ids, without.class_ids);
    let last = |log: &[serde_json::Value]| log.last().unwrap().clone();
    assert!(last(&with_log)["psnr"].as_f64().unwrap() > 5.0);
    for key in ["l1", "ssim", "psnr"] {
        assert!(
            last(&without_log)[key].is_null(),
            "{key}: {}",
            last(&without_log)[key]
        );
    }
    assert_eq!(last(&with_log)["ce"], last(&without_log)["ce"]);
    assert!(last(&without_log)["ce"].as_f64().unwrap() > 0.0);
    // The default backward (float sums) too: its semantic-only kernels bind the colour
    // gradient they never read, a placeholder here.
    let (floats, floats_log) = train("floats.ply", false, false);
    assert!(last(&floats_log)["psnr"].is_null());
    let classes = floats.class_ids.as_ref().unwrap();
    let agree = (classes.iter().zip(without.class_ids.as_ref().unwrap()))
        .filter(|(a, b)| a == b)
        .count();
    assert!(
        agree * 10 > classes.len() * 9,
        "{agree} of {}",
        classes.len()
    );

    // Training the geometry and colours needs the images.
    let mut args = train_args(d, tmp.path().join("never.ply").to_str().unwrap());
    args.drain(1..3);
    let r = run(&args);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("--images"), "{err}");
    assert!(!tmp.path().join("never.ply").exists());
}

#[test]
fn bad_input_gives_a_clear_error_and_no_output() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("room");
    synth_tiny(&d, 4, (48, 36));
    let ds = d.to_str().unwrap();
    let out = tmp.path().join("never.ply");
    let outs = out.to_str().unwrap();

    // No images folder.
    let mut args = train_args(ds, outs);
    args[2] = format!("{ds}/nothing_here");
    args.extend(["--iters", "5"].map(String::from));
    let r = run(&args);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("no image for camera"));

    // Semantics alone without their loss would write the scene it started from.
    let mut args = train_args(ds, outs);
    args.extend(["--iters", "5", "--semantics-only", "--lambda-sem", "0"].map(String::from));
    let r = run(&args);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("trains nothing"));

    // More Gaussians than allowed.
    let mut args = train_args(ds, outs);
    args.extend(["--iters", "5", "--max-gaussians", "10"].map(String::from));
    let r = run(&args);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("more than --max-gaussians"));

    // An image of the wrong size.
    let first = std::fs::read_dir(d.join("images"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    image::RgbImage::new(10, 10).save(&first).unwrap();
    let mut args = train_args(ds, outs);
    args.extend(["--iters", "5"].map(String::from));
    let r = run(&args);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        err.contains("is 10x10, but camera") && err.contains("the size its cameras file gives"),
        "{err}"
    );
    image::RgbImage::new(48, 36).save(&first).unwrap();

    // Label maps that are a half-size copy scale their cameras to 24x18: a full-size image
    // is then at odds with its label map, and the message says so.
    for entry in std::fs::read_dir(d.join("labels")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "png") {
            let full = read_label_png(&path).unwrap();
            let half = LabelMap {
                width: full.width / 2,
                height: full.height / 2,
                labels: (0..full.height / 2)
                    .flat_map(|y| (0..full.width / 2).map(move |x| (x, y)))
                    .map(|(x, y)| full.labels[(2 * y * full.width + 2 * x) as usize])
                    .collect(),
            };
            write_label_png(&path, &half).unwrap();
        }
    }
    let r = run(&args);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        err.contains("is 48x36, but camera")
            && err.contains("renders at 24x18, its label map's size")
            && err.contains("its cameras file gives 48x36")
            && err.contains("must have one size"),
        "{err}"
    );

    assert!(!out.exists(), "a failed run left {}", out.display());
}

#[test]
fn training_starts_from_a_fusion_of_its_scene() {
    // Fuse the room's scene, then train its logits from the fused classes: after one
    // semantics-only step with a tiny learning rate the classes are still the fused ones
    // (where the fusion gave one), so the logits started there and not from random values.
    let (tmp, d) = tiny_room();
    let d = d.as_str();
    let fused = tmp.path().join("fused.ply");
    let fused = fused.to_str().unwrap();
    fuse_synth(Path::new(d), &["--out", fused]);
    let scene = format!("{d}/scene.ply");
    let out = tmp.path().join("trained.ply");
    let mut args = train_args(d, out.to_str().unwrap());
    let at = args.iter().position(|a| a == "--init").unwrap();
    args[at + 1] = scene.clone();
    let extra = [
        "--init-semantics-from",
        fused,
        "--semantics-only",
        "--iters",
        "1",
        "--lr-logits",
        "0.0001",
        "--no-densify",
    ];
    args.extend(extra.map(String::from));
    let r = run(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let said = String::from_utf8_lossy(&r.stderr);
    assert!(
        !said.contains("no `class_conf`"),
        "a fused PLY has it: {said}"
    );
    let want = read_ply(Path::new(fused)).unwrap().class_ids.unwrap();
    let got = read_ply(&out).unwrap().class_ids.unwrap();
    let classed: Vec<usize> = (0..want.len()).filter(|&i| want[i] >= 0).collect();
    assert!(
        classed.len() > want.len() / 2,
        "{} of {} fused",
        classed.len(),
        want.len()
    );
    let same = classed.iter().filter(|&&i| got[i] == want[i]).count();
    assert_eq!(
        same,
        classed.len(),
        "trained classes that left the fused ones"
    );
    // Segment consensus gives the Gaussians no view saw their neighbours' class at
    // confidence 0: they keep it too (they had started uniform and ended unclassed).
    let consensus = tmp.path().join("consensus.ply");
    let consensus = consensus.to_str().unwrap();
    fuse_synth(
        Path::new(d),
        &["--out", consensus, "--method", "segment-consensus"],
    );
    let f = read_ply(Path::new(consensus)).unwrap();
    let (want, conf) = (f.class_ids.unwrap(), f.class_conf.unwrap());
    let filled = (0..want.len())
        .filter(|&i| want[i] >= 0 && conf[i] == 0.0)
        .count();
    assert!(filled > 0, "no Gaussian took its neighbours' class");
    let at = args.iter().position(|a| a == fused).unwrap();
    args[at] = consensus.to_string();
    let r = run(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let got = read_ply(&out).unwrap().class_ids.unwrap();
    let left = (0..want.len()).filter(|&i| want[i] >= 0 && got[i] != want[i]);
    assert_eq!(left.count(), 0, "of {filled} filled from neighbours");
    args[at] = fused.to_string();
    // A PLY of classes without confidences (a synth scene) starts at a fixed one, said so.
    let at = args.iter().position(|a| a == fused).unwrap();
    args[at] = scene.clone();
    let r = run(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let said = String::from_utf8_lossy(&r.stderr);
    assert!(said.contains("no `class_conf`"), "{said}");

    // A PLY of other Gaussians is refused before any work, naming the option.
    let mut args = train_args(d, tmp.path().join("bad.ply").to_str().unwrap());
    let init_cloud = format!("{d}/init.ply");
    args.extend(["--init-semantics-from", &init_cloud, "--iters", "1"].map(String::from));
    let r = run(&args);
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("--init-semantics-from"), "{err}");
    assert!(!tmp.path().join("bad.ply").exists());
}

/// A checkpoint renders every labeled view between two iterations: the training after it
/// must not see that (the same bytes as a run without checkpoints, under --deterministic).
#[test]
fn checkpoints_do_not_change_the_training() {
    let (tmp, d) = tiny_room();
    let d = d.as_str();
    let trained = |name: &str, extra: &[&str]| {
        let out = tmp.path().join(name);
        let mut args = train_args(d, out.to_str().unwrap());
        args.extend(["--iters", "6", "--deterministic"].map(String::from));
        args.extend(extra.iter().map(|s| s.to_string()));
        let r = run(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        std::fs::read(out).unwrap()
    };
    let plain = trained("plain.ply", &[]);
    let with_checkpoints = trained("checked.ply", &["--checkpoint-every", "2"]);
    assert!(
        plain == with_checkpoints,
        "a checkpoint changed the training"
    );
}

/// An iteration on a view without a label map logs no cross-entropy (null, not a perfect
/// 0.0); iterations on the labeled view log their cross-entropy.
#[test]
fn the_log_has_no_cross_entropy_for_views_without_labels() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join("room");
    synth_tiny(&d, 4, (48, 36));
    let maps = common::cli::label_pngs(&d);
    for map in &maps[1..] {
        std::fs::remove_file(map).unwrap();
    }
    let ds = d.to_str().unwrap();
    let report = tmp.path().join("train.json");
    let mut args = train_args(ds, tmp.path().join("t.ply").to_str().unwrap());
    args.pop(); // every view, not only the train ones: more of them lack labels
    args.extend(["--iters", "80", "--report", report.to_str().unwrap()].map(String::from));
    let r = run(&args);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let ce: Vec<&serde_json::Value> = rep["log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| &l["ce"])
        .collect();
    assert!(ce.iter().any(|c| c.is_null()), "{ce:?}");
    assert!(
        ce.iter().any(|c| c.as_f64().is_some_and(|v| v > 0.0)),
        "{ce:?}"
    );

    // With --semantics-only (appearance frozen) such views teach nothing: they are left out,
    // and every logged step has its cross-entropy.
    args.extend(["--semantics-only"].map(String::from));
    let r = run(&args);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(err.contains("have no label map and are left out"), "{err}");
    // ...naming them (by their cameras' names, the maps' stems).
    let stem = |p: &std::path::PathBuf| p.file_stem().unwrap().to_string_lossy().into_owned();
    let removed: Vec<String> = maps[1..].iter().map(stem).collect();
    assert!(err.contains(&removed.join(", ")), "{err}");
    let rep: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let log = rep["log"].as_array().unwrap();
    assert!(log.iter().all(|l| l["ce"].as_f64().is_some()), "{log:?}");
}
