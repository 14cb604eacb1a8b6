//! What a run reads and what it writes, checked against each other before any work: an
//! output that is one of the run's inputs, lies in a folder it reads with its subfolders, or
//! is another of its outputs is refused with nothing written; a fusion refuses before its
//! first file; results that say nothing (no Gaussian classed, no labeled pixel) are errors;
//! a fused scene carries only its own fusion's semantics.

mod common;

use std::path::{Path, PathBuf};

use common::cli::{arg_in, fails, fuse_synth, fuse_synth_fails, ok, synth_tiny};
use semsplat::scene::ply::{read_ply, write_ply};
use semsplat::train::trainer::{with_initial_logits, LogitInit};

/// A temporary folder holding the tiny room in `room/` (3 train views at 32x24).
fn tiny_room() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth_tiny(&room, 3, (32, 24));
    (tmp, room)
}

/// The file names in `dir` (not recursing), sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = (std::fs::read_dir(dir).unwrap())
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn outputs_that_are_inputs_or_each_other_are_refused_before_any_work() {
    let (tmp, room) = tiny_room();
    let (scene, cameras) = (
        std::fs::read(room.join("scene.ply")).unwrap(),
        listing(&room),
    );
    let at = |f: &str| arg_in(tmp.path(), f);
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["--out".into(), arg_in(&room, "scene.ply")],
            "is the run's --scene",
        ),
        (
            vec![
                "--out".into(),
                at("f.ply"),
                "--report".into(),
                arg_in(&room, "cameras.json"),
            ],
            "would destroy that input",
        ),
        (
            vec!["--out".into(), arg_in(&room, "scene.classes.json")],
            "--scene's class table",
        ),
        (
            vec!["--out".into(), arg_in(&room, "labels/x.ply")],
            "inside the --labels folder",
        ),
        (
            vec![
                "--out".into(),
                at("f.ply"),
                "--render-views".into(),
                arg_in(&room, "labels/v"),
            ],
            "inside the --labels folder",
        ),
        (
            vec![
                "--out".into(),
                at("f.ply"),
                "--palette-ply".into(),
                at("f.ply"),
            ],
            "is also --out",
        ),
        (
            vec![
                "--out".into(),
                at("f.ply"),
                "--report".into(),
                at("f.classes.json"),
            ],
            "is also --out's class table",
        ),
        (vec!["--out".into(), at("new/")], "ends in '/'"),
    ];
    for (extra, expected) in cases {
        let extra: Vec<&str> = extra.iter().map(String::as_str).collect();
        let e = fuse_synth_fails(&room, &extra);
        assert!(e.contains(expected), "{extra:?}: {e}");
        assert_eq!(listing(tmp.path()), ["room"], "{extra:?} wrote something");
    }
    // eval's --json over the scene it scores.
    let scene_arg = arg_in(&room, "scene.ply");
    let e = fails(&[
        "eval",
        "--scene",
        &scene_arg,
        "--labels",
        &arg_in(&room, "labels"),
        "--json",
        &scene_arg,
    ]);
    assert!(e.contains("is the run's --scene"), "{e}");
    assert_eq!(std::fs::read(room.join("scene.ply")).unwrap(), scene);
    assert_eq!(listing(&room), cameras);
}

#[test]
fn a_refused_fusion_writes_nothing_and_a_fused_scene_holds_only_its_fusions_semantics() {
    let (tmp, room) = tiny_room();
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let at = |f: &str| arg_in(&out, f);
    // An unknown class to extract is found before the evidence is saved.
    let e = fuse_synth_fails(
        &room,
        &[
            "--out",
            &at("x.ply"),
            "--save-contrib",
            &at("A.npy"),
            "--extract",
            "nosuch",
        ],
    );
    assert!(e.contains("nosuch"), "{e}");
    assert!(listing(&out).is_empty(), "{:?}", listing(&out));

    // A trained scene's logits do not survive its fusion: `render --semantics` would draw
    // them through the fusion's class table.
    let trained = tmp.path().join("trained.ply");
    let g = read_ply(&room.join("scene.ply")).unwrap();
    write_ply(
        &trained,
        &with_initial_logits(&g, 3, LogitInit::SmallRandom, 1),
    )
    .unwrap();
    let fused = at("fused.ply");
    ok(&[
        "fuse",
        "--scene",
        trained.to_str().unwrap(),
        "--cameras",
        &arg_in(&room, "cameras.json"),
        "--labels",
        &arg_in(&room, "labels"),
        "--out",
        &fused,
    ]);
    let f = read_ply(Path::new(&fused)).unwrap();
    assert!(f.semantics.is_none());
    assert!(f.class_ids.unwrap().iter().any(|&c| c >= 0));
}

#[test]
fn fusions_that_class_nothing_are_errors() {
    let (tmp, room) = tiny_room();
    // Label maps of nothing but the ignore value.
    let blank = tmp.path().join("blank");
    std::fs::create_dir(&blank).unwrap();
    for entry in std::fs::read_dir(room.join("labels")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "png") {
            let map = image::open(&path).unwrap().to_luma8();
            let ignored =
                image::GrayImage::from_pixel(map.width(), map.height(), image::Luma([255]));
            ignored.save(blank.join(path.file_name().unwrap())).unwrap();
        }
    }
    let out = arg_in(tmp.path(), "x.ply");
    let e = fails(&[
        "fuse",
        "--scene",
        &arg_in(&room, "scene.ply"),
        "--cameras",
        &arg_in(&room, "cameras.json"),
        "--labels",
        blank.to_str().unwrap(),
        "--out",
        &out,
    ]);
    assert!(e.contains("hold no class"), "{e}");
    // Cameras of another frame: every camera 100 units away, seeing no Gaussian.
    let mut cams: serde_json::Value =
        serde_json::from_slice(&std::fs::read(room.join("cameras.json")).unwrap()).unwrap();
    for cam in cams["cameras"].as_array_mut().unwrap() {
        let t = &mut cam["world_to_camera"][2][3];
        *t = serde_json::json!(t.as_f64().unwrap() - 100.0);
    }
    let far = tmp.path().join("far.json");
    std::fs::write(&far, serde_json::to_vec(&cams).unwrap()).unwrap();
    let e = fails(&[
        "fuse",
        "--scene",
        &arg_in(&room, "scene.ply"),
        "--cameras",
        far.to_str().unwrap(),
        "--labels",
        &arg_in(&room, "labels"),
        "--out",
        &out,
    ]);
    assert!(e.contains("no Gaussian took a class"), "{e}");
    assert!(!Path::new(&out).exists());
    // The same scene and labels fuse with their own cameras.
    fuse_synth(&room, &["--out", &out]);
}
