//! `fuse --shard K/N` + `semsplat merge` give what one `fuse` gives, byte for byte, and
//! merge refuses parts that do not belong together.

mod common;

use common::cli::{fails, fuse_synth, fuse_synth_fails, ok, synth_tiny};

use std::path::Path;

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&bytes(path)).unwrap()
}

/// Fuses the room once and in 3 shards merged (in a scrambled order, in chunks that do not
/// divide the Gaussian count) with the same outputs, and compares them.
fn shards_merge_to_the_single_run(method: &[&str]) {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d, 6, (48, 32));
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    let (scene, cameras, labels) = (p("scene.ply"), p("cameras.json"), p("labels"));
    let inputs = [
        "--scene",
        &scene,
        "--cameras",
        &cameras,
        "--labels",
        &labels,
    ];
    let outputs = |tag: &str| {
        vec![
            "--out".to_string(),
            p(&format!("{tag}.ply")),
            "--palette-ply".into(),
            p(&format!("{tag}.palette.ply")),
            "--report".into(),
            p(&format!("{tag}.json")),
            "--save-contrib".into(),
            p(&format!("{tag}.contrib.npy")),
            "--save-membership".into(),
            p(&format!("{tag}.membership.npy")),
        ]
    };
    let mut single = vec!["fuse"];
    single.extend_from_slice(&inputs);
    single.extend_from_slice(method);
    let single_out = outputs("single");
    single.extend(single_out.iter().map(String::as_str));
    ok(&single);

    let mut views = Vec::new();
    for k in 0..3 {
        let (shard, part) = (format!("{k}/3"), p(&format!("part{k}.npy")));
        let mut args = vec!["fuse"];
        args.extend_from_slice(&inputs);
        args.extend_from_slice(method);
        args.extend_from_slice(&["--shard", &shard, "--out", &part]);
        ok(&args);
        let manifest = json(&d.join(format!("part{k}.manifest.json")));
        assert_eq!(manifest["shard"]["index"], k);
        for v in manifest["views"].as_array().unwrap() {
            views.push(v.as_str().unwrap().to_string());
        }
    }
    // The shards cover every labeled view exactly once.
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

    let (p0, p1, p2) = (p("part0.npy"), p("part1.npy"), p("part2.npy"));
    let mut merge = vec!["merge", &p2, &p0, &p1, "--scene", &scene];
    merge.extend_from_slice(&["--chunk-gaussians", "777"]);
    let merged_out = outputs("merged");
    merge.extend(merged_out.iter().map(String::as_str));
    ok(&merge);

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
    let (single_report, merged_report) =
        (json(&d.join("single.json")), json(&d.join("merged.json")));
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

    // Another scene (here: another file) is refused by its digest.
    let err = fails(&["merge", &a0, &a1, "--scene", &cameras, "--out", &out]);
    assert!(
        err.contains("not the scene the parts were fused from"),
        "{err}"
    );

    // A part cut short in transfer is refused, not read as zeros.
    let data = bytes(Path::new(&a1));
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
