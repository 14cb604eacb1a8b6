//! Reproducible training (lavapipe): `train --deterministic` run twice with the same inputs
//! and seed writes byte-identical PLYs, with and without densification, joint and
//! `--semantics-only`; and one backward run twice gives bit-identical gradients. The
//! gradients' accuracy against the f64 reference is in tests/render_backward.rs.

mod common;

use common::cli::{semsplat_with_env, synth_tiny, train_args};

use std::path::Path;

use semsplat::render::backward::{BackwardVariant, HostPixelGrads};
use semsplat::render::{GpuScene, Rasterizer, RenderOptions, SemanticMode};
use semsplat::scene::ply::{read_ply, write_ply};
use semsplat::scene::random_scene::{random_scene, RandomSceneSpec};
use semsplat::scene::{Camera, Gaussians};

/// Trains the room in `d` into `out` with `extra` options; returns the PLY's bytes.
fn train(d: &str, out: &Path, extra: &[&str]) -> Vec<u8> {
    train_from(d, &format!("{d}/init.ply"), out, extra, None)
}

/// [`train`] from the scene `init`, with `SEMSPLAT_MAX_BINDING` set to `max_binding`.
fn train_from(
    d: &str,
    init: &str,
    out: &Path,
    extra: &[&str],
    max_binding: Option<u64>,
) -> Vec<u8> {
    let mut args = train_args(d, init, out.to_str().unwrap());
    args.extend(["--seed", "7", "--deterministic"].map(String::from));
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let env: Vec<(&str, String)> = max_binding
        .map(|bytes| ("SEMSPLAT_MAX_BINDING", bytes.to_string()))
        .into_iter()
        .collect();
    let r = semsplat_with_env(&args, &env);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    std::fs::read(out).unwrap()
}

fn vertex_count(ply: &[u8]) -> usize {
    let header = String::from_utf8_lossy(&ply[..ply.len().min(2000)]).into_owned();
    let line = header
        .lines()
        .find(|l| l.starts_with("element vertex"))
        .unwrap();
    line.rsplit(' ').next().unwrap().parse().unwrap()
}

#[test]
fn train_twice_with_the_same_seed_writes_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth_tiny(&room, 4, (48, 36));
    let d = room.to_str().unwrap();
    let init = std::fs::read(room.join("init.ply")).unwrap();
    // 30 iterations: the scaled 3DGS schedule densifies at iteration 10.
    let configs: [(&str, &[&str]); 3] = [
        ("densify", &["--iters", "30"]),
        ("no densify", &["--iters", "12", "--no-densify"]),
        ("semantics only", &["--iters", "12", "--semantics-only"]),
    ];
    for (name, extra) in configs {
        let a = train(d, &tmp.path().join("a.ply"), extra);
        let b = train(d, &tmp.path().join("b.ply"), extra);
        assert!(a == b, "{name}: two runs with the same seed differ");
        if name == "densify" {
            assert_ne!(
                vertex_count(&a),
                vertex_count(&init),
                "densification did not run: the test would not cover it"
            );
        }
        if name == "semantics only" {
            // Geometry frozen, logits trained: the output is not the input.
            assert_eq!(vertex_count(&a), vertex_count(&init));
        }
    }
}

/// A scene whose per-Gaussian buffers pass one binding trains as one that fits, here forced
/// by a lower binding limit (as a 1M-Gaussian SH-3 scene passes lavapipe's 128 MiB): the
/// projection, its backward, Adam and the densification's gather split the work into
/// parts of Gaussians, the other kernels (blending, its backward, binning, sort, scan,
/// densification's plan) reach per-Gaussian arrays by address, and the trained PLY is byte
/// for byte the one trained without a limit. No per-Gaussian array must fit one binding.
#[test]
fn training_past_one_binding_writes_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth_tiny(&room, 4, (48, 36));
    let d = room.to_str().unwrap();
    // The room's init ten times over (each copy shifted by a millimetre), with SH degree
    // 3 (zero higher coefficients): 192 bytes per Gaussian.
    let mut g = replicated(&read_ply(&room.join("init.ply")).unwrap(), 10);
    let dc = g.sh.clone();
    g.sh_degree = 3;
    g.sh = dc
        .chunks(3)
        .flat_map(|c| c.iter().copied().chain([0.0; 45]))
        .collect();
    let init = room.join("init_sh3.ply");
    write_ply(&init, &g).unwrap();
    let init = init.to_str().unwrap();
    // Below every per-Gaussian buffer (4 bytes per Gaussian of flags, sort keys and scans,
    // 16 of the projected attributes, 48 of the room's 12 logits, 80 of the fixed-point
    // screen-space gradient), above the loss partial sums (64 KiB).
    let limit = 128 * 1024;
    assert!(
        g.len() as u64 * 4 > limit,
        "the 4-byte per-Gaussian arrays must pass the limit"
    );
    let extra = ["--iters", "30"];
    let whole = train_from(d, init, &tmp.path().join("a.ply"), &extra, None);
    let split = train_from(d, init, &tmp.path().join("b.ply"), &extra, Some(limit));
    assert_ne!(vertex_count(&split), g.len(), "densification did not run");
    assert!(
        whole == split,
        "splitting across bindings changed the result"
    );
}

/// `g` repeated `copies` times, copy k shifted by k millimetres along x.
fn replicated(g: &Gaussians, copies: usize) -> Gaussians {
    let repeat = |v: &[f32]| v.repeat(copies);
    Gaussians {
        means: (0..copies)
            .flat_map(|k| {
                g.means
                    .iter()
                    .map(move |m| [m[0] + 1e-3 * k as f32, m[1], m[2]])
            })
            .collect(),
        log_scales: g.log_scales.repeat(copies),
        quats: g.quats.repeat(copies),
        opacity_logits: repeat(&g.opacity_logits),
        sh: repeat(&g.sh),
        ..g.clone()
    }
}

/// The same backward twice: every gradient bit-identical (the float-atomic path
/// differs run to run on lavapipe's threads; this one may not).
#[test]
fn the_fixed_point_backward_is_bit_identical_run_to_run() {
    let gpu = common::gpu();
    let cam = Camera::look_at(
        "v",
        glam::DVec3::new(0.2, -0.1, -0.5),
        glam::DVec3::new(0.0, 0.0, 4.0),
        -glam::DVec3::Y,
        64,
        48,
        70.0,
    );
    let g = random_scene(&RandomSceneSpec {
        n: 400,
        sh_degree: 1,
        channels: 20,
        depth: (2.0, 7.0),
        spread: 0.6,
        scale: (0.05, 0.4),
        opacity_logit: (-1.0, 3.0),
        seed: 5,
    });
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let pixels = 64 * 48;
    let rgb: Vec<f32> = (0..pixels * 3)
        .map(|i| ((i % 7) as f32 - 3.0) * 1e-3)
        .collect();
    let alpha = vec![1e-4f32; pixels];
    let sem: Vec<f32> = (0..pixels * 20)
        .map(|i| ((i % 5) as f32 - 2.0) * 1e-3)
        .collect();
    let opts = RenderOptions {
        semantics: Some(SemanticMode::RawLogits),
        ..Default::default()
    };
    let upstream = HostPixelGrads {
        rgb: &rgb,
        alpha: &alpha,
        sem_norm: &sem,
    };
    let run = || {
        let mut r = Rasterizer::new(gpu);
        r.set_window_len(16);
        let (_, grads) = r
            .render_backward(&scene, &cam, &opts, &upstream, BackwardVariant::default())
            .unwrap();
        grads
    };
    let (a, b) = (run(), run());
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert!(a.screen.iter().any(|&x| x != 0.0), "no gradient at all");
    assert_eq!(bits(&a.screen), bits(&b.screen));
    assert_eq!(bits(&a.logits), bits(&b.logits));
    assert_eq!(bits(&a.params.means), bits(&b.params.means));
    assert_eq!(bits(&a.params.sh), bits(&b.params.sh));
    common::check_validation(gpu);
}
