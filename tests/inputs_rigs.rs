//! Multi-camera rigs: `cam0/00001.jpg` and `cam1/00001.jpg` in one model. Cameras whose stems
//! repeat are named by their relative image path (`cam0/00001`), label maps are matched in the
//! mirrored subfolders, and outputs named after them land in subfolders of --out; names that
//! would lead outside (`cam0/../../x`) are still refused.

mod common;

use common::cli::{arg_in, fails, ok, read_json, semsplat};

use std::fmt::Write as _;
use std::path::Path;

use semsplat::scene::camera::check_camera_name;
use semsplat::scene::cameras::{image_names, load_cameras};
use semsplat::scene::cameras_json::parse_cameras_json;
use semsplat::scene::colmap::{qvec_from_rotation, read_colmap_model};
use semsplat::scene::labels::read_label_png;
use semsplat::scene::ply::read_ply;
use semsplat::scene::Camera;

/// Writes a COLMAP text model as COLMAP's `model_converter` does: the comment headers, one
/// PINHOLE camera per image (a rig's sensors each have their own), two lines per image (the
/// second, the 2D points, empty here) and a header-only points3D.txt.
fn write_colmap_text(dir: &Path, cams: &[Camera], image_names: &[&str]) {
    std::fs::create_dir_all(dir).unwrap();
    let mut cameras = String::from(
        "# Camera list with one line of data per camera:\n\
         #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    writeln!(cameras, "# Number of cameras: {}", cams.len()).unwrap();
    let mut images = String::from(
        "# Image list with two lines of data per image:\n\
         #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
         #   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    writeln!(
        images,
        "# Number of images: {}, mean observations per image: 0",
        cams.len()
    )
    .unwrap();
    for (i, (c, name)) in cams.iter().zip(image_names).enumerate() {
        let id = i + 1;
        writeln!(
            cameras,
            "{id} PINHOLE {} {} {} {} {} {}",
            c.width, c.height, c.fx, c.fy, c.cx, c.cy
        )
        .unwrap();
        let [qw, qx, qy, qz] = qvec_from_rotation(c.rotation);
        let t = c.translation;
        writeln!(
            images,
            "{id} {qw} {qx} {qy} {qz} {} {} {} {id} {name}\n",
            t.x, t.y, t.z
        )
        .unwrap();
    }
    std::fs::write(dir.join("cameras.txt"), cameras).unwrap();
    std::fs::write(dir.join("images.txt"), images).unwrap();
    std::fs::write(
        dir.join("points3D.txt"),
        "# 3D point list with one line of data per point:\n\
         #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
         # Number of points: 0, mean track length: 0\n",
    )
    .unwrap();
}

/// Copies `from` to `to`, creating `to`'s folder.
fn copy(from: &Path, to: &Path) {
    std::fs::create_dir_all(to.parent().unwrap()).unwrap();
    std::fs::copy(from, to).unwrap();
}

fn class_ids(path: &Path) -> Vec<i32> {
    read_ply(path).unwrap().class_ids.unwrap()
}

/// Every file under `dir`, relative, `/`-separated, sorted.
fn files_under(dir: &Path) -> Vec<String> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_str().unwrap();
                found.push(rel.replace('\\', "/"));
            }
        }
    }
    found.sort();
    found
}

/// The tiny synth room with two train views and no held-out view, in `d/room`.
fn synth_two_view_room(d: &Path) {
    ok(&[
        "synth",
        "--preset",
        "tiny",
        "--out",
        &arg_in(d, "room"),
        "--views",
        "2",
        "--test-views",
        "0",
        "--width",
        "48",
        "--height",
        "32",
    ]);
}

/// The room's two views as a rig model (`rig`) and as plain names (`flat`), with label
/// folders for each: `labels_flat`, `labels_rig` (mirrored subfolders) and `labels_swapped`
/// (the rig's two label files exchanged).
fn write_rig_and_flat_models(d: &Path, cams: &[Camera]) {
    let labels = |i: usize| d.join(format!("room/labels/{}.png", cams[i].name));
    write_colmap_text(&d.join("rig"), cams, &["cam0/00001.jpg", "cam1/00001.jpg"]);
    write_colmap_text(&d.join("flat"), cams, &["v0.jpg", "v1.jpg"]);
    copy(&labels(0), &d.join("labels_flat/v0.png"));
    copy(&labels(1), &d.join("labels_flat/v1.png"));
    copy(&labels(0), &d.join("labels_rig/cam0/00001.png"));
    copy(&labels(1), &d.join("labels_rig/cam1/00001.png"));
    copy(&labels(1), &d.join("labels_swapped/cam0/00001.png"));
    copy(&labels(0), &d.join("labels_swapped/cam1/00001.png"));
}

/// `fuse` of the room's scene with the given cameras and labels, rendering its views.
fn fuse_room(d: &Path, cameras: &str, labels: &str, out: &str, views: &str) {
    ok(&[
        "fuse",
        "--scene",
        &arg_in(d, "room/scene.ply"),
        "--cameras",
        &arg_in(d, cameras),
        "--labels",
        &arg_in(d, labels),
        "--classes",
        &arg_in(d, "room/classes.json"),
        "--render-views",
        &arg_in(d, views),
        "--out",
        &arg_in(d, out),
    ]);
}

/// Fuses flat, rig and swapped rig: the rig gives the flat result, the swap changes it.
fn check_rig_fuses_like_flat_and_swap_changes_it(d: &Path) {
    fuse_room(d, "flat", "labels_flat", "flat.ply", "views_flat");
    fuse_room(d, "rig", "labels_rig", "rig.ply", "views_rig");
    fuse_room(d, "rig", "labels_swapped", "swapped.ply", "views_swapped");
    let flat = class_ids(&d.join("flat.ply"));
    let rig_ids = class_ids(&d.join("rig.ply"));
    assert_eq!(
        rig_ids, flat,
        "the rig must fuse exactly as the same views named flat"
    );
    let changed = class_ids(&d.join("swapped.ply"))
        .iter()
        .zip(&rig_ids)
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        changed > 0,
        "swapping the rig's label files changed nothing"
    );
}

/// A flat label folder whose one `00001.png` both rig cameras would read by its stem: fuse
/// refuses it (it fused the one map as both views) and inspect reports it, naming both.
fn check_flat_labels_of_a_rig_are_refused(d: &Path, cams: &[Camera]) {
    copy(
        &d.join(format!("room/labels/{}.png", cams[0].name)),
        &d.join("labels_rig_flat/00001.png"),
    );
    let e = fails(&[
        "fuse",
        "--scene",
        &arg_in(d, "room/scene.ply"),
        "--cameras",
        &arg_in(d, "rig"),
        "--labels",
        &arg_in(d, "labels_rig_flat"),
        "--out",
        &arg_in(d, "rig_flat.ply"),
    ]);
    let named = "00001.png matches two cameras by its stem, 'cam0/00001' and 'cam1/00001'";
    assert!(e.contains(named), "{e}");
    assert!(!d.join("rig_flat.ply").exists());
    let inspected = semsplat(&[
        "inspect",
        &arg_in(d, "labels_rig_flat"),
        "--cameras",
        &arg_in(d, "rig"),
    ]);
    let report = String::from_utf8_lossy(&inspected.stdout);
    assert!(
        !inspected.status.success() && report.contains(named),
        "{report}"
    );
}

/// --render-views writes the rig views into subfolders of its folder, and they are the
/// plain model's views; beside them the mark of a render's folder, as `render` writes it.
fn check_rig_render_views_match_flat(d: &Path) {
    assert_eq!(
        files_under(&d.join("views_rig")),
        [
            ".semsplat-render",
            "cam0/00001.labels.png",
            "cam0/00001.palette.png",
            "cam1/00001.labels.png",
            "cam1/00001.palette.png"
        ]
    );
    for (rig_view, flat_view) in [("cam0/00001", "v0"), ("cam1/00001", "v1")] {
        let a = read_label_png(&d.join(format!("views_rig/{rig_view}.labels.png"))).unwrap();
        let b = read_label_png(&d.join(format!("views_flat/{flat_view}.labels.png"))).unwrap();
        assert_eq!(a.labels, b.labels, "{rig_view}");
    }
}

/// eval reads labels and images by relative path (images/cam0/00001.png).
fn check_rig_eval_reads_by_relative_path(d: &Path, cams: &[Camera]) {
    for (i, rig_view) in ["cam0/00001", "cam1/00001"].iter().enumerate() {
        let image = d.join(format!("room/images/{}.png", cams[i].name));
        copy(&image, &d.join(format!("images_rig/{rig_view}.png")));
    }
    ok(&[
        "eval",
        "--scene",
        &arg_in(d, "rig.ply"),
        "--cameras",
        &arg_in(d, "rig"),
        "--labels",
        &arg_in(d, "labels_rig"),
        "--views",
        "all",
        "--images",
        &arg_in(d, "images_rig"),
        "--json",
        &arg_in(d, "eval.json"),
    ]);
    let eval = read_json(&d.join("eval.json"));
    assert!(eval["miou"].as_f64().unwrap() > 0.5, "{eval}");
    assert!(
        eval["image_quality"]["psnr"].as_f64().unwrap() > 10.0,
        "{eval}"
    );
}

/// render (with --semantics, and --raw) of one rig view by its name lands inside --out.
fn check_rig_view_renders_by_name_inside_out(d: &Path) {
    let render = |scene: &str, extra: &str| {
        ok(&[
            "render",
            "--scene",
            &arg_in(d, scene),
            "--cameras",
            &arg_in(d, "rig"),
            "--views",
            "cam1/00001",
            extra,
            "--out",
            &arg_in(d, "render_out"),
        ])
    };
    render("rig.ply", "--semantics");
    render("room/scene.ply", "--raw");
    let written = files_under(&d.join("render_out"));
    for f in [
        "cam1/00001.png",
        "cam1/00001.labels.png",
        "cam1/00001.rgb.npy",
    ] {
        assert!(written.contains(&f.to_owned()), "{f} not in {written:?}");
    }
    // Beside the view's files, only the mark of a render's folder (render refuses to
    // replace files in a folder without it).
    assert!(
        (written.iter())
            .filter(|f| *f != ".semsplat-render")
            .all(|f| f.starts_with("cam1/00001.")),
        "{written:?}"
    );
}

/// Two views of the synth room as a two-sensor rig (`cam0/00001.jpg`, `cam1/00001.jpg`) and
/// as plain names (`v0.jpg`, `v1.jpg`), same numbers: fusing the rig with mirrored label
/// subfolders gives exactly the plain model's result, and swapping the two rig label files
/// changes it, so each view took the labels under its own folder.
#[test]
fn colmap_rig_fuses_with_mirrored_label_subfolders() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_two_view_room(d);
    let cams = load_cameras(&d.join("room/cameras.json")).unwrap();
    write_rig_and_flat_models(d, &cams);

    let rig = read_colmap_model(&d.join("rig")).unwrap();
    let names: Vec<&str> = rig.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["cam0/00001", "cam1/00001"]);

    check_rig_fuses_like_flat_and_swap_changes_it(d);
    check_flat_labels_of_a_rig_are_refused(d, &cams);
    check_rig_render_views_match_flat(d);
    check_rig_eval_reads_by_relative_path(d, &cams);
    check_rig_view_renders_by_name_inside_out(d);
}

/// Stems stay the names where unique; repeated stems take the relative path, without the
/// folders every image shares (nerfstudio's `images/`) and without `.` components.
#[test]
fn repeated_stems_are_named_by_relative_path() {
    assert_eq!(
        image_names(&[
            "cam0/00001.jpg",
            "cam1/00001.JPG",
            "cam0/00002.jpg",
            "a.png"
        ]),
        ["cam0/00001", "cam1/00001", "00002", "a"]
    );
    assert_eq!(
        image_names(&["images/cam0/1.png", "./images/cam1/1.png", "images/x.png"]),
        ["cam0/1", "cam1/1", "x"]
    );
    assert_eq!(
        image_names(&["cam0\\f.jpg", "cam1\\f.jpg"]),
        ["cam0/f", "cam1/f"]
    );
    assert_eq!(
        image_names(&["/data/a/1.jpg", "/data/b/1.jpg"]),
        ["a/1", "b/1"]
    );
    // Ordinary datasets: unchanged.
    assert_eq!(
        image_names(&["images/frame.001.JPG", "images/frame.002.JPG"]),
        ["frame.001", "frame.002"]
    );

    // An INRIA cameras.json of a rig reads the same way.
    let inria = |name: &str| {
        format!(
            r#"{{"img_name": "{name}", "width": 4, "height": 3, "position": [0,0,0],
            "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 2, "fy": 2}}"#
        )
    };
    let json = format!("[{}, {}]", inria("cam1/00001"), inria("cam0/00001"));
    let (_, cams) = parse_cameras_json(json.as_bytes()).unwrap();
    let names: Vec<&str> = cams.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["cam1/00001", "cam0/00001"]);
}

/// A relative path is accepted only when every component is a plain name; COLMAP image
/// names that climb out (`cam0/../../x.jpg`) are still refused.
#[test]
fn rig_names_that_leave_the_folder_are_refused() {
    assert!(check_camera_name("cam0/00001").is_ok());
    assert!(check_camera_name("rig/cam0/00001").is_ok());
    for (name, why) in [
        ("cam0/../../x", "'..'"),
        ("../x", "'..'"),
        ("cam0/./x", "'.'"),
        ("/abs/x", "absolute"),
        ("a//b", "empty path component"),
        ("a/", "empty path component"),
        ("a\\b", "backslash"),
        ("cam0/C:x", "drive prefix"),
        ("cam0/a\u{0}b", "NUL"),
    ] {
        let e = format!("{:#}", check_camera_name(name).unwrap_err());
        assert!(e.contains("camera name") && e.contains(why), "{name}: {e}");
    }

    let tmp = tempfile::tempdir().unwrap();
    let cam = |name: &str| Camera {
        name: name.into(),
        width: 4,
        height: 3,
        fx: 2.0,
        fy: 2.0,
        cx: 2.0,
        cy: 1.5,
        rotation: glam::DMat3::IDENTITY,
        translation: glam::DVec3::new(0.0, 0.0, 3.0),
        split: semsplat::scene::Split::Train,
    };
    let model = tmp.path().join("model");
    write_colmap_text(
        &model,
        &[cam("a"), cam("b")],
        &["cam0/../../x.jpg", "cam1/x.jpg"],
    );
    let e = format!("{:#}", read_colmap_model(&model).unwrap_err());
    assert!(e.contains("cam0/../../x") && e.contains("'..'"), "{e}");
    // Two images that differ only by extension cannot be told apart by name.
    write_colmap_text(&model, &[cam("a"), cam("b")], &["cam0/x.jpg", "cam0/x.png"]);
    let e = format!("{:#}", read_colmap_model(&model).unwrap_err());
    assert!(e.contains("share the name 'x'"), "{e}");
    // Named by the model's image ids (1 and 2 here), not by positions in a sorted list.
    assert!(e.contains("image 1 and image 2 share"), "{e}");
}
