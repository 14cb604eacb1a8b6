//! Round trips and hand-written files for the scene formats: PLY, COLMAP, camera JSON,
//! label PNGs, class tables, atomic writes.

use std::path::Path;

use glam::{DMat3, DQuat, DVec3};
use semsplat::dataset::CompactClasses;
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::cameras_json::{
    read_cameras_json, read_cameras_json_kind, write_inria_cameras, write_semsplat_cameras,
    CameraJsonKind,
};
use semsplat::scene::classes::{default_color, read_class_table, write_class_table, ClassTable};
use semsplat::scene::colmap::{read_colmap_model, write_colmap_model, ColmapFormat};
use semsplat::scene::gaussians::sh_coeffs_for_degree;
use semsplat::scene::labels::{
    load_label_dir, read_label_png, write_label_png, write_palette_png, LabelDir, LabelMap,
    MissingLabels,
};
use semsplat::scene::ply::{
    classes_sidecar_path, read_classes_sidecar, read_ply, read_ply_from, write_classes_sidecar,
    write_ply,
};
use semsplat::scene::{Camera, ClassInfo, Gaussians, SemanticLogits, Split};
use semsplat::util::{write_atomic, Rng};

fn random_gaussians(n: usize, sh_degree: u32, seed: u64) -> Gaussians {
    let mut rng = Rng::new(seed);
    let mut f = || rng.range_f64(-3.0, 3.0) as f32;
    let k = sh_coeffs_for_degree(sh_degree);
    Gaussians {
        means: (0..n).map(|_| [f(), f(), f()]).collect(),
        log_scales: (0..n).map(|_| [f(), f(), f()]).collect(),
        quats: (0..n).map(|_| [f() + 4.0, f(), f(), f()]).collect(),
        opacity_logits: (0..n).map(|_| f()).collect(),
        sh_degree,
        sh: (0..n * k * 3).map(|_| f()).collect(),
        ..Default::default()
    }
}

fn with_semantics(mut g: Gaussians, channels: usize) -> Gaussians {
    let n = g.len();
    g.class_ids = Some((0..n).map(|i| (i as i32 % 7) - 1).collect());
    g.class_conf = Some((0..n).map(|i| (i % 11) as f32 / 10.0).collect());
    g.instance_ids = Some((0..n).map(|i| (i as i32 % 4) - 1).collect());
    g.semantics = Some(SemanticLogits {
        channels,
        logits: (0..n * channels).map(|i| i as f32 * 0.25 - 3.0).collect(),
    });
    g
}

fn ply_header(path: &Path) -> Vec<String> {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap();
    String::from_utf8(bytes[..end].to_vec())
        .unwrap()
        .lines()
        .map(str::to_owned)
        .collect()
}

fn property_names(header: &[String]) -> Vec<String> {
    header
        .iter()
        .filter_map(|l| l.strip_prefix("property "))
        .map(|l| l.split_whitespace().last().unwrap().to_owned())
        .collect()
}

#[test]
fn ply_round_trips_every_sh_degree_without_semantics() {
    let dir = tempfile::tempdir().unwrap();
    for degree in 0..=3 {
        let g = random_gaussians(37, degree, degree as u64);
        let path = dir.path().join(format!("deg{degree}.ply"));
        write_ply(&path, &g).unwrap();
        let back = read_ply(&path).unwrap();
        assert_eq!(back, g, "degree {degree}");
        let names = property_names(&ply_header(&path));
        let rest = names.iter().filter(|n| n.starts_with("f_rest_")).count();
        assert_eq!(rest, [0, 9, 24, 45][degree as usize]);
    }
}

#[test]
fn ply_round_trips_semantics_and_keeps_standard_properties_first() {
    let dir = tempfile::tempdir().unwrap();
    let g = with_semantics(random_gaussians(50, 1, 9), 5);
    let path = dir.path().join("sem.ply");
    write_ply(&path, &g).unwrap();
    assert_eq!(read_ply(&path).unwrap(), g);

    let names = property_names(&ply_header(&path));
    let mut expected: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    expected.extend((0..9).map(|i| format!("f_rest_{i}")));
    expected.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    expected.extend(["class", "class_conf", "instance"].map(String::from));
    expected.extend((0..5).map(|i| format!("sem_{i}")));
    assert_eq!(names, expected);
    let header = ply_header(&path);
    assert!(header.contains(&"format binary_little_endian 1.0".to_owned()));
    assert!(header.contains(&"property int class".to_owned()));

    // Only some semantic fields set: only those are written.
    let mut partial = random_gaussians(5, 0, 3);
    partial.class_ids = Some(vec![3, -1, 0, 2, 2]);
    let path = dir.path().join("partial.ply");
    write_ply(&path, &partial).unwrap();
    let back = read_ply(&path).unwrap();
    assert_eq!(back, partial);
    assert!(back.class_conf.is_none() && back.semantics.is_none() && back.instance_ids.is_none());
}

#[test]
fn ply_reads_f_rest_channel_major_from_hand_built_binary() {
    // Degree 1: 3 rest coefficients per channel, stored R1 R2 R3 G1 G2 G3 B1 B2 B3.
    let mut text = String::from("ply\nformat binary_little_endian 1.0\nelement vertex 1\n");
    let mut names: Vec<String> = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"]
        .map(String::from)
        .to_vec();
    names.extend((0..9).map(|i| format!("f_rest_{i}")));
    names.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    for n in &names {
        text.push_str(&format!("property float {n}\n"));
    }
    text.push_str("end_header\n");
    let mut bytes = text.into_bytes();
    // x y z, dc, rest (100 + i), opacity, scales, quat
    let mut values = vec![1.0f32, 2.0, 3.0, 0.1, 0.2, 0.3];
    values.extend((0..9).map(|i| 100.0 + i as f32));
    values.extend([-0.5, -1.0, -2.0, -3.0, 1.0, 0.0, 0.0, 0.0]);
    for v in &values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let g = read_ply_from(&bytes[..], Some(bytes.len() as u64)).unwrap();
    assert_eq!(g.len(), 1);
    assert_eq!(g.sh_degree, 1);
    assert_eq!(g.means[0], [1.0, 2.0, 3.0]);
    assert_eq!(g.opacity_logits[0], -0.5);
    assert_eq!(g.log_scales[0], [-1.0, -2.0, -3.0]);
    assert_eq!(g.quats[0], [1.0, 0.0, 0.0, 0.0]);
    // sh[coeff][rgb]
    assert_eq!(&g.sh[0..3], &[0.1, 0.2, 0.3]);
    for coeff in 1..4 {
        for ch in 0..3 {
            let expected = 100.0 + (ch * 3 + coeff - 1) as f32;
            assert_eq!(g.sh[coeff * 3 + ch], expected, "coeff {coeff} channel {ch}");
        }
    }
}

/// The 14 required property names in a shuffled order plus extras of other types.
const MIXED_HEADER: &str = "property double x
property float y
property float z
property float nx
property uchar red
property float f_dc_0
property float f_dc_1
property float f_dc_2
property float opacity
property float scale_0
property float scale_1
property float scale_2
property float rot_0
property float rot_1
property float rot_2
property float rot_3
property short class
property double class_conf
";

#[test]
fn ply_reads_hand_written_ascii_with_extra_properties_and_a_preceding_element() {
    let text = format!(
        "ply\nformat ascii 1.0\ncomment hand written\nelement camera 1\nproperty float fov\n\
         element vertex 2\n{MIXED_HEADER}end_header\n\
         0.5\n\
         1.5 -2 3e-1 0 255 0.25 0.5 0.75 -1.5 -4 -5 -6 0.5 0.5 0.5 0.5 4 0.9\n\
         -1 0 0 0 7 1 1 1 2 0 0 0 1 0 0 0 -1 0\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hand.ply");
    std::fs::write(&path, text).unwrap();
    let g = read_ply(&path).unwrap();
    assert_eq!(g.len(), 2);
    assert_eq!(g.sh_degree, 0);
    assert_eq!(g.means, vec![[1.5, -2.0, 0.3], [-1.0, 0.0, 0.0]]);
    assert_eq!(&g.sh[..3], &[0.25, 0.5, 0.75]);
    assert_eq!(g.opacity_logits, vec![-1.5, 2.0]);
    assert_eq!(g.log_scales[0], [-4.0, -5.0, -6.0]);
    assert_eq!(g.quats[1], [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(g.class_ids, Some(vec![4, -1]));
    assert_eq!(g.class_conf, Some(vec![0.9, 0.0]));
    assert!(g.instance_ids.is_none() && g.semantics.is_none());
}

fn mixed_binary_ply(big_endian: bool) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut bytes =
        format!("ply\nformat {format} 1.0\nelement vertex 2\n{MIXED_HEADER}end_header\n")
            .into_bytes();
    for v in 0..2 {
        let s = v as f32;
        let mut put = |b: &[u8]| bytes.extend_from_slice(b);
        let f = |x: f32| {
            if big_endian {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        };
        let d = |x: f64| {
            if big_endian {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            }
        };
        put(&d(10.0 + s as f64)); // x
        put(&f(20.0 + s)); // y
        put(&f(30.0 + s)); // z
        put(&f(0.0)); // nx
        put(&[200]); // red
        for x in [
            0.1,
            0.2,
            0.3,
            -2.0 + s,
            -1.0,
            -1.5,
            -2.0,
            0.0,
            1.0,
            0.0,
            0.0,
        ] {
            put(&f(x));
        }
        let class: i16 = 300 + v;
        put(&if big_endian {
            class.to_be_bytes()
        } else {
            class.to_le_bytes()
        });
        put(&d(0.75));
    }
    bytes
}

#[test]
fn ply_reads_hand_built_binary_little_and_big_endian_with_mixed_types() {
    for big_endian in [false, true] {
        let bytes = mixed_binary_ply(big_endian);
        let g = read_ply_from(&bytes[..], None).unwrap();
        assert_eq!(g.len(), 2, "big endian: {big_endian}");
        assert_eq!(g.means, vec![[10.0, 20.0, 30.0], [11.0, 21.0, 31.0]]);
        assert_eq!(g.opacity_logits, vec![-2.0, -1.0]);
        assert_eq!(g.log_scales[1], [-1.0, -1.5, -2.0]);
        assert_eq!(g.quats[0], [0.0, 1.0, 0.0, 0.0]);
        assert_eq!(g.class_ids, Some(vec![300, 301]));
        assert_eq!(g.class_conf, Some(vec![0.75, 0.75]));
    }
}

#[test]
fn class_table_sidecar_sits_beside_the_ply() {
    assert_eq!(
        classes_sidecar_path(Path::new("out/scene.ply")),
        Path::new("out/scene.classes.json")
    );
    assert_eq!(
        classes_sidecar_path(Path::new("scene.PLY")),
        Path::new("scene.classes.json")
    );
    assert_eq!(
        classes_sidecar_path(Path::new("a/scene")),
        Path::new("a/scene.classes.json")
    );
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("scene.ply");
    assert_eq!(read_classes_sidecar(&ply).unwrap(), None);
    let table = ClassTable {
        classes: vec![
            ClassInfo {
                id: 3,
                name: "chair".into(),
                color: [1, 2, 3],
            },
            ClassInfo {
                id: 0,
                name: "wall".into(),
                color: [9, 9, 9],
            },
        ],
    };
    write_classes_sidecar(&ply, &table).unwrap();
    let back = read_classes_sidecar(&ply).unwrap().unwrap();
    // Written sorted by id.
    assert_eq!(
        back.classes.iter().map(|c| c.id).collect::<Vec<_>>(),
        vec![0, 3]
    );
    assert_eq!(back.by_name("chair").unwrap().color, [1, 2, 3]);
}

// ---------------------------------------------------------------------------------------
// Cameras

fn test_cameras() -> Vec<Camera> {
    let mut rng = Rng::new(42);
    (0..5)
        .map(|i| {
            let axis = DVec3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
            let rotation = DMat3::from_quat(DQuat::from_axis_angle(axis, rng.range_f64(-3.0, 3.0)));
            let wide = i % 2 == 0;
            Camera {
                name: format!("frame_{i:03}"),
                width: if wide { 640 } else { 320 },
                height: if wide { 480 } else { 240 },
                fx: if wide { 500.0 } else { 260.5 },
                fy: if wide { 501.25 } else { 260.5 },
                cx: if wide { 320.5 } else { 158.0 },
                cy: if wide { 239.75 } else { 121.0 },
                rotation,
                translation: DVec3::new(rng.normal(), rng.normal(), rng.normal()),
                split: Split::Train,
            }
        })
        .collect()
}

fn assert_cameras_close(got: &[Camera], want: &[Camera], tol: f64) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g.name, w.name);
        assert_eq!(
            (g.width, g.height, g.split),
            (w.width, w.height, w.split),
            "{}",
            w.name
        );
        for (a, b) in [(g.fx, w.fx), (g.fy, w.fy), (g.cx, w.cx), (g.cy, w.cy)] {
            assert!((a - b).abs() <= tol, "{}: intrinsics {a} vs {b}", w.name);
        }
        assert!(
            g.rotation.abs_diff_eq(w.rotation, tol),
            "{}: rotation",
            w.name
        );
        assert!(
            g.translation.abs_diff_eq(w.translation, tol),
            "{}: translation",
            w.name
        );
    }
}

#[test]
fn colmap_round_trips_binary_and_text() {
    let cams = test_cameras();
    for format in [ColmapFormat::Binary, ColmapFormat::Text] {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("sparse").join("0");
        write_colmap_model(&model, &cams, format, "jpg").unwrap();
        assert!(model
            .join(if format == ColmapFormat::Binary {
                "points3D.bin"
            } else {
                "points3D.txt"
            })
            .is_file());
        // The model folder, the dataset folder and one of the files all work.
        for path in [
            model.clone(),
            dir.path().to_owned(),
            model.join(if format == ColmapFormat::Binary {
                "images.bin"
            } else {
                "images.txt"
            }),
        ] {
            let back = load_cameras(&path).unwrap();
            assert_cameras_close(&back, &cams, 1e-12);
        }
    }
}

#[test]
fn colmap_text_written_by_hand_is_read() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("cameras.txt"),
        "# Camera list\n1 SIMPLE_PINHOLE 100 80 90 50 40\n2 PINHOLE 200 100 150 160 99.5 50.5\n\
         3 OPENCV 200 100 150 160 99.5 50.5 0 0 0 0\n",
    )
    .unwrap();
    // The second pose line has an empty points line after it; the first has points.
    std::fs::write(
        dir.path().join("images.txt"),
        "# Image list\n\
         7 1 0 0 0 1 2 3 1 images/b.png\n\
         10.5 20.5 -1 11 21 5\n\
         3 0 1 0 0 0 0 -1 2 sub/dir/a.JPG\n\
         \n\
         9 1 0 0 0 0 0 0 3 c.frame.jpeg\n",
    )
    .unwrap();
    let cams = read_colmap_model(dir.path()).unwrap();
    let names: Vec<&str> = cams.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, vec!["a", "b", "c.frame"]); // sorted, stems
    let a = &cams[0];
    assert_eq!(
        (a.width, a.height, a.fx, a.fy, a.cx, a.cy),
        (200, 100, 150.0, 160.0, 99.5, 50.5)
    );
    // qvec (0, 1, 0, 0): 180 degrees about x.
    assert!(a
        .rotation
        .abs_diff_eq(DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0)), 1e-15));
    assert_eq!(a.translation, DVec3::new(0.0, 0.0, -1.0));
    let b = &cams[1];
    assert_eq!((b.fx, b.fy, b.cx, b.cy), (90.0, 90.0, 50.0, 40.0));
    assert_eq!(b.translation, DVec3::new(1.0, 2.0, 3.0));
    assert_eq!(b.center(), DVec3::new(-1.0, -2.0, -3.0));
    // OPENCV with zero distortion is a pinhole camera.
    assert_eq!(cams[2].fx, 150.0);
}

#[test]
fn colmap_binary_built_by_hand_is_read_and_2d_points_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let mut cams = Vec::new();
    cams.extend_from_slice(&1u64.to_le_bytes());
    cams.extend_from_slice(&5u32.to_le_bytes()); // camera id
    cams.extend_from_slice(&0i32.to_le_bytes()); // SIMPLE_PINHOLE
    cams.extend_from_slice(&64u64.to_le_bytes());
    cams.extend_from_slice(&48u64.to_le_bytes());
    for v in [70.0f64, 32.0, 24.0] {
        cams.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(dir.path().join("cameras.bin"), cams).unwrap();
    let mut imgs = Vec::new();
    imgs.extend_from_slice(&2u64.to_le_bytes());
    for (id, name, points, tz) in [(4u32, "x/one.png", 3u64, 5.0f64), (9, "two.png", 0, 6.0)] {
        imgs.extend_from_slice(&id.to_le_bytes());
        for v in [2.0f64, 0.0, 0.0, 0.0, 0.0, 0.0, tz] {
            imgs.extend_from_slice(&v.to_le_bytes()); // unnormalized identity qvec, tvec
        }
        imgs.extend_from_slice(&5u32.to_le_bytes());
        imgs.extend_from_slice(name.as_bytes());
        imgs.push(0);
        imgs.extend_from_slice(&points.to_le_bytes());
        for p in 0..points {
            imgs.extend_from_slice(&(p as f64).to_le_bytes());
            imgs.extend_from_slice(&1.0f64.to_le_bytes());
            imgs.extend_from_slice(&(-1i64).to_le_bytes());
        }
    }
    std::fs::write(dir.path().join("images.bin"), imgs).unwrap();
    let cams = read_colmap_model(dir.path()).unwrap();
    assert_eq!(cams.len(), 2);
    assert_eq!(cams[0].name, "one");
    assert_eq!(cams[1].name, "two");
    assert_eq!(
        (
            cams[0].width,
            cams[0].height,
            cams[0].fx,
            cams[0].fy,
            cams[0].cx
        ),
        (64, 48, 70.0, 70.0, 32.0)
    );
    assert!(cams[0].rotation.abs_diff_eq(DMat3::IDENTITY, 1e-15));
    assert_eq!(cams[1].translation.z, 6.0);
}

#[test]
fn camera_jsons_round_trip_and_are_told_apart() {
    let mut cams = test_cameras();
    cams[1].split = Split::Test;
    let dir = tempfile::tempdir().unwrap();
    let semsplat_path = dir.path().join("cams.json");
    write_semsplat_cameras(&semsplat_path, &cams).unwrap();
    let (kind, back) = read_cameras_json_kind(&semsplat_path).unwrap();
    assert_eq!(kind, CameraJsonKind::Semsplat);
    // serde_json parses floats to within 1 ulp (no `float_roundtrip` feature).
    assert_cameras_close(&back, &cams, 1e-12);
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&semsplat_path).unwrap()).unwrap();
    assert_eq!(v["format"], "semsplat-cameras");
    assert_eq!(v["version"], 1);
    assert_eq!(v["cameras"][1]["split"], "test");
    assert_eq!(
        v["cameras"][0]["world_to_camera"][3],
        serde_json::json!([0.0, 0.0, 0.0, 1.0])
    );

    // INRIA has no splits: everything loads as train.
    let inria_path = dir.path().join("cameras.json");
    write_inria_cameras(&inria_path, &cams).unwrap();
    let (kind, back) = read_cameras_json_kind(&inria_path).unwrap();
    assert_eq!(kind, CameraJsonKind::Inria);
    cams[1].split = Split::Train;
    assert_cameras_close(&back, &cams, 1e-12);
    assert_cameras_close(&load_cameras(&inria_path).unwrap(), &cams, 1e-12);
}

#[test]
fn inria_json_written_by_hand_is_read() {
    // Camera at (1, 2, 3) looking down world -z: camera-to-world = diag(1, -1, -1).
    let text = r#"[{"id": 0, "img_name": "00001", "width": 800, "height": 600,
        "position": [1.0, 2.0, 3.0],
        "rotation": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        "fy": 700.0, "fx": 710.0},
        {"id": 1, "img_name": "00002.png", "width": 800, "height": 600,
        "position": [0.0, 0.0, 0.0], "rotation": [[0, 1, 0], [-1, 0, 0], [0, 0, 1]],
        "fx": 710.0, "fy": 700.0, "cx": 390.0, "cy": 310.0}]"#;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cameras.json");
    std::fs::write(&path, text).unwrap();
    let cams = read_cameras_json(&path).unwrap();
    assert_eq!(cams[0].name, "00001");
    assert_eq!(cams[1].name, "00002");
    assert_eq!((cams[0].cx, cams[0].cy), (400.0, 300.0));
    assert_eq!((cams[1].cx, cams[1].cy), (390.0, 310.0));
    assert_eq!((cams[0].fx, cams[0].fy), (710.0, 700.0));
    assert!(cams[0]
        .center()
        .abs_diff_eq(DVec3::new(1.0, 2.0, 3.0), 1e-15));
    // World point one unit in front of the camera (world -z) projects to the center.
    let pc = cams[0].world_to_camera(DVec3::new(1.0, 2.0, 2.0));
    assert!(pc.abs_diff_eq(DVec3::new(0.0, 0.0, 1.0), 1e-15));
    // Camera-to-world rows [[0,1,0],[-1,0,0],[0,0,1]]: camera x axis is world -y.
    let pc = cams[1].world_to_camera(DVec3::new(0.0, -1.0, 0.0));
    assert!(pc.abs_diff_eq(DVec3::new(1.0, 0.0, 0.0), 1e-15));
}

#[test]
fn semsplat_json_written_by_hand_is_read() {
    let text = r#"{"format": "semsplat-cameras", "version": 1, "cameras": [
        {"name": "v0", "width": 4, "height": 3, "fx": 2, "fy": 3, "cx": 2, "cy": 1.5,
         "world_to_camera": [[1,0,0,5],[0,1,0,6],[0,0,1,7],[0,0,0,1]], "split": "test"},
        {"name": "v1", "width": 4, "height": 3, "fx": 2, "fy": 3, "cx": 2, "cy": 1.5,
         "world_to_camera": [[0,-1,0,0],[1,0,0,0],[0,0,1,0],[0,0,0,1]]}]}"#;
    let (kind, cams) = semsplat::scene::cameras_json::parse_cameras_json(text.as_bytes()).unwrap();
    assert_eq!(kind, CameraJsonKind::Semsplat);
    assert_eq!(cams[0].split, Split::Test);
    assert_eq!(cams[1].split, Split::Train);
    assert_eq!(cams[0].translation, DVec3::new(5.0, 6.0, 7.0));
    // Row-major: camera x = -world y.
    assert_eq!(
        cams[1].world_to_camera(DVec3::new(0.0, 1.0, 0.0)),
        DVec3::new(-1.0, 0.0, 0.0)
    );
}

// ---------------------------------------------------------------------------------------
// Label maps and class tables

fn png_bit_depth(path: &Path) -> u8 {
    std::fs::read(path).unwrap()[24]
}

#[test]
fn label_pngs_round_trip_8_and_16_bit() {
    let dir = tempfile::tempdir().unwrap();
    let small = LabelMap::new(3, 2, vec![0, 1, 254, LabelMap::IGNORE, 7, 0]).unwrap();
    let p8 = dir.path().join("small.png");
    write_label_png(&p8, &small).unwrap();
    assert_eq!(png_bit_depth(&p8), 8);
    assert_eq!(read_label_png(&p8).unwrap(), small);
    // 255 is the 8-bit ignore value on disk.
    let img = image::open(&p8).unwrap().into_luma8();
    assert_eq!(img.get_pixel(0, 1).0[0], 255);

    let large = LabelMap::new(2, 2, vec![255, 1000, LabelMap::IGNORE, 65534]).unwrap();
    let p16 = dir.path().join("large.png");
    write_label_png(&p16, &large).unwrap();
    assert_eq!(png_bit_depth(&p16), 16);
    assert_eq!(read_label_png(&p16).unwrap(), large);
    assert_eq!(large.get(1, 0), Some(1000));
    assert_eq!(large.get(2, 0), None);

    // 8-bit files written by other tools: 255 loads as IGNORE.
    let other = image::GrayImage::from_raw(2, 1, vec![255, 3]).unwrap();
    let p = dir.path().join("other.png");
    other.save(&p).unwrap();
    assert_eq!(
        read_label_png(&p).unwrap().labels,
        vec![LabelMap::IGNORE, 3]
    );
}

#[test]
fn palette_png_uses_table_colors_fallbacks_and_black_for_ignore() {
    let dir = tempfile::tempdir().unwrap();
    let table = ClassTable {
        classes: vec![ClassInfo {
            id: 2,
            name: "floor".into(),
            color: [10, 20, 30],
        }],
    };
    let map = LabelMap::new(3, 1, vec![2, 9, LabelMap::IGNORE]).unwrap();
    let path = dir.path().join("vis.png");
    write_palette_png(&path, &map, &table).unwrap();
    let img = image::open(&path).unwrap().into_rgb8();
    assert_eq!(img.get_pixel(0, 0).0, [10, 20, 30]);
    assert_eq!(img.get_pixel(1, 0).0, default_color(9));
    assert_eq!(img.get_pixel(2, 0).0, [0, 0, 0]);
    assert_ne!(default_color(9), default_color(10));
    assert_eq!(default_color(9), default_color(9));
}

fn camera_named(name: &str, width: u32, height: u32) -> Camera {
    Camera {
        name: name.into(),
        width,
        height,
        fx: 10.0,
        fy: 10.0,
        cx: width as f64 / 2.0,
        cy: height as f64 / 2.0,
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        split: Split::Train,
    }
}

#[test]
fn label_folder_streams_maps_in_camera_order() {
    let dir = tempfile::tempdir().unwrap();
    let cams = vec![
        camera_named("b", 2, 1),
        camera_named("a", 2, 1),
        camera_named("c", 2, 1),
    ];
    write_label_png(
        &dir.path().join("a.png"),
        &LabelMap::new(2, 1, vec![1, 1]).unwrap(),
    )
    .unwrap();
    write_label_png(
        &dir.path().join("b.png"),
        &LabelMap::new(2, 1, vec![2, LabelMap::IGNORE]).unwrap(),
    )
    .unwrap();
    write_label_png(
        &dir.path().join("c.png"),
        &LabelMap::new(2, 1, vec![3, 1]).unwrap(),
    )
    .unwrap();
    std::fs::write(dir.path().join("notes.txt"), "not a label map").unwrap();
    let table = ClassTable::from_ids([1, 2, 3]);
    let labels = LabelDir::open(dir.path(), &cams, Some(&table), MissingLabels::Error).unwrap();
    let seen: Vec<(usize, Vec<u16>)> = labels
        .iter()
        .map(|r| r.map(|(i, m)| (i, m.labels)).unwrap())
        .collect();
    assert_eq!(
        seen,
        vec![
            (0, vec![2, LabelMap::IGNORE]),
            (1, vec![1, 1]),
            (2, vec![3, 1])
        ]
    );
    assert_eq!(load_label_dir(dir.path(), &cams, None).unwrap().len(), 3);

    // Skipping policy: a camera without a map is left out and reported.
    let more = vec![camera_named("a", 2, 1), camera_named("zzz", 2, 1)];
    let labels = LabelDir::open(dir.path(), &more, None, MissingLabels::Skip).unwrap();
    assert_eq!(labels.len(), 1);
    assert_eq!(labels.skipped(), ["zzz".to_owned()]);
}

#[test]
fn class_tables_parse_both_shapes_and_round_trip() {
    let list =
        ClassTable::from_json_str(r#"[{"id": 4, "name": "sofa", "color": [1, 2, 3]}, {"id": 0}]"#)
            .unwrap();
    assert_eq!(list.get(4).unwrap().name, "sofa");
    assert_eq!(list.get(0).unwrap().name, "class_0");
    assert_eq!(list.get(0).unwrap().color, default_color(0));
    assert_eq!(list.by_name("sofa").unwrap().id, 4);
    assert_eq!(list.color_of(77), default_color(77));
    let obj = ClassTable::from_json_str(
        r#"{"classes": [{"id": 4, "name": "sofa", "color": [1, 2, 3]}, {"id": 0}]}"#,
    )
    .unwrap();
    assert_eq!(obj, list);

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("classes.json");
    write_class_table(&path, &list).unwrap();
    let back = read_class_table(&path).unwrap();
    assert_eq!(back.len(), 2);
    assert_eq!(back.get(4), list.get(4));
    assert_eq!(back.get(0), list.get(0));
}

#[test]
fn compact_classes_number_present_ids_in_order() {
    let maps = [
        LabelMap::new(2, 2, vec![40, 7, LabelMap::IGNORE, 7]).unwrap(),
        LabelMap::new(1, 1, vec![1000]).unwrap(),
    ];
    let compact = CompactClasses::from_ids(maps.iter().flat_map(|m| m.present_ids())).unwrap();
    assert_eq!(compact.len(), 3);
    assert_eq!(compact.user_ids(), &[7, 40, 1000]);
    assert_eq!(compact.compact_of(40), Some(1));
    assert_eq!(compact.compact_of(8), None);
    assert_eq!(compact.user_of(2), Some(1000));
    assert_eq!(compact.user_of(3), None);
    let lut = compact.label_lut();
    assert_eq!(
        (lut[7], lut[1000], lut[LabelMap::IGNORE as usize], lut[5]),
        (0, 2, u16::MAX, u16::MAX)
    );
    let names = ClassTable {
        classes: vec![ClassInfo {
            id: 40,
            name: "lamp".into(),
            color: [5, 5, 5],
        }],
    };
    let t = compact.table(&names);
    assert_eq!(
        t.classes
            .iter()
            .map(|c| c.name.as_str())
            .collect::<Vec<_>>(),
        vec!["class_7", "lamp", "class_1000"]
    );
    let from_table = CompactClasses::from_table(&names).unwrap();
    assert_eq!(from_table.user_ids(), &[40]);
}

// ---------------------------------------------------------------------------------------
// Atomic writes

#[test]
fn write_atomic_leaves_no_file_when_writing_fails() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("out.bin");
    let result = write_atomic(&target, |w| {
        w.write_all(&[1u8; 100_000])?;
        anyhow::bail!("simulated failure halfway")
    });
    let err = format!("{:#}", result.unwrap_err());
    assert!(
        err.contains("simulated failure") && err.contains("out.bin"),
        "{err}"
    );
    assert!(!target.exists());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "temp file left behind"
    );

    // An existing file is left untouched by a failed rewrite.
    std::fs::write(&target, b"old").unwrap();
    let result = write_atomic(&target, |w| {
        w.write_all(b"new, half written")?;
        anyhow::bail!("fail again")
    });
    assert!(result.is_err());
    assert_eq!(std::fs::read(&target).unwrap(), b"old");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

    // A PLY write that fails (inconsistent arrays) leaves nothing either.
    let mut g = random_gaussians(3, 0, 1);
    g.opacity_logits.pop();
    let ply = dir.path().join("bad.ply");
    assert!(write_ply(&ply, &g).is_err());
    assert!(!ply.exists());
}

// ---------------------------------------------------------------------------------------
// `semsplat inspect`

fn inspect(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .arg("inspect")
        .args(args)
        .output()
        .unwrap();
    let text = |b: Vec<u8>| String::from_utf8(b).unwrap();
    (out.status.success(), text(out.stdout), text(out.stderr))
}

/// A clean scene with semantics and a class table beside it: `inspect --json` counts its
/// Gaussians, SH degree and classes, names them from the table, and finds no problem.
/// Returns the scene written.
fn check_inspect_summarizes_clean_scene(ply: &Path) -> Gaussians {
    let g = with_semantics(random_gaussians(20, 2, 5), 3);
    write_ply(ply, &g).unwrap();
    write_classes_sidecar(ply, &ClassTable::from_ids(0..6)).unwrap();
    let (ok, stdout, stderr) = inspect(&[ply.as_os_str(), "--json".as_ref()]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["gaussians"], 20);
    assert_eq!(v["sh_degree"], 2);
    assert_eq!(v["problems"].as_array().unwrap().len(), 0);
    let classes = v["classes"].as_array().unwrap();
    let count_of = |id: i64| {
        classes
            .iter()
            .find(|c| c["id"] == id)
            .map(|c| c["count"].as_u64().unwrap())
    };
    assert_eq!(count_of(-1), Some(3)); // ids cycle -1..=5 over 20 Gaussians
    assert_eq!(count_of(5), Some(2));
    assert_eq!(
        classes.iter().find(|c| c["id"] == 2).unwrap()["name"],
        "class_2"
    );
    // The folder holding scene.ply is its scene, not a label folder.
    let (ok, stdout, stderr) = inspect(&[ply.parent().unwrap().as_os_str(), "--json".as_ref()]);
    assert!(ok, "{stderr}");
    let folder: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(folder["gaussians"], 20);
    g
}

/// `g` with a zero quaternion at 4 and a NaN position at 7, written to `ply` as another
/// tool's file would hold it: `inspect` fails and names both problems.
fn check_inspect_fails_on_broken_scene(ply: &Path, mut g: Gaussians) {
    g.quats[4] = [0.0; 4];
    // The writer refuses NaN: write a marker and patch it into NaN, as another tool's file.
    g.means[7][0] = 12345.5;
    write_ply(ply, &g).unwrap();
    let mut bytes = std::fs::read(ply).unwrap();
    let at = bytes
        .windows(4)
        .position(|w| w == 12345.5f32.to_le_bytes())
        .unwrap();
    bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    std::fs::write(ply, bytes).unwrap();
    let (ok, stdout, stderr) = inspect(&[ply.as_os_str()]);
    assert!(!ok);
    assert!(
        stdout.contains("zero rotation quaternion (first: index 4)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("non-finite position (first: index 7)"),
        "{stdout}"
    );
    assert!(stderr.contains("2 problem(s)"), "{stderr}");
}

/// Cameras and a label folder checked against them: each summarizes alone, and together
/// the camera without a label map is a problem.
fn check_inspect_cameras_and_labels_against_them(dir: &Path) {
    let cams = vec![camera_named("a", 2, 1), camera_named("b", 2, 1)];
    let cam_path = dir.join("cams.json");
    write_semsplat_cameras(&cam_path, &cams).unwrap();
    let (ok, stdout, _) = inspect(&[cam_path.as_os_str()]);
    assert!(
        ok && stdout.contains("semsplat camera JSON") && stdout.contains("cameras: 2"),
        "{stdout}"
    );
    let labels = dir.join("labels");
    write_label_png(
        &labels.join("a.png"),
        &LabelMap::new(2, 1, vec![1, LabelMap::IGNORE]).unwrap(),
    )
    .unwrap();
    // A second class: one class and the ignore id alone is flagged as binary masks.
    write_label_png(
        &labels.join("c.png"),
        &LabelMap::new(2, 1, vec![2, LabelMap::IGNORE]).unwrap(),
    )
    .unwrap();
    let (ok, stdout, _) = inspect(&[labels.as_os_str(), "--json".as_ref()]);
    assert!(ok, "{stdout}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["ignore_share"], 0.5);
    assert_eq!(v["classes"][0]["id"], 1);
    let (ok, stdout, _) = inspect(&[
        labels.as_os_str(),
        "--cameras".as_ref(),
        cam_path.as_os_str(),
    ]);
    assert!(!ok);
    assert!(
        stdout.contains("1 of 2 cameras have no label map: b"),
        "{stdout}"
    );
    // The folder's own class table, which fuse checks the ids against, is checked too.
    write_class_table(&labels.join("classes.json"), &ClassTable::from_ids([1])).unwrap();
    let (ok, stdout, _) = inspect(&[labels.as_os_str()]);
    assert!(
        !ok && stdout.contains("label ids not in the class table: 2"),
        "{stdout}"
    );
}

/// Finite values no scene renders: every Gaussian transparent, a colour coefficient of
/// 1e30 (it passed every check, and training on it diverged at once).
fn check_inspect_flags_what_renders_nothing_or_overflows(dir: &Path) {
    let ply = dir.join("odd.ply");
    let mut g = random_gaussians(20, 1, 7);
    g.opacity_logits.fill(-1000.0);
    write_ply(&ply, &g).unwrap();
    let (ok, stdout, _) = inspect(&[ply.as_os_str()]);
    assert!(
        !ok && stdout.contains("every Gaussian is transparent"),
        "{stdout}"
    );
    g.opacity_logits[3] = 0.0;
    let stride = g.sh_coeffs() * 3;
    g.sh[5 * stride] = 1e30;
    write_ply(&ply, &g).unwrap();
    let (ok, stdout, _) = inspect(&[ply.as_os_str()]);
    assert!(!ok && !stdout.contains("transparent"), "{stdout}");
    assert!(
        stdout.contains("1 Gaussians have a colour (SH) coefficient"),
        "{stdout}"
    );
    assert!(stdout.contains("(first: index 5)"), "{stdout}");
}

#[test]
fn inspect_summarizes_files_and_fails_on_problems() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("scene.ply");
    check_inspect_flags_what_renders_nothing_or_overflows(dir.path());
    // A class list in another tool's layout is said to be neither kind inspect reads.
    let names = dir.path().join("names.json");
    std::fs::write(&names, r#"{"0": "floor", "1": "wall"}"#).unwrap();
    let (ok, _, stderr) = inspect(&[names.as_os_str()]);
    assert!(
        !ok && stderr.contains("neither cameras") && stderr.contains("nor a class table"),
        "{stderr}"
    );
    let g = check_inspect_summarizes_clean_scene(&ply);
    check_inspect_fails_on_broken_scene(&ply, g);
    check_inspect_cameras_and_labels_against_them(dir.path());
}
