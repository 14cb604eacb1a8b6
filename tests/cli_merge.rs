//! `fuse --shard K/N` + `semsplat merge` give what one `fuse` gives, byte for byte, and
//! merge refuses parts that do not belong together.

mod common;

use common::cli::{
    arg_in, fails, fails_owned, fuse_synth, fuse_synth_fails, ok, ok_owned, read_json, synth_tiny,
};

use std::path::Path;

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The output options shared by `fuse` and `merge`, every file named `{tag}.*` in `d`.
fn output_args(d: &Path, tag: &str) -> Vec<String> {
    vec![
        "--out".to_string(),
        arg_in(d, &format!("{tag}.ply")),
        "--palette-ply".into(),
        arg_in(d, &format!("{tag}.palette.ply")),
        "--report".into(),
        arg_in(d, &format!("{tag}.json")),
        "--save-contrib".into(),
        arg_in(d, &format!("{tag}.contrib.npy")),
        "--save-membership".into(),
        arg_in(d, &format!("{tag}.membership.npy")),
    ]
}

/// One `fuse` of every view, into `single.*`.
fn fuse_single(d: &Path, inputs: &[&str], method: &[&str]) {
    let mut single = vec!["fuse"];
    single.extend_from_slice(inputs);
    single.extend_from_slice(method);
    let single_out = output_args(d, "single");
    single.extend(single_out.iter().map(String::as_str));
    ok(&single);
}

/// `fuse --shard K/3` for K = 0, 1, 2 into `partK.npy`; returns the views their manifests
/// list, after checking each manifest names its shard.
fn fuse_three_shards(d: &Path, inputs: &[&str], method: &[&str]) -> Vec<String> {
    let mut views = Vec::new();
    for k in 0..3 {
        let (shard, part) = (format!("{k}/3"), arg_in(d, &format!("part{k}.npy")));
        let mut args = vec!["fuse"];
        args.extend_from_slice(inputs);
        args.extend_from_slice(method);
        args.extend_from_slice(&["--shard", &shard, "--out", &part]);
        ok(&args);
        let manifest = read_json(&d.join(format!("part{k}.manifest.json")));
        assert_eq!(manifest["shard"]["index"], k);
        for v in manifest["views"].as_array().unwrap() {
            views.push(v.as_str().unwrap().to_string());
        }
    }
    views
}

/// The shards cover every labeled view exactly once.
fn assert_shards_cover_every_labeled_view_once(d: &Path, mut views: Vec<String>) {
    views.sort();
    let mut labeled: Vec<String> = std::fs::read_dir(d.join("labels"))
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().into_string().unwrap();
            name.strip_suffix(".png").map(str::to_string)
        })
        .collect();
    labeled.sort();
    assert_eq!(views, labeled);
}

/// `merge` of the three parts (in a scrambled order, in chunks that do not divide the
/// Gaussian count) into `merged.*`.
fn merge_scrambled_parts(d: &Path, scene: &str) {
    let (p0, p1, p2) = (
        arg_in(d, "part0.npy"),
        arg_in(d, "part1.npy"),
        arg_in(d, "part2.npy"),
    );
    let mut merge = vec!["merge", &p2, &p0, &p1, "--scene", scene];
    merge.extend_from_slice(&["--chunk-gaussians", "777"]);
    let merged_out = output_args(d, "merged");
    merge.extend(merged_out.iter().map(String::as_str));
    ok(&merge);
}

/// `merged.*` are `single.*` byte for byte, with the same report, nothing of `fuse`'s
/// scratch file is left, and the result is not empty.
fn assert_merged_is_the_single_run(d: &Path) {
    for (a, b) in [
        ("single.ply", "merged.ply"),
        ("single.palette.ply", "merged.palette.ply"),
        ("single.classes.json", "merged.classes.json"),
        ("single.contrib.npy", "merged.contrib.npy"),
        ("single.membership.npy", "merged.membership.npy"),
    ] {
        assert!(bytes(&d.join(a)) == bytes(&d.join(b)), "{a} != {b}");
    }
    // `fuse` assigned on the GPU and spilled its evidence rows to a scratch file for the
    // matrix outputs; `merge` held them in memory. Nothing of the scratch file is left.
    let hidden: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with('.'))
        .collect();
    assert!(hidden.is_empty(), "left behind: {hidden:?}");
    let (single_report, merged_report) = (
        read_json(&d.join("single.json")),
        read_json(&d.join("merged.json")),
    );
    assert_eq!(single_report["per_class"], merged_report["per_class"]);
    assert_eq!(single_report["method"], merged_report["method"]);
    // Something was classified, so equal files are not two empty results.
    let unseen = &single_report["per_class"]
        .as_array()
        .unwrap()
        .last()
        .unwrap()["gaussians"];
    assert!(unseen.as_u64().unwrap() < single_report["gaussians"].as_u64().unwrap() / 2);
}

/// Fuses the room once and in 3 shards merged (in a scrambled order, in chunks that do not
/// divide the Gaussian count) with the same outputs, and compares them.
fn shards_merge_to_the_single_run(method: &[&str]) {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 6, (48, 32));
    let (scene, cameras, labels) = (
        arg_in(d, "scene.ply"),
        arg_in(d, "cameras.json"),
        arg_in(d, "labels"),
    );
    let inputs = [
        "--scene",
        &scene,
        "--cameras",
        &cameras,
        "--labels",
        &labels,
    ];
    fuse_single(d, &inputs, method);
    let views = fuse_three_shards(d, &inputs, method);
    assert_shards_cover_every_labeled_view_once(d, views);
    merge_scrambled_parts(d, &scene);
    assert_merged_is_the_single_run(d);
}

#[test]
fn flashsplat_shards_merge_to_the_single_run_byte_for_byte() {
    shards_merge_to_the_single_run(&["--method", "flashsplat"]);
}

#[test]
fn vote_shards_merge_to_the_single_run_byte_for_byte() {
    shards_merge_to_the_single_run(&["--method", "vote"]);
}

#[test]
fn merge_refuses_parts_that_do_not_belong_together() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 6, (48, 32));
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    let (scene, cameras) = (p("scene.ply"), p("cameras.json"));
    let shard = |k: &str, method: &str, out: &str| {
        fuse_synth(d, &["--method", method, "--shard", k, "--out", out])
    };
    let (a0, a1, v1) = (p("a0.npy"), p("a1.npy"), p("v1.npy"));
    shard("0/2", "flashsplat", &a0);
    shard("1/2", "flashsplat", &a1);
    shard("1/2", "vote", &v1);
    let out = p("m.ply");
    let merge = |parts: &[&str]| {
        let mut args = vec!["merge"];
        args.extend_from_slice(parts);
        args.extend_from_slice(&["--scene", &scene, "--out", &out]);
        fails(&args)
    };

    let err = merge(&[&a0, &v1]);
    assert!(
        err.contains("different inputs") && err.contains("method"),
        "{err}"
    );
    let err = merge(&[&a0]);
    assert!(err.contains("missing shard(s) 1/2"), "{err}");
    let err = merge(&[&a0, &a1, &a1]);
    assert!(err.contains("shard 1/2 is given twice"), "{err}");
    // Part 0 copied under shard 1's index (its manifest edited): its views twice, shard
    // 1's in none.
    let copy = p("c1.npy");
    std::fs::copy(&a0, &copy).unwrap();
    let manifest = std::fs::read_to_string(d.join("a0.manifest.json")).unwrap();
    let edited = manifest.replacen("\"index\": 0", "\"index\": 1", 1);
    assert_ne!(edited, manifest);
    std::fs::write(d.join("c1.manifest.json"), edited).unwrap();
    let err = merge(&[&a0, &copy]);
    assert!(err.contains("is in two parts"), "{err}");
    // A part that is not there is named as such (it was blamed on its manifest).
    let err = merge(&[&a0, &p("a9.npy")]);
    assert!(err.contains("a9.npy: no such file"), "{err}");
    // A part given to `fuse --contrib` is pointed to merge (not read as a matrix of sums).
    let err = fails(&["fuse", "--scene", &scene, "--contrib", &a0, "--out", &out]);
    assert!(
        err.contains("part of a sharded fusion") && err.contains("merge"),
        "{err}"
    );

    // A class to extract that no part holds is named before the parts are summed.
    let err = fails(&[
        "merge",
        &a0,
        &a1,
        "--scene",
        &scene,
        "--extract",
        "kite",
        "--out",
        &out,
    ]);
    assert!(err.contains("no class 'kite'"), "{err}");

    // Another scene (here: another file) is refused by its digest.
    let err = fails(&["merge", &a0, &a1, "--scene", &cameras, "--out", &out]);
    assert!(
        err.contains("not the scene the parts were fused from"),
        "{err}"
    );

    // Another shard's part under this one's manifest (the same shape, other sums) is
    // refused by the part's digest, as is a part whose sums were edited.
    let data = bytes(Path::new(&a1));
    std::fs::copy(&a0, &a1).unwrap();
    let err = merge(&[&a0, &a1]);
    assert!(err.contains("not the part its manifest"), "{err}");
    let mut edited = data.clone();
    *edited.last_mut().unwrap() ^= 1;
    std::fs::write(&a1, &edited).unwrap();
    let err = merge(&[&a0, &a1]);
    assert!(err.contains("not the part its manifest"), "{err}");

    // A part cut short in transfer is refused, not read as zeros.
    std::fs::write(&a1, &data[..data.len() - 8]).unwrap();
    let err = merge(&[&a0, &a1]);
    assert!(err.contains("truncated"), "{err}");

    // A part without its manifest is refused.
    std::fs::remove_file(d.join("a0.manifest.json")).unwrap();
    let err = merge(&[&a0, &a1]);
    assert!(err.contains("manifest"), "{err}");
    assert!(!Path::new(&out).exists(), "no output on refusal");

    // Float atomics have no exact parts.
    let err = fuse_synth_fails(d, &["--shard", "0/2", "--float-atomics", "--out", &a0]);
    assert!(err.contains("--float-atomics"), "{err}");
}

/// `--depth-tol` is part of a part's key only for the methods that read it: FlashSplat
/// shards given different tolerances merge, occlusion-checked vote shards are refused.
#[test]
fn depth_tolerance_matters_to_merge_only_where_the_method_reads_it() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 4, (48, 32));
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    let scene = p("scene.ply");
    let shard = |k: &str, method: &[&str], tol: &str, out: &str| {
        let mut args = method.to_vec();
        args.extend_from_slice(&["--depth-tol", tol, "--shard", k, "--out", out]);
        fuse_synth(d, &args)
    };
    let merge = |a: &str, b: &str, out: &str| {
        vec![
            "merge".to_string(),
            a.into(),
            b.into(),
            "--scene".into(),
            scene.clone(),
            "--out".into(),
            out.into(),
        ]
    };
    let (f0, f1) = (p("f0.npy"), p("f1.npy"));
    shard("0/2", &["--method", "flashsplat"], "0.05", &f0);
    shard("1/2", &["--method", "flashsplat"], "0.2", &f1);
    let args = merge(&f0, &f1, &p("f.ply"));
    ok_owned(&args);

    let occlusion = ["--method", "vote", "--occlusion"];
    let (o0, o1) = (p("o0.npy"), p("o1.npy"));
    shard("0/2", &occlusion, "0.05", &o0);
    shard("1/2", &occlusion, "0.2", &o1);
    let args = merge(&o0, &o1, &p("o.ply"));
    let err = fails_owned(&args);
    assert!(err.contains("depth_tolerance"), "{err}");
}

/// A label map written again between two shards' runs (here its classes 0 and 1 swapped)
/// is told apart by its contents, whatever its size; label maps at half the cameras'
/// resolution (which scale the views) still merge with `--cameras` naming the file the
/// shards were given.
#[test]
fn merge_knows_label_contents_and_the_cameras_file_of_scaled_views() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 4, (64, 48));
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    let (scene, cameras) = (p("scene.ply"), p("cameras.json"));
    let maps = common::cli::label_pngs(d);
    // Half-resolution copies of every map.
    for map in &maps {
        let img = image::open(map).unwrap().to_luma8();
        let half = image::imageops::resize(&img, 32, 24, image::imageops::FilterType::Nearest);
        half.save(map).unwrap();
    }
    let shard = |k: &str, out: &str| {
        fuse_synth(d, &["--method", "vote", "--shard", k, "--out", out]);
    };
    let (a0, a1) = (p("a0.npy"), p("a1.npy"));
    shard("0/2", &a0);
    shard("1/2", &a1);
    let merged = p("m.ply");
    let views = p("views");
    ok(&[
        "merge",
        &a0,
        &a1,
        "--scene",
        &scene,
        "--cameras",
        &cameras,
        "--render-views",
        &views,
        "--out",
        &merged,
    ]);

    let first = &maps[0];
    let mut img = image::open(first).unwrap().to_luma8();
    for v in img.pixels_mut() {
        v.0[0] = match v.0[0] {
            0 => 1,
            1 => 0,
            other => other,
        };
    }
    img.save(first).unwrap();
    shard("1/2", &a1);
    let err = fails(&["merge", &a0, &a1, "--scene", &scene, "--out", &p("n.ply")]);
    assert!(err.contains("labels"), "{err}");
}

/// `merge --help` describes what merge writes: the options it shares with `fuse` do not
/// speak of segment consensus, shards or a fused scene's class, which merge never has.
#[test]
fn merge_help_speaks_only_of_what_merge_writes() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(["merge", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    for fuse_only in [
        "segment consensus",
        "`fuse --shard` only",
        "without --labels",
        "`segment`",
    ] {
        assert!(!help.contains(fuse_only), "'{fuse_only}' in: {help}");
    }
    assert!(
        help.contains("--out <OUT>") && help.contains("class_conf"),
        "{help}"
    );
}
