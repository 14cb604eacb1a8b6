//! Numbers at the edges of float32, each checked against what float32 has room for or the
//! f64 reference: a scene far from the origin (georeferenced coordinates) against the same
//! Gaussians near it, through every command that projects centers; a needle (50 m by 1 cm)
//! against the reference's footprint; a Gaussian whose covariance float32 cannot hold,
//! culled alike by rendering, fusion and the reference; quaternions of any magnitude.

mod common;

use std::path::Path;

use common::cli::{arg_in, ok, synth_tiny};
use common::{check_validation, gpu};
use glam::DVec3;
use semsplat::fuse::{accumulate, FuseConfig, Method};
use semsplat::render::reference::{self, RenderSettings};
use semsplat::render::{GpuScene, Rasterizer, RenderOptions};
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::cameras_json::write_semsplat_cameras;
use semsplat::scene::ply::{read_ply, write_ply};
use semsplat::scene::random_scene::{random_scene, RandomSceneSpec};
use semsplat::scene::{Camera, Gaussians};

/// 2^17 m: float32 holds coordinates from there to 2^18 m in steps of 1/64 m, and a
/// camera-space point computed from them in float32 was off by millimetres (a pixel at a
/// metre's distance).
const FAR: f64 = 131_072.0;

/// The room's scene and cameras moved by `offset`, its means on the 1/64 m grid that
/// float32 holds exactly up to 2^18 m (so the far copy holds the very same Gaussians).
fn moved_room(room: &Path, into: &Path, offset: DVec3) {
    std::fs::create_dir_all(into).unwrap();
    let mut g = read_ply(&room.join("scene.ply")).unwrap();
    for m in &mut g.means {
        *m = m.map(|v| ((v as f64 * 64.0).round() / 64.0) as f32);
        let moved = DVec3::from(m.map(f64::from)) + offset;
        *m = moved.as_vec3().to_array();
    }
    write_ply(&into.join("scene.ply"), &g).unwrap();
    let cams: Vec<Camera> = load_cameras(&room.join("cameras.json"))
        .unwrap()
        .into_iter()
        .map(|c| Camera {
            translation: c.translation - c.rotation * offset,
            ..c
        })
        .collect();
    write_semsplat_cameras(&into.join("cameras.json"), &cams).unwrap();
}

#[test]
fn a_scene_far_from_the_origin_lifts_and_renders_as_it_does_near_it() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let room = d.join("room");
    synth_tiny(&room, 4, (96, 72));
    moved_room(&room, &d.join("near"), DVec3::ZERO);
    moved_room(&room, &d.join("far"), DVec3::new(FAR, FAR, FAR));
    let labels = arg_in(&room, "labels");
    let methods: [&[&str]; 4] = [
        &["--method", "vote"],
        &["--method", "vote", "--occlusion"],
        &["--method", "flashsplat"],
        &["--method", "segment-consensus"],
    ];
    for method in methods {
        let classes = |at: &str| {
            let dir = d.join(at);
            let out = arg_in(&dir, "fused.ply");
            let (scene, cameras) = (arg_in(&dir, "scene.ply"), arg_in(&dir, "cameras.json"));
            let fuse = [
                "fuse",
                "--scene",
                &scene,
                "--cameras",
                &cameras,
                "--labels",
                &labels,
            ];
            ok(&[&fuse[..], method, &["--out", &out]].concat());
            read_ply(Path::new(&out)).unwrap().class_ids.unwrap()
        };
        let (near, far) = (classes("near"), classes("far"));
        let differ = near.iter().zip(&far).filter(|(a, b)| a != b).count();
        assert_eq!(
            differ,
            0,
            "{method:?}: {differ} of {} classes differ",
            near.len()
        );
    }
    for at in ["near", "far"] {
        let dir = d.join(at);
        let (scene, cameras) = (arg_in(&dir, "scene.ply"), arg_in(&dir, "cameras.json"));
        let out = arg_in(&dir, "views");
        ok(&[
            "render",
            "--scene",
            &scene,
            "--cameras",
            &cameras,
            "--out",
            &out,
        ]);
    }
    let view = |at: &str| std::fs::read(d.join(at).join("views/train_0000.png")).unwrap();
    assert!(
        view("near") == view("far"),
        "the far scene renders otherwise"
    );
}

/// One Gaussian `scale` metres by 1 cm by 1 cm along the image's diagonal, 2 m in front of
/// a camera at the origin.
fn needle(length: f64) -> (Gaussians, Camera) {
    let half = std::f64::consts::FRAC_PI_8; // 45 degrees about the view axis
    let g = common::spec_scene::scene(&[common::spec_scene::Spec {
        mean: [0.0, 0.0, 2.0],
        log_scale: [length.ln() as f32, 0.01f32.ln(), 0.01f32.ln()],
        quat: [half.cos() as f32, 0.0, 0.0, half.sin() as f32],
        logit: 3.0,
        sh: vec![[1.0, 1.0, 1.0]],
        logits: vec![],
    }]);
    let cam = Camera::look_at("v", DVec3::ZERO, DVec3::Z, -DVec3::Y, 96, 96, 40.0);
    (g, cam)
}

/// Alpha of `g` from `cam` on the GPU and by the f64 reference.
fn alphas(g: &Gaussians, cam: &Camera) -> (Vec<f32>, Vec<f64>) {
    let scene = GpuScene::upload(gpu(), g).unwrap();
    let opts = RenderOptions {
        semantics: None,
        ..Default::default()
    };
    let frame = Rasterizer::new(gpu()).render(&scene, cam, &opts).unwrap();
    let settings = RenderSettings::default();
    (frame.alpha, reference::render(g, cam, &settings).alpha)
}

#[test]
fn a_needle_covers_the_pixels_the_reference_gives_it() {
    // 50 m by 1 cm: its 2D covariance's determinant is about 2 ulp of xx * yy in float32.
    let (g, cam) = needle(50.0);
    let (gpu_alpha, want) = alphas(&g, &cam);
    let covered = want.iter().filter(|&&a| a > 1.0 / 255.0).count();
    assert!(covered > 500, "the reference covers {covered} pixels");
    let worst = (gpu_alpha.iter().zip(&want))
        .map(|(&a, &b)| (a as f64 - b).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 2e-3,
        "alpha differs by {worst} from the reference's"
    );
    check_validation(gpu());
}

#[test]
fn a_covariance_past_float32_is_culled_by_rendering_fusion_and_the_reference() {
    let g = random_scene(&RandomSceneSpec {
        n: 400,
        seed: 5,
        scale: (0.02, 0.1),
        ..Default::default()
    });
    let cam = Camera::look_at("v", DVec3::ZERO, DVec3::Z, -DVec3::Y, 64, 48, 70.0);
    let mut huge = g.clone();
    huge.means.push([0.0, 0.0, 3.0]);
    huge.log_scales.push([60.0; 3]); // e^60 m: its covariance passes float32's range
    huge.quats.push([1.0, 0.0, 0.0, 0.0]);
    huge.opacity_logits.push(2.0);
    huge.sh.extend_from_slice(&[0.5; 3]);
    let (with, without) = (alphas(&huge, &cam), alphas(&g, &cam));
    assert_eq!(with.0, without.0, "rendering drew the overflowing Gaussian");
    assert_eq!(
        with.1, without.1,
        "the reference drew the overflowing Gaussian"
    );

    // FlashSplat's evidence: the others' unchanged, none for it.
    let labels = vec![Some(vec![0u32; 64 * 48])];
    let cfg = FuseConfig {
        method: Method::FlashSplat,
        ..Default::default()
    };
    let evidence = |g: &Gaussians| {
        let scene = GpuScene::upload(gpu(), g).unwrap();
        let cams = std::slice::from_ref(&cam);
        accumulate(gpu(), &scene, cams, &labels, 1, &cfg, |_, _| {})
            .unwrap()
            .0
    };
    let (a, b) = (evidence(&huge), evidence(&g));
    assert_eq!(a.data[..g.len()], b.data[..]);
    assert_eq!(a.get(0, g.len()), 0.0);
    check_validation(gpu());

    // `inspect` names it as a problem.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("huge.ply");
    write_ply(&path, &huge).unwrap();
    let out = common::cli::semsplat(&["inspect", path.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!out.status.success(), "{text}");
    assert!(text.contains("1 Gaussian(s) larger than 1e6 m"), "{text}");
}

#[test]
fn quaternions_of_any_magnitude_rotate_alike() {
    let g = random_scene(&RandomSceneSpec {
        n: 300,
        seed: 9,
        scale: (0.02, 0.2),
        ..Default::default()
    });
    let cam = Camera::look_at("v", DVec3::ZERO, DVec3::Z, -DVec3::Y, 64, 48, 70.0);
    let unit = alphas(&g, &cam).0;
    for factor in [1e20f32, 1e-30] {
        let mut scaled = g.clone();
        for q in &mut scaled.quats {
            *q = q.map(|v| v * factor);
        }
        let got = alphas(&scaled, &cam).0;
        let worst = (got.iter().zip(&unit))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst < 1e-5,
            "quaternions times {factor}: alpha differs by {worst}"
        );
    }
    check_validation(gpu());
}
