//! Every kind of bad input gives one clear error that names the file and the problem.

use std::path::{Path, PathBuf};

mod common;

use common::npy::npy_v1;
use glam::{DMat3, DVec3};
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::cameras_json::{parse_cameras_json, write_semsplat_cameras};
use semsplat::scene::classes::{read_class_table, ClassTable};
use semsplat::scene::colmap::{read_colmap_model, read_images_bin_from};
use semsplat::scene::images::load_view_image;
use semsplat::scene::labels::{read_label_png, write_label_png, LabelDir, LabelMap, MissingLabels};
use semsplat::scene::ply::{read_ply, read_ply_from, read_ply_unchecked, write_ply};
use semsplat::scene::{Camera, Gaussians, Split};

fn error_of<T>(r: anyhow::Result<T>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => format!("{e:#}"),
    }
}

/// Asserts that the error names `path` (by file name) and contains every `needle`.
fn assert_error(err: &str, path: &Path, needles: &[&str]) {
    let name = path.file_name().unwrap().to_str().unwrap();
    assert!(err.contains(name), "error does not name {name}: {err}");
    for n in needles {
        assert!(err.contains(n), "error lacks '{n}': {err}");
    }
}

fn one_gaussian() -> Gaussians {
    Gaussians {
        means: vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]],
        log_scales: vec![[0.0; 3]; 2],
        quats: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        opacity_logits: vec![0.5; 2],
        sh_degree: 0,
        sh: vec![0.1; 6],
        ..Default::default()
    }
}

fn write_tmp(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

const REQUIRED: &str = "property float x\nproperty float y\nproperty float z\n\
property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\n\
property float scale_0\nproperty float scale_1\nproperty float scale_2\n\
property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n";

// ---------------------------------------------------------------------------------------
// PLY

#[test]
fn truncated_ply_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ply");
    write_ply(&good, &one_gaussian()).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let cut = write_tmp(dir.path(), "cut.ply", &bytes[..bytes.len() - 5]);
    assert_error(
        &error_of(read_ply(&cut)),
        &cut,
        &["truncated", "2 vertices"],
    );
    // Streaming (no size known) reports where the data ends.
    let err = error_of(read_ply_from(&bytes[..bytes.len() - 5], None));
    assert!(
        err.contains("truncated") && err.contains("vertex 1"),
        "{err}"
    );
    // Header cut off.
    let header_only = write_tmp(
        dir.path(),
        "header.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 2\n",
    );
    assert_error(
        &error_of(read_ply(&header_only)),
        &header_only,
        &["end_header"],
    );
    // ASCII with too few values.
    let ascii = write_tmp(
        dir.path(),
        "short.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 2\n{REQUIRED}end_header\n0 0 0 0 0 0 0 0 0 0 1 0 0 0\n1 2 3\n"),
    );
    assert_error(&error_of(read_ply(&ascii)), &ascii, &["truncated"]);
}

#[test]
fn ply_data_that_does_not_fit_its_header_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let v = "0 0 0 0 0 0 0 0 0 0 1 0 0 0";
    let head =
        |n: usize| format!("ply\nformat ascii 1.0\nelement vertex {n}\n{REQUIRED}end_header\n");
    // One value short on one line, one over on the next: read as one stream, the second
    // vertex would be shifted by one field.
    let shifted = write_tmp(
        dir.path(),
        "shifted.ply",
        format!("{}{v}\n0 0 0 0 0 0 0 0 0 1 0 0 0\n{v} 7\n", head(3)),
    );
    assert_error(
        &error_of(read_ply(&shifted)),
        &shifted,
        &["vertex 1 ends after 13 values", "14 properties"],
    );
    let joined = write_tmp(dir.path(), "joined.ply", format!("{}{v} {v}\n", head(2)));
    assert_error(
        &error_of(read_ply(&joined)),
        &joined,
        &["vertex 0's line holds more"],
    );
    let more = write_tmp(dir.path(), "more.ply", format!("{}{v}\n{v}\n", head(1)));
    assert_error(
        &error_of(read_ply(&more)),
        &more,
        &["past the header's 1 vertices"],
    );
    // Binary: a count smaller than the data.
    let good = dir.path().join("good.ply");
    write_ply(&good, &one_gaussian()).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let mut fewer_bytes = bytes.clone();
    let at = (bytes.windows(16))
        .position(|w| w == b"element vertex 2")
        .unwrap();
    fewer_bytes[at + 15] = b'1';
    let fewer = write_tmp(dir.path(), "fewer.ply", &fewer_bytes);
    // Less than a vertex past the count is a writer's padding, let pass.
    let padded = write_tmp(dir.path(), "padded.ply", [&bytes[..], &[0, 0, 0]].concat());
    assert_eq!(read_ply(&padded).unwrap().len(), 2);
    assert_error(
        &error_of(read_ply(&fewer)),
        &fewer,
        &["past the header's 1 vertices"],
    );
    // A class written as an unsigned narrow type: its largest value is -1, as 2^32 - 1 is.
    for (ty, max) in [("uchar", 255), ("ushort", 65535)] {
        let p = write_tmp(
            dir.path(),
            &format!("{ty}.ply"),
            format!("ply\nformat ascii 1.0\nelement vertex 2\n{REQUIRED}property {ty} class\nend_header\n{v} 3\n{v} {max}\n"),
        );
        assert_eq!(read_ply(&p).unwrap().class_ids.unwrap(), [3, -1], "{ty}");
    }
}

#[test]
fn malformed_ply_headers_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, String, &str)] = &[
        ("magic.ply", "plx\nformat ascii 1.0\nend_header\n".into(), "not a PLY"),
        ("format.ply", format!("ply\nformat binary_middle_endian 1.0\nelement vertex 0\n{REQUIRED}end_header\n"), "unknown PLY format"),
        ("noformat.ply", format!("ply\nelement vertex 0\n{REQUIRED}end_header\n"), "no format"),
        ("type.ply", format!("ply\nformat ascii 1.0\nelement vertex 0\n{REQUIRED}property float128 q\nend_header\n"), "unknown type 'float128'"),
        ("count.ply", format!("ply\nformat ascii 1.0\nelement vertex -3\n{REQUIRED}end_header\n"), "invalid count"),
        ("novertex.ply", "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n".into(), "no 'vertex' element"),
        ("list.ply", format!("ply\nformat ascii 1.0\nelement vertex 0\n{REQUIRED}property list uchar float q\nend_header\n"), "is a list"),
        ("garbage.ply", format!("ply\nformat ascii 1.0\nelement vertex 0\n{REQUIRED}hello world\nend_header\n"), "malformed header line"),
        ("dup.ply", format!("ply\nformat ascii 1.0\nelement vertex 0\n{REQUIRED}property float x\nend_header\n"), "'x' appears twice"),
        ("notnum.ply", format!("ply\nformat ascii 1.0\nelement vertex 1\n{REQUIRED}end_header\n0 0 zero 0 0 0 0 0 0 0 1 0 0 0\n"), "'zero' is not a number"),
        ("classfloat.ply", format!("ply\nformat ascii 1.0\nelement vertex 1\n{REQUIRED}property float class\nend_header\n0 0 0 0 0 0 0 0 0 0 1 0 0 0 2.5\n"), "not a 32-bit integer"),
    ];
    for (name, text, needle) in cases {
        let p = write_tmp(dir.path(), name, text);
        assert_error(&error_of(read_ply(&p)), &p, &[needle]);
    }
}

#[test]
fn missing_or_inconsistent_ply_properties_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let no_rot = REQUIRED
        .replace("property float rot_3\n", "")
        .replace("property float opacity\n", "");
    let p = write_tmp(
        dir.path(),
        "norot.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 0\n{no_rot}end_header\n"),
    );
    assert_error(
        &error_of(read_ply(&p)),
        &p,
        &["missing required vertex properties", "opacity", "rot_3"],
    );

    let five_rest: String = (0..5)
        .map(|i| format!("property float f_rest_{i}\n"))
        .collect();
    let p = write_tmp(
        dir.path(),
        "rest.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 0\n{REQUIRED}{five_rest}end_header\n"),
    );
    assert_error(&error_of(read_ply(&p)), &p, &["5 f_rest", "SH degree"]);

    let gap: String = (1..10)
        .map(|i| format!("property float f_rest_{i}\n"))
        .collect();
    let p = write_tmp(
        dir.path(),
        "gap.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 0\n{REQUIRED}{gap}end_header\n"),
    );
    assert_error(&error_of(read_ply(&p)), &p, &["f_rest_9"]);

    let sem = "property float sem_0\nproperty float sem_2\n";
    let p = write_tmp(
        dir.path(),
        "sem.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 0\n{REQUIRED}{sem}end_header\n"),
    );
    assert_error(&error_of(read_ply(&p)), &p, &["sem_2"]);
}

/// Writes `g` as a PLY whose one `marker` value is then replaced by `bad` (the writer itself
/// refuses non-finite values, so a file another tool wrote is made by patching bytes).
fn write_ply_patched(p: &Path, g: &Gaussians, marker: f32, bad: f32) {
    write_ply(p, g).unwrap();
    let mut bytes = std::fs::read(p).unwrap();
    let m = marker.to_le_bytes();
    let at = bytes
        .windows(4)
        .position(|w| w == m)
        .expect("marker written");
    bytes[at..at + 4].copy_from_slice(&bad.to_le_bytes());
    std::fs::write(p, bytes).unwrap();
}

#[test]
fn nan_inf_and_zero_quaternions_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut nan = one_gaussian();
    nan.opacity_logits[1] = 12345.5;
    let p = dir.path().join("nan.ply");
    write_ply_patched(&p, &nan, 12345.5, f32::NAN);
    assert_error(
        &error_of(read_ply(&p)),
        &p,
        &["non-finite opacity", "index 1"],
    );
    // The unchecked reader (used by `inspect`) still loads it.
    assert!(read_ply_unchecked(&p).unwrap().opacity_logits[1].is_nan());

    let mut inf = one_gaussian();
    inf.means[0][2] = 12345.5;
    let p = dir.path().join("inf.ply");
    write_ply_patched(&p, &inf, 12345.5, f32::INFINITY);
    assert_error(
        &error_of(read_ply(&p)),
        &p,
        &["non-finite position", "index 0"],
    );

    let mut zero = one_gaussian();
    zero.quats[1] = [0.0; 4];
    let p = dir.path().join("zeroq.ply");
    write_ply(&p, &zero).unwrap();
    assert_error(
        &error_of(read_ply(&p)),
        &p,
        &["zero rotation quaternion", "index 1"],
    );

    // ASCII "nan"/"inf" tokens too.
    let p = write_tmp(
        dir.path(),
        "nanascii.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 1\n{REQUIRED}end_header\n0 0 0 nan 0 0 0 inf 0 0 1 0 0 0\n"),
    );
    assert_error(
        &error_of(read_ply(&p)),
        &p,
        &["non-finite SH", "non-finite scale"],
    );
}

#[test]
fn absurd_vertex_counts_fail_without_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!("ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n{REQUIRED}end_header\n");
    let p = write_tmp(dir.path(), "huge.ply", &text);
    assert_error(&error_of(read_ply(&p)), &p, &["1000000000000 vertices"]);
    // From a stream of unknown length: runs out of data, not memory.
    let err = error_of(read_ply_from(text.as_bytes(), None));
    assert!(err.contains("truncated"), "{err}");
    let text = format!(
        "ply\nformat ascii 1.0\nelement vertex 18446744073709551615\n{REQUIRED}end_header\n"
    );
    assert!(read_ply_from(text.as_bytes(), None).is_err());
    assert!(read_ply_from(text.as_bytes(), Some(text.len() as u64)).is_err());
}

// ---------------------------------------------------------------------------------------
// Cameras

#[test]
fn distorted_colmap_models_are_refused_with_undistort_advice() {
    let dir = tempfile::tempdir().unwrap();
    write_tmp(
        dir.path(),
        "cameras.txt",
        "1 SIMPLE_RADIAL 100 80 90 50 40 -0.02\n",
    );
    write_tmp(dir.path(), "images.txt", "1 1 0 0 0 0 0 0 1 a.png\n\n");
    let err = error_of(read_colmap_model(dir.path()));
    assert!(err.contains(&dir.path().display().to_string()), "{err}");
    assert!(
        err.contains("SIMPLE_RADIAL") && err.contains("image_undistorter"),
        "{err}"
    );

    // Binary OPENCV with distortion, found through sparse/0.
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("sparse/0");
    std::fs::create_dir_all(&model).unwrap();
    let mut cams = 1u64.to_le_bytes().to_vec();
    cams.extend_from_slice(&1u32.to_le_bytes());
    cams.extend_from_slice(&4i32.to_le_bytes()); // OPENCV
    cams.extend_from_slice(&100u64.to_le_bytes());
    cams.extend_from_slice(&80u64.to_le_bytes());
    for v in [90.0f64, 90.0, 50.0, 40.0, 0.1, 0.0, 0.0, 0.0] {
        cams.extend_from_slice(&v.to_le_bytes());
    }
    write_tmp(&model, "cameras.bin", cams);
    write_tmp(&model, "images.bin", 0u64.to_le_bytes());
    let err = error_of(load_cameras(dir.path()));
    assert!(err.contains("OPENCV") && err.contains("undistort"), "{err}");
}

#[test]
fn broken_colmap_models_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    write_tmp(dir.path(), "cameras.txt", "1 PINHOLE 100 80 90 90 50 40\n");
    write_tmp(dir.path(), "images.txt", "1 1 0 0 0 0 0 0 2 a.png\n\n");
    let err = error_of(read_colmap_model(dir.path()));
    assert!(
        err.contains("camera 2") && err.contains("not in the model"),
        "{err}"
    );

    write_tmp(dir.path(), "images.txt", "1 0 0 0 0 0 0 0 1 a.png\n\n");
    let err = error_of(read_colmap_model(dir.path()));
    assert!(err.contains("quaternion") && err.contains("zero"), "{err}");

    // Images in different folders with one stem are a rig (named by relative path, see
    // tests/inputs_rigs.rs); the same path with two extensions cannot be told apart.
    write_tmp(
        dir.path(),
        "images.txt",
        "1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 0 1 a.jpg\n",
    );
    let err = error_of(read_colmap_model(dir.path()));
    assert!(err.contains("share the name 'a'"), "{err}");

    write_tmp(dir.path(), "cameras.txt", "1 PINHOLE 100 80 90 90 50\n");
    let err = error_of(read_colmap_model(dir.path()));
    assert!(
        err.contains("cameras.txt") && err.contains("line 1") && err.contains("needs 4 parameters"),
        "{err}"
    );

    // Named by the model's ids (image 7 of camera 3), not a position in a sorted list.
    write_tmp(dir.path(), "cameras.txt", "3 PINHOLE 100 80 0 90 50 40\n");
    write_tmp(dir.path(), "images.txt", "7 1 0 0 0 0 0 0 3 a.png\n\n");
    let err = error_of(read_colmap_model(dir.path()));
    assert!(
        err.contains("fx = 0") && err.contains("image 7 ('a.png') of camera 3"),
        "{err}"
    );

    write_tmp(dir.path(), "images.txt", "# no images\n");
    let err = error_of(read_colmap_model(dir.path()));
    assert!(err.contains("no images"), "{err}");

    let empty = tempfile::tempdir().unwrap();
    let err = error_of(load_cameras(empty.path()));
    assert!(err.contains("not a COLMAP model"), "{err}");

    // Binary: truncated image record, absurd counts.
    let bin = tempfile::tempdir().unwrap();
    let mut cams = 1u64.to_le_bytes().to_vec();
    cams.extend_from_slice(&1u32.to_le_bytes());
    cams.extend_from_slice(&1i32.to_le_bytes());
    cams.extend_from_slice(&100u64.to_le_bytes());
    cams.extend_from_slice(&80u64.to_le_bytes());
    for v in [90.0f64, 90.0, 50.0, 40.0] {
        cams.extend_from_slice(&v.to_le_bytes());
    }
    write_tmp(bin.path(), "cameras.bin", &cams);
    let mut imgs = u64::MAX.to_le_bytes().to_vec();
    imgs.extend_from_slice(&1u32.to_le_bytes());
    imgs.extend_from_slice(&1.0f64.to_le_bytes());
    let p = write_tmp(bin.path(), "images.bin", &imgs);
    assert_error(&error_of(read_colmap_model(bin.path())), &p, &["truncated"]);
    let mut huge_points = 1u64.to_le_bytes().to_vec();
    huge_points.extend_from_slice(&1u32.to_le_bytes());
    for v in [1.0f64, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0] {
        huge_points.extend_from_slice(&v.to_le_bytes());
    }
    huge_points.extend_from_slice(&1u32.to_le_bytes());
    huge_points.extend_from_slice(b"a.png\0");
    huge_points.extend_from_slice(&(u64::MAX / 2).to_le_bytes());
    let err = error_of(read_images_bin_from(&mut &huge_points[..]));
    assert!(err.contains("2D points"), "{err}");
    // More records than the count names: the rest would be left out silently.
    let mut more = cams.clone();
    more.extend_from_slice(&cams[8..]);
    let p = write_tmp(bin.path(), "cameras.bin", &more);
    assert_error(
        &error_of(read_colmap_model(bin.path())),
        &p,
        &["continues past the 1 cameras"],
    );
    let mut bad_model = cams.clone();
    bad_model[12..16].copy_from_slice(&99i32.to_le_bytes());
    let p = write_tmp(bin.path(), "cameras.bin", &bad_model);
    assert_error(
        &error_of(read_colmap_model(bin.path())),
        &p,
        &["unknown model id 99"],
    );
}

fn good_camera(name: &str) -> Camera {
    Camera {
        name: name.into(),
        width: 4,
        height: 3,
        fx: 2.0,
        fy: 2.0,
        cx: 2.0,
        cy: 1.5,
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        split: Split::Train,
    }
}

#[test]
fn invalid_camera_jsons_are_errors() {
    let cam = |extra: &str| {
        format!(
            r#"{{"format": "semsplat-cameras", "version": 1, "cameras": [{{"name": "v0", "width": 4, "height": 3,
            "fx": 2, "fy": 2, "cx": 2, "cy": 1.5, "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]{extra}}}]}}"#
        )
    };
    assert!(parse_cameras_json(cam("").as_bytes()).is_ok());
    let cases: Vec<(String, &str)> = vec![
        (cam("").replace("\"fx\": 2", "\"fx\": 0"), "fx = 0"),
        (cam("").replace("\"width\": 4", "\"width\": 0"), "size 0x3"),
        (
            cam("").replace("\"width\": 4, \"height\": 3", "\"width\": 1048576, \"height\": 4096"),
            "32-bit pixel indices",
        ),
        (
            cam("").replace("[1,0,0,0],[0,1,0,0]", "[2,0,0,0],[0,1,0,0]"),
            "not orthonormal (|R^T R - I| = 3.00e0, over the 1e-3 allowed): write the poses with \
             more digits",
        ),
        (cam("").replace("[1,0,0,0],[0,1,0,0]", "[-1,0,0,0],[0,1,0,0]"), "reflection"),
        (cam("").replace("[0,0,0,1]]", "[0,0,1,1]]"), "last row"),
        (cam("").replace("\"version\": 1", "\"version\": 2"), "version 2"),
        (cam("").replace("semsplat-cameras", "other-cams"), "unknown camera format"),
        (cam(r#", "split": "val""#), "unknown variant"),
        (cam("").replace("\"fx\": 2, ", ""), "missing field `fx`"),
        (cam("").replace("]}]}", "]}, {\"name\": \"v0\", \"width\": 4, \"height\": 3, \"fx\": 2, \"fy\": 2, \"cx\": 2, \"cy\": 1.5, \"world_to_camera\": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]}"), "share the name 'v0'"),
        ("{\"frames\": []}".into(), "transforms.json"),
        ("[]".into(), "no cameras"),
        ("{not json".into(), "invalid JSON"),
        (r#"[{"img_name": "a", "width": 4, "height": 3, "position": [0,0,0], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 2}]"#.into(), "camera 0 ('a'): missing field `fy`"),
        (r#"[{"img_name": "a", "width": 4, "height": 3, "position": [0,0,0], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 2, "fy": 1e999}]"#.into(), "invalid JSON"),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (i, (text, needle)) in cases.iter().enumerate() {
        let p = write_tmp(dir.path(), &format!("cams{i}.json"), text);
        assert_error(&error_of(load_cameras(&p)), &p, &[needle]);
    }
    // Writers refuse invalid cameras too, and leave no file.
    let mut bad = good_camera("x");
    bad.fy = f64::NAN;
    let p = dir.path().join("out.json");
    assert_error(
        &error_of(write_semsplat_cameras(&p, &[bad])),
        &p,
        &["fy = NaN"],
    );
    assert!(!p.exists());
    let p = write_tmp(dir.path(), "cams.yaml", "x");
    assert_error(
        &error_of(load_cameras(&p)),
        &p,
        &["cannot tell the camera format"],
    );
}

/// Camera names become output and input file names, so every camera source refuses names
/// that are paths: the semsplat and INRIA JSONs here, COLMAP through the same check.
#[test]
fn camera_names_that_are_paths_are_errors() {
    let semsplat = |name: &str| {
        format!(
            r#"{{"format": "semsplat-cameras", "version": 1, "cameras": [{{"name": {name}, "width": 4, "height": 3,
            "fx": 2, "fy": 2, "cx": 2, "cy": 1.5, "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}}]}}"#
        )
    };
    let inria = |name: &str| {
        format!(
            r#"[{{"img_name": {name}, "width": 4, "height": 3, "position": [0,0,0], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 2, "fy": 2}}]"#
        )
    };
    let cases = [
        (r#""../../x""#, "'..'"),
        (r#""cam0/../../x""#, "'..'"),
        (r#""/abs/x""#, "absolute path"),
        (r#""a\\b""#, "backslash"),
        (r#"".""#, "names a folder"),
        (r#""..""#, "names a folder"),
        (r#""a\u0000b""#, "NUL"),
        (r#""""#, "empty"),
        (r#""C:x""#, "drive prefix"),
    ];
    for (name, needle) in cases {
        let err = error_of(parse_cameras_json(semsplat(name).as_bytes()));
        assert!(
            err.contains("camera name") && err.contains(needle),
            "{name}: {err}"
        );
    }
    // INRIA strips folders from img_name (as COLMAP does), so only `.`/`..` stems remain.
    for (name, needle) in [
        (r#""..""#, "names a folder"),
        (r#""a/..""#, "names a folder"),
    ] {
        let err = error_of(parse_cameras_json(inria(name).as_bytes()));
        assert!(
            err.contains("camera name") && err.contains(needle),
            "{name}: {err}"
        );
    }
    assert!(parse_cameras_json(semsplat(r#""frame..001""#).as_bytes()).is_ok());
}

// ---------------------------------------------------------------------------------------
// Label maps and class tables

#[test]
fn cameras_without_label_maps_are_listed() {
    let dir = tempfile::tempdir().unwrap();
    write_label_png(&dir.path().join("v0.png"), &LabelMap::filled(4, 3, 1)).unwrap();
    let cams: Vec<Camera> = (0..9).map(|i| good_camera(&format!("v{i}"))).collect();
    let err = error_of(LabelDir::open(
        dir.path(),
        &cams,
        None,
        MissingLabels::Error,
    ));
    assert!(err.contains(&dir.path().display().to_string()), "{err}");
    assert!(
        err.contains("8 of 9 cameras") && err.contains("v1, v2, v3, v4, v5 and 3 more"),
        "{err}"
    );
}

#[test]
fn label_maps_of_the_wrong_size_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v0.png");
    write_label_png(&p, &LabelMap::filled(5, 3, 1)).unwrap();
    let labels =
        LabelDir::open(dir.path(), &[good_camera("v0")], None, MissingLabels::Error).unwrap();
    let err = error_of(labels.load(0));
    assert_error(&err, &p, &["5x3", "camera is 4x3"]);
}

#[test]
fn class_ids_outside_the_table_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v0.png");
    let mut map = LabelMap::filled(4, 3, 1);
    map.labels[0] = 9;
    map.labels[1] = 12;
    map.labels[2] = LabelMap::IGNORE;
    write_label_png(&p, &map).unwrap();
    let table = ClassTable::from_ids([0, 1]);
    let labels = LabelDir::open(
        dir.path(),
        &[good_camera("v0")],
        Some(&table),
        MissingLabels::Error,
    )
    .unwrap();
    let err = error_of(labels.iter().next().unwrap());
    assert_error(&err, &p, &["2 pixels", "not in the class table: 9, 12"]);
}

#[test]
fn color_and_broken_label_pngs_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = dir.path().join("rgb.png");
    image::RgbImage::from_pixel(2, 2, image::Rgb([1, 2, 3]))
        .save(&rgb)
        .unwrap();
    assert_error(
        &error_of(read_label_png(&rgb)),
        &rgb,
        &["RGB PNG", "single-channel class ids"],
    );

    // A 16-bit palette PNG header (no such PNG): refused before decoding. (Valid palette
    // PNGs are label maps: tests/inputs_labels.rs.)
    let mut pal = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\0\x02\0\0\0\x02\x10\x03\0\0\0".to_vec();
    pal.extend_from_slice(&[0; 4]);
    let p = write_tmp(dir.path(), "pal.png", pal);
    assert_error(
        &error_of(read_label_png(&p)),
        &p,
        &["palette", "bit depth 16"],
    );

    let p = write_tmp(dir.path(), "text.png", "not a png at all, just text");
    assert_error(&error_of(read_label_png(&p)), &p, &["not a PNG"]);

    let good = dir.path().join("good.png");
    write_label_png(&good, &LabelMap::filled(64, 64, 3)).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let p = write_tmp(dir.path(), "cut.png", &bytes[..bytes.len() / 2]);
    assert_error(&error_of(read_label_png(&p)), &p, &["cannot decode"]);
}

#[test]
fn invalid_class_tables_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            r#"[{"id": 1, "name": "a"}, {"id": 1, "name": "b"}]"#,
            "duplicate class id 1",
        ),
        (
            r#"[{"id": 1, "name": "a"}, {"id": 2, "name": "a"}]"#,
            "duplicate class name 'a'",
        ),
        (
            r#"{"classes": [{"id": 65535, "name": "x"}]}"#,
            "ids must be below 65535",
        ),
        (
            r#"[{"id": 3, "name": "a", "color": [1, 2]}]"#,
            "not a class table",
        ),
        (r#"{"labels": []}"#, "not a class table"),
    ];
    for (i, (text, needle)) in cases.iter().enumerate() {
        let p = write_tmp(dir.path(), &format!("classes{i}.json"), text);
        assert_error(&error_of(read_class_table(&p)), &p, &[needle]);
    }
}

/// Train images: the extension in any case, one image a view (two are an error naming
/// both), and transparent pixels composited over black (3DGS's default background).
#[test]
fn view_images_are_found_in_any_case_once_and_composited_over_black() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = good_camera("a");
    (cam.width, cam.height) = (2, 1);
    image::RgbImage::from_raw(2, 1, vec![255, 0, 0, 0, 0, 255])
        .unwrap()
        .save_with_format(dir.path().join("a.PNG"), image::ImageFormat::Png)
        .unwrap();
    let rgb = load_view_image(dir.path(), &cam).unwrap();
    assert_eq!(rgb, [1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
    image::RgbImage::new(2, 1)
        .save(dir.path().join("a.jpg"))
        .unwrap();
    let err = error_of(load_view_image(dir.path(), &cam));
    assert!(
        err.contains("2 images") && err.contains("a.jpg") && err.contains("a.PNG"),
        "{err}"
    );
    // White under alpha 0 is no observation; half alpha halves the colour.
    cam.name = "b".into();
    image::RgbaImage::from_raw(2, 1, vec![255, 255, 255, 0, 255, 255, 255, 128])
        .unwrap()
        .save(dir.path().join("b.png"))
        .unwrap();
    let rgb = load_view_image(dir.path(), &cam).unwrap();
    assert_eq!(&rgb[..3], [0.0; 3]);
    assert!(
        rgb[3..].iter().all(|&v| (v - 128.0 / 255.0).abs() < 1e-6),
        "{rgb:?}"
    );
}

/// A plain point cloud in ASCII (x y z and uchar colours, a point a line), as SfM tools
/// write `input.ply`, reads as a cloud.
#[test]
fn ascii_point_clouds_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let header = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                  property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
                  end_header\n";
    let p = write_tmp(
        dir.path(),
        "cloud.ply",
        format!("{header}0 1 2 255 0 0\n3 4 5 0 0 255\n"),
    );
    let cloud = semsplat::scene::ply::read_point_cloud_ply(&p)
        .unwrap()
        .expect("a cloud");
    assert_eq!(cloud.points, [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]);
    let short = write_tmp(
        dir.path(),
        "short.ply",
        format!("{header}0 1 2 255 0\n3 4 5 0 0 255\n"),
    );
    let err = error_of(semsplat::scene::ply::read_point_cloud_ply(&short));
    assert!(err.contains("more values"), "{err}");
}

// ---------------------------------------------------------------------------------------
// Found by fuzzing the readers

/// A compressed PLY (SuperSplat) of `n` packed vertices in `chunks` chunk rows, with an
/// `sh` element of 9 bytes per splat; binary. `packed_ty` is the packed words' type.
fn compressed_ply(header_n: usize, n: usize, packed_ty: &str) -> Vec<u8> {
    let mut h = String::from("ply\nformat binary_little_endian 1.0\nelement chunk 1\n");
    for p in [
        "x", "y", "z", "scale_x", "scale_y", "scale_z", "r", "g", "b",
    ] {
        h += &format!("property float min_{p}\nproperty float max_{p}\n");
    }
    h += &format!("element vertex {header_n}\n");
    for p in ["position", "rotation", "scale", "color"] {
        h += &format!("property {packed_ty} packed_{p}\n");
    }
    h += &format!("element sh {header_n}\n");
    for i in 0..9 {
        h += &format!("property uchar f_rest_{i}\n");
    }
    h += "end_header\n";
    let mut b = h.into_bytes();
    for k in 0..18 {
        b.extend_from_slice(&(k as f32).to_le_bytes());
    }
    for i in 0..n {
        for w in 0..4u32 {
            match packed_ty {
                "float" => b.extend_from_slice(&(-5.0f32 + w as f32).to_le_bytes()),
                _ => b.extend_from_slice(&(0x1234_5678 * (i as u32 + w)).to_le_bytes()),
            }
        }
    }
    b.extend(std::iter::repeat_n(128u8, 9 * n));
    b
}

/// An element without properties holds no bytes: a count of 2^64 - 1 must not be looped
/// over (the compressed-PLY and point-cloud readers hung), and data past the header's
/// counts is refused there as in the Gaussian reader (it was dropped silently, and the
/// compressed reader read its `sh` rows shifted into the vertices').
#[test]
fn ply_column_readers_skip_empty_rows_and_refuse_data_past_the_counts() {
    let dir = tempfile::tempdir().unwrap();
    for fmt in ["binary_little_endian", "ascii"] {
        let h = format!(
            "ply\nformat {fmt} 1.0\nelement chunk 0\nproperty float min_x\nelement vertex 0\n\
             property uint packed_position\nelement pad 18446744073709551615\nend_header\n"
        );
        let err = error_of(read_ply_from(h.as_bytes(), Some(h.len() as u64)));
        assert!(err.contains("no property 'packed_rotation'"), "{err}");
    }
    let xyz = "property float x\nproperty float y\nproperty float z\n";
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\n{xyz}\
         element pad 18446744073709551615\nend_header\n"
    )
    .into_bytes();
    bytes.extend_from_slice(&[0; 12]);
    let p = write_tmp(dir.path(), "pad.ply", &bytes);
    let cloud = semsplat::scene::ply::read_point_cloud_ply(&p)
        .unwrap()
        .unwrap();
    assert_eq!(cloud.points, [[0.0; 3]]);

    // One vertex declared, two stored.
    let mut bytes =
        format!("ply\nformat binary_little_endian 1.0\nelement vertex 1\n{xyz}end_header\n")
            .into_bytes();
    bytes.extend_from_slice(&[0; 24]);
    let p = write_tmp(dir.path(), "more.ply", &bytes);
    let err = error_of(semsplat::scene::ply::read_point_cloud_ply(&p));
    assert_error(&err, &p, &["data continues past", "counts are wrong"]);
    let p = write_tmp(
        dir.path(),
        "more_ascii.ply",
        format!("ply\nformat ascii 1.0\nelement vertex 1\n{xyz}end_header\n0 0 0\n1 1 1\n"),
    );
    let err = error_of(semsplat::scene::ply::read_point_cloud_ply(&p));
    assert_error(&err, &p, &["values continue past", "counts are wrong"]);

    // A compressed PLY whose counts say 2 of its 3 splats; a writer's padding passes.
    assert_eq!(
        read_ply_from(&compressed_ply(3, 3, "uint")[..], None)
            .unwrap()
            .len(),
        3
    );
    let mut padded = compressed_ply(3, 3, "uint");
    padded.push(b'\n');
    assert!(read_ply_from(&padded[..], None).is_ok());
    let err = error_of(read_ply_from(&compressed_ply(2, 3, "uint")[..], None));
    assert!(err.contains("data continues past"), "{err}");
}

/// Packed words are uint32 bit fields: a float property's -5 was cast to 0, silently.
#[test]
fn compressed_ply_words_that_are_not_uint32_are_errors() {
    let err = error_of(read_ply_from(&compressed_ply(1, 1, "float")[..], None));
    assert!(
        err.contains("'packed_position' value -5 is not a 32-bit unsigned word"),
        "{err}"
    );
}

fn spz(count: u32, splats: usize, fractional_bits: u8, flags: u8) -> Vec<u8> {
    use std::io::Write;
    let mut raw = 0x5053_474e_u32.to_le_bytes().to_vec();
    raw.extend_from_slice(&2u32.to_le_bytes());
    raw.extend_from_slice(&count.to_le_bytes());
    raw.extend_from_slice(&[0, fractional_bits, flags, 0]);
    // Positions: x = 2^22 in 24-bit fixed point; then alpha, colour, scale, rotation.
    for _ in 0..splats {
        raw.extend_from_slice(&[0, 0, 0x40, 0, 0, 0, 0, 0, 0]);
    }
    raw.extend(std::iter::repeat_n(128u8, splats * (1 + 3 + 3 + 3)));
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(&raw).unwrap();
    gz.finish().unwrap()
}

/// A count below the data read every later attribute stream from the previous one's bytes
/// (alphas from positions, ...); fractional bits past 23 were read as 23; a gzip stream
/// that is no .spz was inflated whole (up to 8 GiB) before its magic was looked at.
#[test]
fn spz_counts_below_the_data_and_unsupported_fractional_bits_are_errors() {
    use semsplat::scene::splat_formats::parse_spz;
    assert_eq!(parse_spz(&spz(3, 3, 12, 0)).unwrap().means[0][0], 1024.0);
    let err = error_of(parse_spz(&spz(2, 3, 12, 0)));
    assert!(
        err.contains("data continues past the .spz header's 2 splats"),
        "{err}"
    );
    // Extensions (flag 0x2) may follow the SH.
    assert_eq!(parse_spz(&spz(2, 3, 12, 2)).unwrap().len(), 2);
    assert_eq!(
        parse_spz(&spz(1, 1, 30, 0)).unwrap().means[0][0],
        1.0 / 256.0
    );
    let err = error_of(parse_spz(&spz(1, 1, 200, 0)));
    assert!(err.contains("fractional bits 200"), "{err}");
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, &[0u8; 1 << 16]).unwrap();
    let err = error_of(parse_spz(&gz.finish().unwrap()));
    assert!(err.contains("not an .spz stream"), "{err}");
}

/// npyz multiplied the shape unchecked (a panic: overflow checks are on in release) and
/// allocated a version 2 header's length whole (4 GiB for a 15-byte file).
#[test]
fn npy_headers_that_do_not_fit_are_errors_not_panics() {
    use semsplat::util::npy::parse_npy_f64;
    let header =
        |shape: &str| format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}");
    let err = error_of(parse_npy_f64(&npy_v1(
        &header("(4294967296, 4294967296)"),
        &[],
    )));
    assert!(
        err.contains("shape [4294967296, 4294967296] is too large"),
        "{err}"
    );
    let err = error_of(parse_npy_f64(&npy_v1(&header("(0x100000000, 2)"), &[])));
    assert!(err.contains("not a tuple of whole numbers"), "{err}");
    let err = error_of(parse_npy_f64(b"\x93NUMPY\x02\x00\xff\xff\xff\xff{'de"));
    assert!(err.contains("header claims 4294967295 bytes"), "{err}");
    // An empty evidence matrix whose other dimension is huge: refused, not allocated.
    let tmp = tempfile::tempdir().unwrap();
    let empty = tmp.path().join("empty.npy");
    std::fs::write(&empty, npy_v1(&header("(0, 1099511627776)"), &[])).unwrap();
    let err = error_of(semsplat::fuse::scores::ClassScores::load_npy(&empty));
    assert!(err.contains("an empty matrix"), "{err}");
    // A shape that fits still reads.
    let ok = npy_v1(&header("(2,)"), &[0; 16]);
    assert_eq!(parse_npy_f64(&ok).unwrap().shape, [2]);
}

/// A distortion coefficient or camera model of the wrong JSON type was skipped, reading a
/// distorted camera as a pinhole one.
#[test]
fn nerfstudio_distortion_that_is_not_a_number_is_an_error() {
    let json = |extra: &str| {
        format!(
            r#"{{"fl_x": 500, "fl_y": 500, "cx": 320, "cy": 240, "w": 640, "h": 480, {extra}
            "frames": [{{"file_path": "a.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,2],[0,0,0,1]]}}]}}"#
        )
    };
    for (extra, needle) in [
        (r#""k1": "0.3","#, "distortion k1 = \"0.3\" is not a number"),
        (r#""p1": [0.1],"#, "distortion p1 = [0.1] is not a number"),
        (
            r#""camera_model": 5,"#,
            "camera_model 5 is not a model name",
        ),
    ] {
        let err = error_of(parse_cameras_json(json(extra).as_bytes()));
        assert!(err.contains(needle), "{err}");
    }
    assert!(parse_cameras_json(json(r#""k1": null, "camera_model": null,"#).as_bytes()).is_ok());
}

/// Joining a name's words turned two spaces or a tab into one space.
#[test]
fn colmap_text_image_names_keep_their_whitespace() {
    let text = "1 1 0 0 0 0 0 0 1 my  image.png\n\n2 1 0 0 0 0 0 1 1 tab\there.png  \n";
    let images = semsplat::scene::colmap::read_images_txt_from(&mut text.as_bytes()).unwrap();
    let names: Vec<&str> = images.iter().map(|i| i.name.as_str()).collect();
    assert_eq!(names, ["my  image.png", "tab\there.png"]);
}

/// A 57-byte PNG claiming 16384 x 16384 RGBA had a 1 GiB buffer zeroed (about a second)
/// before its decoder found no data.
#[test]
fn label_pngs_too_small_for_their_size_are_refused_from_the_header() {
    let dir = tempfile::tempdir().unwrap();
    let mut png = b"\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\x40\0\0\0\x40\0\x08\x06\0\0\0".to_vec();
    png.extend_from_slice(&[0; 4]); // CRC (not read before the check)
    png.extend_from_slice(b"\0\0\0\0IDAT\0\0\0\0\0\0\0\0IEND\0\0\0\0");
    let p = write_tmp(dir.path(), "huge.png", &png);
    let err = error_of(read_label_png(&p));
    assert_error(&err, &p, &["16384x16384", "cannot hold that many pixels"]);
}

/// A mistyped scene without --cameras is named as missing, not as a folder without cameras.
#[test]
fn a_missing_scene_is_named_before_its_cameras_are_looked_for() {
    use semsplat::scene::scene_file::cameras_for_scene;
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nosuch.ply");
    let err = error_of(cameras_for_scene(None, &missing));
    assert_error(&err, &missing, &["does not exist"]);
    assert!(!err.contains("--cameras"), "{err}");
    // An existing scene in a folder without cameras still asks for them.
    let scene = write_tmp(dir.path(), "scene.ply", b"ply\n");
    let err = error_of(cameras_for_scene(None, &scene));
    assert!(err.contains("--cameras is needed"), "{err}");
}
