//! What a run reads and what it writes, checked against each other before any work: an
//! output that is one of the run's inputs, lies in a folder it reads with its subfolders, or
//! is another of its outputs is refused with nothing written; a fusion refuses before its
//! first file; results that say nothing (no Gaussian classed, no labeled pixel) are errors;
//! a fused scene carries only its own fusion's semantics.

mod common;

use std::path::{Path, PathBuf};

use common::cli::{
    arg_in, fails, fails_owned, fuse_synth, fuse_synth_fails, ok, ok_owned, synth_tiny,
};
use semsplat::scene::ply::{read_ply, write_ply};
use semsplat::train::trainer::{with_initial_logits, LogitInit};

/// A temporary folder holding the tiny room in `room/` (3 train views at 32x24).
fn tiny_room() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth_tiny(&room, 3, (32, 24));
    (tmp, room)
}

/// `dir/trained.ply`: the room's scene with logits of `channels` classes started as
/// `start`, as a `train` output holds them.
fn with_logits(room: &Path, dir: &Path, channels: usize, start: LogitInit) -> PathBuf {
    let trained = dir.join("trained.ply");
    let g = read_ply(&room.join("scene.ply")).unwrap();
    write_ply(&trained, &with_initial_logits(&g, channels, start, 1)).unwrap();
    trained
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
            "would replace that input",
        ),
        (
            vec!["--out".into(), arg_in(&room, "scene.classes.json")],
            "--scene's class table",
        ),
        (
            vec!["--out".into(), arg_in(&room, "labels/x.png")],
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
        // The label folder's class table beside it (the room's), and inside it (none yet:
        // the next run would take a file written there for its table).
        (
            vec![
                "--out".into(),
                at("f.ply"),
                "--report".into(),
                arg_in(&room, "classes.json"),
            ],
            "--labels folder's class table",
        ),
        (
            vec![
                "--out".into(),
                at("f.ply"),
                "--save-contrib".into(),
                arg_in(&room, "labels/classes.json"),
            ],
            "--labels folder's class table",
        ),
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

/// An output named by a link is checked where the write lands (a link without an image's
/// extension into the label folder replaced a label map; a dangling link to `--out` as
/// `--palette-ply` replaced the fused scene), a PLY written through a link has its class
/// table beside the link's target, and a name too long for its temp file is refused before
/// the work.
#[test]
fn outputs_named_by_links_are_checked_where_they_land() {
    let (tmp, room) = tiny_room();
    let d = tmp.path();
    let link = |name: &str, to: &Path| {
        std::os::unix::fs::symlink(to, d.join(name)).unwrap();
        arg_in(d, name)
    };
    let map = room.join("labels/train_0000.png");
    let map_bytes = std::fs::read(&map).unwrap();
    let into_labels = link("L", &map);
    let e = fuse_synth_fails(&room, &["--out", &into_labels]);
    assert!(e.contains("inside the --labels folder"), "{e}");
    let fused = arg_in(d, "a.ply");
    let to_fused = link("P", &d.join("a.ply"));
    let e = fuse_synth_fails(&room, &["--out", &fused, "--palette-ply", &to_fused]);
    assert!(e.contains("is also --out"), "{e}");
    let long = arg_in(d, &format!("{}.ply", "n".repeat(240)));
    let e = fuse_synth_fails(&room, &["--out", &long]);
    assert!(e.contains("too long to be written safely"), "{e}");
    assert_eq!(std::fs::read(&map).unwrap(), map_bytes);
    assert_eq!(listing(d), ["L", "P", "room"]);

    // An output named as the spilled evidence's scratch file once was (`--out`'s stem and
    // `.evidence`): creating its temp file truncated the scratch before it was read back.
    let (fused, contrib) = (arg_in(d, "b.ply"), arg_in(d, "b.evidence"));
    fuse_synth(&room, &["--out", &fused, "--save-membership", &contrib]);
    let saved = semsplat::util::npy::read_npy_f64(&d.join("b.evidence")).unwrap();
    assert!(saved.data.iter().any(|&v| v > 0.0), "no evidence saved");

    std::fs::create_dir(d.join("real")).unwrap();
    let through = link("T.ply", &d.join("real/t.ply"));
    fuse_synth(&room, &["--out", &through]);
    assert_eq!(listing(&d.join("real")), ["t.classes.json", "t.ply"]);
    assert!(!d.join("T.classes.json").exists());
}

/// Unmounts its folder when dropped (a failed assertion too), before the test's temp
/// folder is removed through it.
struct Unmount(PathBuf);

impl Drop for Unmount {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
    }
}

/// The room under a second mount point (a bind mount, as a container's volume mounted
/// twice gives): its scene and label folder are still the run's inputs there. Needs mount
/// permission (root, as CI runs); elsewhere it says so and checks nothing.
#[test]
fn inputs_under_a_second_mount_point_are_still_inputs() {
    let (tmp, room) = tiny_room();
    let bind = tmp.path().join("bind");
    std::fs::create_dir(&bind).unwrap();
    let mounted = std::process::Command::new("mount")
        .arg("--bind")
        .args([&room, &bind])
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !mounted {
        eprintln!("skipped: no permission to bind-mount here");
        return;
    }
    let _unmount = Unmount(bind.clone());
    let scene_bytes = std::fs::read(room.join("scene.ply")).unwrap();
    let e = fuse_synth_fails(&room, &["--out", &arg_in(&bind, "scene.ply")]);
    assert!(e.contains("is the run's --scene"), "{e}");
    let e = fuse_synth_fails(&room, &["--out", &arg_in(&bind, "labels/x.png")]);
    assert!(e.contains("inside the --labels folder"), "{e}");
    assert_eq!(std::fs::read(room.join("scene.ply")).unwrap(), scene_bytes);
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
    let trained = with_logits(&room, tmp.path(), 3, LogitInit::SmallRandom);
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

    // Segment consensus extracts by the classes it decided (its evidence rows are not its
    // decision): every Gaussian kept is of the class, and every one of the class is kept.
    let (whole, boxes) = (at("whole.ply"), at("box.ply"));
    let consensus = ["--method", "segment-consensus"];
    fuse_synth(&room, &[&consensus[..], &["--out", &whole]].concat());
    fuse_synth(
        &room,
        &[&consensus[..], &["--out", &boxes, "--extract", "box"]].concat(),
    );
    let box_id = 3; // the tiny room's box
    let whole = read_ply(Path::new(&whole)).unwrap().class_ids.unwrap();
    let boxes = read_ply(Path::new(&boxes)).unwrap().class_ids.unwrap();
    assert!(boxes.iter().all(|&c| c == box_id));
    assert_eq!(boxes.len(), whole.iter().filter(|&&c| c == box_id).count());
    assert!(!boxes.is_empty());
}

#[test]
fn runs_on_views_that_see_nothing_are_errors() {
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
    // Training and scoring on those cameras say so too.
    let (scene, labels) = (arg_in(&room, "scene.ply"), arg_in(&room, "labels"));
    let far = far.to_str().unwrap();
    let e = fails(&[
        "train",
        "--images",
        &arg_in(&room, "images"),
        "--labels",
        &labels,
        "--cameras",
        far,
        "--init",
        &scene,
        "--iters",
        "2",
        "--out",
        &out,
    ]);
    assert!(e.contains("no training view sees any"), "{e}");
    let e = fails(&[
        "eval",
        "--scene",
        &scene,
        "--cameras",
        far,
        "--labels",
        &labels,
    ]);
    assert!(e.contains("no view renders any Gaussian"), "{e}");
    // The same scene and labels fuse with their own cameras.
    fuse_synth(&room, &["--out", &out]);
}

/// The outputs of `bench --export`, `train`'s checkpoints and `--render-views` are checked
/// like the others; a trained scene with another scene's class table is refused by
/// `render --semantics`; `inspect` flags label maps of nothing but the ignore value.
#[test]
fn exports_checkpoints_and_view_folders_are_checked_too() {
    let (tmp, room) = tiny_room();
    let cameras = std::fs::read(room.join("cameras.json")).unwrap();
    let e = fails(&[
        "bench",
        "fuse",
        "--scene",
        room.to_str().unwrap(),
        "--views",
        "2",
        "--width",
        "16",
        "--height",
        "12",
        "--iters",
        "1",
        "--export",
        room.to_str().unwrap(),
    ]);
    assert!(
        e.contains("--export") && e.contains("would replace that input"),
        "{e}"
    );
    assert_eq!(std::fs::read(room.join("cameras.json")).unwrap(), cameras);
    // The scene as a file, its cameras beside it; exported elsewhere.
    let export = arg_in(tmp.path(), "export");
    ok(&[
        "bench",
        "render",
        "--scene",
        &arg_in(&room, "scene.ply"),
        "--iters",
        "1",
        "--json",
        "--export",
        &export,
    ]);
    assert_eq!(
        listing(Path::new(&export)),
        ["bench.json", "cameras.json", "scene.ply"]
    );
    std::fs::remove_dir_all(&export).unwrap();

    // Resuming from a checkpoint under the same --out would write over it.
    let (images, labels) = (arg_in(&room, "images"), arg_in(&room, "labels"));
    let checkpoint = arg_in(tmp.path(), "t.iter2.ply");
    std::fs::copy(room.join("scene.ply"), &checkpoint).unwrap();
    let e = fails(&[
        "train",
        "--images",
        &images,
        "--labels",
        &labels,
        "--init",
        &checkpoint,
        "--cameras",
        &arg_in(&room, "cameras.json"),
        "--iters",
        "4",
        "--checkpoint-every",
        "2",
        "--out",
        &arg_in(tmp.path(), "t.ply"),
    ]);
    assert!(
        e.contains("replaced by the checkpoint of iteration 2"),
        "{e}"
    );

    let e = fuse_synth_fails(
        &room,
        &[
            "--out",
            &arg_in(tmp.path(), "v.ply"),
            "--render-views",
            &arg_in(tmp.path(), "v.ply"),
        ],
    );
    assert!(e.contains("cannot share a path"), "{e}");
    assert_eq!(listing(tmp.path()), ["room", "t.iter2.ply"]);
}

/// `render --semantics` refuses a class table of another length than the logits, and gives
/// pixels whose logits tie no class; `inspect` flags maps of nothing but the ignore value.
#[test]
fn render_and_inspect_say_what_would_mislead() {
    let (tmp, room) = tiny_room();
    // Logits of 3 channels beside the room's 6-class table.
    let trained = with_logits(&room, tmp.path(), 3, LogitInit::SmallRandom);
    std::fs::copy(
        room.join("scene.classes.json"),
        tmp.path().join("trained.classes.json"),
    )
    .unwrap();
    let views = arg_in(tmp.path(), "views");
    let cameras = arg_in(&room, "cameras.json");
    // `render --semantics` of `scene` into `views`, with `extra` arguments.
    let render_semantics = |scene: &Path, extra: &[&str]| -> Vec<String> {
        let mut args = ["render", "--scene", scene.to_str().unwrap()]
            .into_iter()
            .chain(["--cameras", &cameras, "--semantics", "--out", &views])
            .map(str::to_owned)
            .collect::<Vec<_>>();
        args.extend(extra.iter().map(|a| a.to_string()));
        args
    };
    let e = fails_owned(&render_semantics(&trained, &[]));
    assert!(
        e.contains("3 semantic channels") && e.contains("lists"),
        "{e}"
    );
    // Uniform logits (untouched by training) tie everywhere: no class, not the last one.
    std::fs::remove_file(tmp.path().join("trained.classes.json")).unwrap();
    let trained = with_logits(&room, tmp.path(), 3, LogitInit::Uniform);
    ok_owned(&render_semantics(&trained, &["--views", "train_0000"]));
    let labels = image::open(Path::new(&views).join("train_0000.labels.png")).unwrap();
    assert!(labels.to_luma8().pixels().all(|p| p[0] == 255));

    let blank = tmp.path().join("blank");
    std::fs::create_dir(&blank).unwrap();
    image::GrayImage::from_pixel(4, 3, image::Luma([255]))
        .save(blank.join("a.png"))
        .unwrap();
    let out = common::cli::semsplat(&["inspect", blank.to_str().unwrap()]);
    assert!(!out.status.success());
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(
        report.contains("every pixel is the ignore value"),
        "{report}"
    );

    // A scene whose class table lacks a class its Gaussians carry (the floor, 0).
    let odd = tmp.path().join("odd.ply");
    std::fs::copy(room.join("scene.ply"), &odd).unwrap();
    let mut table = common::cli::read_json(&room.join("scene.classes.json"));
    let classes = table["classes"].as_array_mut().unwrap();
    classes.retain(|c| c["id"] != 0);
    std::fs::write(tmp.path().join("odd.classes.json"), table.to_string()).unwrap();
    let said = ok_owned(&render_semantics(&odd, &["--views", "train_0000"]));
    assert!(said.contains("does not list: 0;"), "{said}");

    // Cameras whose values parse but are no capture's.
    let mut cams = common::cli::read_json(Path::new(&cameras));
    cams["cameras"][0]["cx"] = serde_json::json!(-1e9);
    let odd_cameras = tmp.path().join("odd_cameras.json");
    std::fs::write(&odd_cameras, cams.to_string()).unwrap();
    let out = common::cli::semsplat(&["inspect", odd_cameras.to_str().unwrap()]);
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(
        !out.status.success() && report.contains("principal point"),
        "{report}"
    );
}

/// Runs whose result would mean nothing are errors (a scene of no Gaussians, label maps
/// with no label), and say what they chose: `--extract` names the class and its id, and
/// selecting from a fused scene reads the `--classes` given; `eval --truth` takes a scene
/// folder as `--scene` does.
#[test]
fn empty_inputs_are_errors_and_selections_name_their_class() {
    let (tmp, room) = tiny_room();
    let (d, p) = (tmp.path(), |f: &Path| f.to_str().unwrap().to_string());
    let cameras = arg_in(&room, "cameras.json");
    let fused = d.join("fused").join("fused.ply");
    fuse_synth(&room, &["--out", &p(&fused)]);

    let blank = d.join("blank");
    std::fs::create_dir(&blank).unwrap();
    for map in std::fs::read_dir(room.join("labels")).unwrap() {
        let name = map.unwrap().file_name();
        image::GrayImage::from_pixel(32, 24, image::Luma([255]))
            .save(blank.join(name))
            .unwrap();
    }
    let eval = |labels: &Path, extra: &[&str]| {
        let mut args = vec![
            "eval",
            "--scene",
            fused.to_str().unwrap(),
            "--cameras",
            &cameras,
        ];
        args.extend_from_slice(&["--labels", labels.to_str().unwrap(), "--views", "all"]);
        args.extend_from_slice(extra);
        args.iter().map(|a| a.to_string()).collect::<Vec<_>>()
    };
    let e = fails_owned(&eval(&blank, &[]));
    assert!(e.contains("nothing to score"), "{e}");
    let truth = p(&room);
    let scored = eval(&room.join("labels"), &["--truth", &truth]);
    let out = common::cli::semsplat(&scored.iter().map(String::as_str).collect::<Vec<_>>());
    let printed = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(printed.contains("3D accuracy"), "{printed}");
    // Half the Gaussians at -1: eval says they draw no class (they scored as if classed).
    let mut half = read_ply(&fused).unwrap();
    let classes = half.class_ids.as_mut().unwrap();
    let n = classes.len();
    classes[..n / 2].fill(-1);
    let unclassified = classes.iter().filter(|&&c| c == -1).count();
    let halved = d.join("fused").join("half.ply");
    write_ply(&halved, &half).unwrap();
    let mut halved_eval = eval(&room.join("labels"), &[]);
    halved_eval[2] = p(&halved); // --scene
    let said = ok_owned(&halved_eval);
    assert!(
        said.contains(&format!("{unclassified} of the scene's {n} Gaussians"))
            && said.contains("have no class (-1)")
            && !said.contains("3D accuracy counts them"),
        "{said} (no --truth: no 3D accuracy to speak of)"
    );

    let picked = ok_owned(&fuse_args(
        &room,
        &["--extract", "BALL", "--out", &arg_in(d, "b.ply")],
    ));
    assert!(picked.contains("class 'ball' (id 4)"), "{picked}");
    let e = fuse_synth_fails(
        &room,
        &["--extract", "ceiling", "--out", &arg_in(d, "c.ply")],
    );
    assert!(e.contains("classes the label maps use"), "{e}");
    // A fused scene without its sidecar selects through the table given.
    let bare = d.join("bare");
    std::fs::create_dir(&bare).unwrap();
    std::fs::copy(&fused, bare.join("fused.ply")).unwrap();
    let classes = arg_in(&room, "classes.json");
    let from_fused = [
        "fuse",
        "--scene",
        &arg_in(&bare, "fused.ply"),
        "--classes",
        &classes,
    ];
    let picked = ok(&[
        &from_fused[..],
        &["--extract", "ball", "--out", &arg_in(d, "f.ply")],
    ]
    .concat());
    assert!(picked.contains("class 'ball' (id 4)"), "{picked}");
    assert!(!picked.contains("no effect"), "{picked}");
    // Options of how views are fused read nothing here: likely --labels was forgotten.
    let picked = ok(&[
        &from_fused[..],
        &["--extract", "ball", "--method", "vote", "--train-only"],
        &["--out", &arg_in(d, "f2.ply")],
    ]
    .concat());
    assert!(
        picked.contains("note: --method, --train-only have no effect: without --labels"),
        "{picked}"
    );
    // A class of the table no Gaussian holds selects nothing: refused, nothing written.
    let none = arg_in(d, "none.ply");
    let e = fails(&[&from_fused[..], &["--extract", "ceiling", "--out", &none]].concat());
    assert!(
        e.contains("no Gaussian is of class 'ceiling' (id 2): nothing to extract"),
        "{e}"
    );
    assert!(!Path::new(&none).exists());
    // Selected by evidence, --gamma 1 keeps none: the reason is the bias, named.
    let e = common::cli::fuse_synth_fails(
        &room,
        &["--extract", "ball", "--gamma", "1", "--out", &none],
    );
    assert!(
        e.contains(
            "no Gaussian is of class 'ball' (id 4) by FlashSplat's one-vs-rest test at --gamma 1"
        ),
        "{e}"
    );
    assert!(!Path::new(&none).exists());

    let empty = d.join("empty.ply");
    let g = read_ply(&room.join("scene.ply")).unwrap();
    write_ply(&empty, &g.select(&vec![false; g.len()])).unwrap();
    let e = fails(&[
        "fuse",
        "--scene",
        &p(&empty),
        "--cameras",
        &cameras,
        "--labels",
        &arg_in(&room, "labels"),
        "--out",
        &arg_in(d, "e.ply"),
    ]);
    assert!(e.contains("holds no Gaussians"), "{e}");
    // One labeled pixel a view: segment consensus classes every Gaussian from the one or
    // two the views observed, and says so (it said "0 Gaussians left without a class").
    let one_pixel = d.join("one_pixel");
    std::fs::create_dir(&one_pixel).unwrap();
    for map in std::fs::read_dir(room.join("labels")).unwrap() {
        let map = map.unwrap();
        let mut labels = image::open(map.path()).unwrap().to_luma8();
        let centre = *labels.get_pixel(16, 12);
        labels.pixels_mut().for_each(|px| *px = image::Luma([255]));
        labels.put_pixel(16, 12, centre);
        labels.save(one_pixel.join(map.file_name())).unwrap();
    }
    let said = ok(&[
        "fuse",
        "--scene",
        &arg_in(&room, "scene.ply"),
        "--labels",
        &p(&one_pixel),
        "--method",
        "segment-consensus",
        "--out",
        &arg_in(d, "one_pixel.ply"),
    ]);
    assert!(said.contains("warning: the views observed only"), "{said}");
    // A fused scene named .npy would be a PLY under a NumPy name: refused, nothing written.
    let npy = arg_in(d, "fused.npy");
    let e = fails(&[&from_fused[..], &["--out", &npy]].concat());
    assert!(
        e.contains("is written as a PLY") && e.contains(".ply name"),
        "{e}"
    );
    assert!(!Path::new(&npy).exists());
    assert!(!d.join("e.ply").exists());
    // ...and a shard's part (evidence, NumPy) named .ply would be an array under a PLY name.
    let part = arg_in(d, "part.ply");
    let scene = arg_in(&room, "scene.ply");
    let shard = [
        "fuse",
        "--scene",
        &scene,
        "--labels",
        &p(&one_pixel),
        "--shard",
        "0/2",
    ];
    let e = fails(&[&shard[..], &["--out", &part]].concat());
    assert!(
        e.contains("is a shard's part") && e.contains(".npy name"),
        "{e}"
    );
    assert!(!Path::new(&part).exists());
    let out = common::cli::semsplat(&["inspect", &p(&empty)]);
    assert!(
        !out.status.success(),
        "inspect calls an empty scene a problem"
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("no Gaussians"));
    // As it calls a class table of no class, of two classes of one colour (colour-coded
    // maps cannot be read through it), or of two names one in another case.
    for (table, problem) in [
        (r#"{"classes": []}"#, "lists no class"),
        (
            r#"[{"id": 0, "name": "a", "color": [1, 2, 3]}, {"id": 7, "name": "b", "color": [1, 2, 3]}]"#,
            "classes 0 and 7 share the colour [1, 2, 3]",
        ),
        (
            r#"[{"id": 1, "name": "Wall", "color": [1, 2, 3]}, {"id": 7, "name": "wall", "color": [4, 5, 6]}]"#,
            "classes 1 'Wall' and 7 'wall' differ only in case",
        ),
    ] {
        let path = d.join("table.json");
        std::fs::write(&path, table).unwrap();
        let out = common::cli::semsplat(&["inspect", &p(&path)]);
        let report = String::from_utf8_lossy(&out.stdout);
        assert!(
            !out.status.success() && report.contains(problem),
            "{report}"
        );
    }
}

/// `inspect` of a file whose name says nothing reads what its first bytes say (as `fuse
/// --scene` reads any name as PLY), and still refuses what they do not name.
#[test]
fn inspect_tells_a_nameless_file_by_its_first_bytes() {
    let (tmp, room) = tiny_room();
    let d = tmp.path();
    let copy = |from: &Path, to: &str| {
        std::fs::copy(from, d.join(to)).unwrap();
        d.join(to).to_str().unwrap().to_string()
    };
    let scene = copy(&room.join("scene.ply"), "scene_copy");
    let map = copy(&room.join("labels/train_0000.png"), "mask.label");
    let notes = copy(&room.join("room.json"), "notes");
    for (path, kind) in [(&scene, "(3DGS scene)"), (&map, "(label map)")] {
        let out = common::cli::semsplat(&["inspect", path]);
        let report = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success() && report.contains(kind), "{report}");
    }
    let e = fails(&["inspect", &notes]);
    assert!(
        e.contains("cannot tell what") && e.contains("first bytes"),
        "{e}"
    );
}

/// JPEG label maps, a folder of them or one named .png, are named as JPEG with what to do
/// (they had been "no PNG files", "neither a COLMAP model nor...", "not a PNG file").
#[test]
fn jpeg_label_maps_are_named_with_what_to_do() {
    let (tmp, room) = tiny_room();
    let (jpegs, renamed) = (tmp.path().join("jpegs"), tmp.path().join("renamed"));
    std::fs::create_dir_all(&jpegs).unwrap();
    // A JPEG's first bytes (SOI, APP0), then enough to pass for a file.
    let jpeg: Vec<u8> = [0xff, 0xd8, 0xff, 0xe0]
        .into_iter()
        .chain([0; 60])
        .collect();
    for name in ["train_0000", "train_0001", "train_0002", "test_0000"] {
        std::fs::write(jpegs.join(format!("{name}.jpg")), &jpeg).unwrap();
    }
    let out = tmp.path().join("out.ply");
    let room_s = room.to_str().unwrap();
    let fuse = |labels: &Path| {
        let args = ["fuse", "--scene", room_s, "--out", out.to_str().unwrap()];
        fails(&[&args[..], &["--labels", labels.to_str().unwrap()]].concat())
    };
    let must_be_png = "label maps must be PNG";
    let e = fuse(&jpegs);
    assert!(
        e.contains("no PNG files but 4 JPEG files") && e.contains(must_be_png),
        "{e}"
    );
    let e = fails(&["inspect", jpegs.to_str().unwrap()]);
    assert!(
        e.contains("holds 4 JPEG files") && e.contains(must_be_png),
        "{e}"
    );
    let e = fails(&["inspect", jpegs.join("test_0000.jpg").to_str().unwrap()]);
    assert!(
        e.contains("is a JPEG image") && e.contains(must_be_png),
        "{e}"
    );
    std::fs::create_dir_all(&renamed).unwrap();
    for map in common::cli::label_pngs(&room) {
        std::fs::copy(&map, renamed.join(map.file_name().unwrap())).unwrap();
    }
    std::fs::write(renamed.join("train_0001.png"), &jpeg).unwrap();
    let e = fuse(&renamed);
    assert!(
        e.contains("train_0001.png: a JPEG file named .png") && e.contains(must_be_png),
        "{e}"
    );
}

/// `inspect` of a camera file it cannot read says what is wrong with it as cameras, not
/// also that it is no class table; a scene without a class table lists its classes by id
/// alone (no empty names).
#[test]
fn inspect_says_only_what_applies() {
    let (tmp, room) = tiny_room();
    let cams = std::fs::read_to_string(room.join("cameras.json")).unwrap();
    let bad = tmp.path().join("val.json");
    std::fs::write(&bad, cams.replacen("\"train\"", "\"val\"", 1)).unwrap();
    let e = fails(&["inspect", bad.to_str().unwrap()]);
    assert!(
        e.contains("unknown variant") && !e.contains("class table"),
        "{e}"
    );
    let bare = tmp.path().join("bare.ply");
    std::fs::copy(room.join("scene.ply"), &bare).unwrap();
    let out = common::cli::semsplat(&["inspect", bare.to_str().unwrap()]);
    let report = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{report}");
    assert!(
        report.contains("id: 0, count:") && !report.contains("name: ,"),
        "{report}"
    );
}

/// `fuse` on the room with `extra`, as owned arguments.
fn fuse_args(room: &Path, extra: &[&str]) -> Vec<String> {
    common::cli::fuse_synth_args(room, extra)
}

/// `fuse --render-views` keeps off files no render wrote, as `render` does, before any
/// output is written; its own folder it renders into again.
#[test]
fn fuse_render_views_keeps_off_files_it_did_not_write() {
    let (tmp, room) = tiny_room();
    let (views, out) = (tmp.path().join("views"), tmp.path().join("fused.ply"));
    std::fs::create_dir_all(&views).unwrap();
    let mine = views.join("train_0000.labels.png");
    std::fs::write(&mine, b"my own file").unwrap();
    let fuse = fuse_args(
        &room,
        &[
            "--out",
            out.to_str().unwrap(),
            "--render-views",
            views.to_str().unwrap(),
        ],
    );
    let e = common::cli::fails_owned(&fuse);
    assert!(
        e.contains("--render-views") && e.contains("train_0000.labels.png"),
        "{e}"
    );
    assert_eq!(std::fs::read(&mine).unwrap(), b"my own file");
    assert!(!out.exists());
    std::fs::remove_file(&mine).unwrap();
    common::cli::ok_owned(&fuse);
    assert!(mine.is_file());
    common::cli::ok_owned(&fuse);
}

/// `render` never replaces files it did not write (a view's label map and photo share its
/// name) unless forced; its own output folder renders again.
#[test]
fn render_keeps_off_files_it_did_not_write() {
    let (tmp, room) = tiny_room();
    let labels = room.join("labels");
    let map = labels.join("train_0000.png");
    let before = std::fs::read(&map).unwrap();
    let render = |out: &Path, extra: &[&str]| -> Vec<String> {
        let args = [
            "render",
            "--scene",
            room.to_str().unwrap(),
            "--semantics",
            "--out",
        ];
        let all = [&args[..], &[out.to_str().unwrap()], extra].concat();
        all.iter().map(|a| a.to_string()).collect()
    };
    let e = fails_owned(&render(&labels, &[]));
    assert!(
        e.contains("no render wrote") && e.contains("--force"),
        "{e}"
    );
    assert_eq!(
        std::fs::read(&map).unwrap(),
        before,
        "the label map is untouched"
    );
    let views = tmp.path().join("views");
    ok_owned(&render(&views, &[]));
    ok_owned(&render(&views, &[]));
    ok_owned(&render(&labels, &["--force"]));
    assert_ne!(std::fs::read(&map).unwrap(), before, "forced");
}

/// A folder a render wrote into holds the user's files beside the render's: only the files
/// a render wrote there are replaced again without --force (a render of one view once made
/// every file of the folder replaceable).
#[test]
fn a_render_folder_keeps_off_the_files_no_render_wrote() {
    let (_tmp, room) = tiny_room();
    let labels = room.join("labels");
    let render = |view: &str, extra: &[&str]| -> Vec<String> {
        let args = ["render", "--scene", room.to_str().unwrap(), "--semantics"];
        let out = ["--out", labels.to_str().unwrap(), "--views", view];
        let all = [&args[..], &out, extra].concat();
        all.iter().map(|a| a.to_string()).collect()
    };
    ok_owned(&render("train_0000", &["--force"]));
    let map = labels.join("train_0001.png");
    let before = std::fs::read(&map).unwrap();
    let e = fails_owned(&render("train_0001", &[]));
    assert!(e.contains("train_0001.png") && e.contains("--force"), "{e}");
    assert_eq!(
        std::fs::read(&map).unwrap(),
        before,
        "the label map is untouched"
    );
    ok_owned(&render("train_0000", &[]));
}

/// Views without a label map cost a fusion nothing: its views a second are those with one
/// over its time, and a held-out camera without one is not said to be fused; a map named
/// for no camera is named; `eval` names only the cameras of --views it cannot score.
#[test]
fn unlabeled_views_count_in_neither_the_rate_nor_evals_note() {
    let (tmp, room) = tiny_room();
    let labels = tmp.path().join("some_labels");
    std::fs::create_dir_all(&labels).unwrap();
    for name in ["train_0000.png", "train_0002.png"] {
        std::fs::copy(room.join("labels").join(name), labels.join(name)).unwrap();
    }
    let misnamed = labels.join("train_0001_label.png");
    std::fs::copy(room.join("labels").join("train_0001.png"), &misnamed).unwrap();
    let (out, report) = (arg_in(tmp.path(), "f.ply"), arg_in(tmp.path(), "f.json"));
    let (scene, cameras) = (arg_in(&room, "scene.ply"), arg_in(&room, "cameras.json"));
    let inputs = ["fuse", "--scene", &scene, "--cameras", &cameras];
    let outputs = ["--out", &out, "--report", &report];
    let labels_arg = ["--labels", labels.to_str().unwrap()];
    let said = ok(&[&inputs[..], &labels_arg, &outputs].concat());
    assert!(!said.contains("marked \"test\""), "{said}");
    assert!(
        said.contains("1 label map(s)") && said.contains("train_0001_label"),
        "{said}"
    );
    // With --train-only a held-out camera's map is held out, not a map of no camera.
    let test_map = labels.join("test_0000.png");
    std::fs::copy(room.join("labels/test_0000.png"), &test_map).unwrap();
    let train_out = arg_in(tmp.path(), "train_only.ply");
    let train_only = ["--train-only", "--out", &train_out];
    let said = ok(&[&inputs[..], &labels_arg, &train_only].concat());
    assert!(
        said.contains("1 label map(s)") && !said.contains("test_0000,"),
        "{said}"
    );
    std::fs::remove_file(&test_map).unwrap();
    std::fs::remove_file(&misnamed).unwrap();
    let stats = &common::cli::read_json(Path::new(&report))["stats"];
    let number = |key: &str| stats[key].as_f64().unwrap();
    let labeled = number("views_with_labels");
    assert_eq!((number("views"), labeled), (4.0, 2.0), "{stats}");
    let seconds = number("views_per_s") * number("wall_s");
    assert!((seconds - labeled).abs() < 0.01 * labeled, "{stats}");
    // The held-out view's map, alone: the train views lacking one are not eval's business.
    let test_labels = tmp.path().join("test_labels");
    std::fs::create_dir_all(&test_labels).unwrap();
    let map = "test_0000.png";
    std::fs::copy(room.join("labels").join(map), test_labels.join(map)).unwrap();
    let eval = |labels: &Path, views: &str| {
        let args = [
            "eval",
            "--scene",
            &out,
            "--cameras",
            &cameras,
            "--views",
            views,
        ];
        ok(&[&args[..], &["--labels", labels.to_str().unwrap()]].concat())
    };
    let said = eval(&test_labels, "test");
    assert!(!said.contains("have no label map"), "{said}");
    let said = eval(&labels, "train");
    assert!(
        said.contains("1 of the 3 cameras of --views train") && said.contains("train_0001"),
        "{said}"
    );
    assert!(!said.contains("test_0000"), "{said}");
}

/// What a file is, said where it is not what a command reads: a PNG or a cut PLY given as
/// a scene, a room description or run summary given as cameras (no class table either),
/// a shard's manifest to `inspect`, whose --json says even of a file it cannot read.
#[test]
fn readers_say_what_a_file_is() {
    let (tmp, room) = tiny_room();
    let p = |f: &str| arg_in(&room, f);
    let labels = p("labels");
    let fuse = |scene: &str, cameras: &str| {
        let out = arg_in(tmp.path(), "f.ply");
        let args = [
            "fuse",
            "--scene",
            scene,
            "--cameras",
            cameras,
            "--labels",
            &labels,
        ];
        fails(&[&args[..], &["--out", &out]].concat())
    };
    let png = p("images/train_0000.png");
    let as_ply = arg_in(tmp.path(), "image.ply");
    std::fs::copy(&png, &as_ply).unwrap();
    let err = fuse(&as_ply, &p("cameras.json"));
    assert!(err.contains("not a PLY file: a PNG image"), "{err}");
    let cut = arg_in(tmp.path(), "cut.ply");
    let scene = std::fs::read(room.join("scene.ply")).unwrap();
    std::fs::write(&cut, &scene[..100]).unwrap();
    let err = fuse(&cut, &p("cameras.json"));
    assert!(err.contains("ends before its end_header"), "{err}");
    for not_cameras in ["room.json", "synth.json"] {
        let err = fuse(&p("scene.ply"), &p(not_cameras));
        assert!(
            err.contains("unrecognized camera JSON"),
            "{not_cameras}: {err}"
        );
        assert!(
            !err.contains("this is a class table"),
            "{not_cameras}: {err}"
        );
    }
    let err = fuse(&p("scene.ply"), &p("classes.json"));
    assert!(err.contains("this is a class table"), "{err}");
    let out = common::cli::semsplat(&["inspect", "--json", &cut]);
    assert!(!out.status.success());
    let said: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(said["kind"], "unreadable");
    assert!(
        said["problems"][0].as_str().unwrap().contains("end_header"),
        "{said}"
    );
    let part = arg_in(tmp.path(), "part.npy");
    fuse_synth(&room, &["--shard", "0/2", "--out", &part]);
    let manifest = arg_in(tmp.path(), "part.manifest.json");
    let err = fails(&["inspect", &manifest]);
    assert!(err.contains("manifest of a `fuse --shard` part"), "{err}");
    // semsplat's own summaries are named as JSON inspect does not read, by their keys.
    let err = fails(&["inspect", &p("synth.json")]);
    assert!(
        err.contains("JSON of no kind inspect reads") && err.contains("generator"),
        "{err}"
    );
    // --json answers for a path that does not exist too.
    let missing = arg_in(tmp.path(), "missing.ply");
    let out = common::cli::semsplat(&["inspect", "--json", &missing]);
    let said: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(
        !out.status.success() && said["kind"] == "unreadable",
        "{said}"
    );
}
