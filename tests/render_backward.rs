//! The GPU backward pass (blend and projection backward) against the independent f64
//! analytic backward of the CPU reference (src/render/reference/backward*.rs, itself
//! checked by finite differences in tests/reference_backward.rs), and directly against
//! finite differences of the f64 reference forward.

mod common;

use glam::DVec3;
use semsplat::gpu::Gpu;
use semsplat::render::backward::{BackwardVariant, HostGrads, HostPixelGrads};
use semsplat::render::reference::backward::{
    backward, objective, GaussianParams, ParamGrads, PixelGrads,
};
use semsplat::render::reference::{self, RenderSettings};
use semsplat::render::{GpuScene, Rasterizer, RenderOptions, SemanticMode};
use semsplat::scene::random_scene::{random_scene, RandomSceneSpec};
use semsplat::scene::{Camera, Gaussians};
use semsplat::util::Rng;

fn camera(w: u32, h: u32) -> Camera {
    Camera::look_at(
        "bwd",
        DVec3::new(0.2, -0.1, -0.5),
        DVec3::new(0.0, 0.0, 4.0),
        -DVec3::Y,
        w,
        h,
        70.0,
    )
}

/// Random upstream gradients for a view, as f32 (GPU) and the same values as f64.
fn upstream(
    pixels: usize,
    channels: usize,
    seed: u64,
) -> (Vec<f32>, Vec<f32>, Vec<f32>, PixelGrads) {
    let mut rng = Rng::new(seed);
    let mut v =
        |n: usize| -> Vec<f32> { (0..n).map(|_| rng.range_f64(-1.0, 1.0) as f32).collect() };
    let (rgb, alpha, sem) = (v(pixels * 3), v(pixels), v(pixels * channels));
    let host = PixelGrads {
        rgb: rgb
            .chunks_exact(3)
            .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64])
            .collect(),
        alpha: alpha.iter().map(|&a| a as f64).collect(),
        sem_norm: sem.iter().map(|&s| s as f64).collect(),
    };
    (rgb, alpha, sem, host)
}

/// Per tensor: ||gpu - cpu|| / ||cpu|| (relative L2 error).
fn rel_l2(gpu: &[f32], cpu: impl Iterator<Item = f64>) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    let mut n = 0;
    for (g, c) in gpu.iter().zip(cpu) {
        assert!(g.is_finite(), "non-finite GPU gradient");
        num += (*g as f64 - c).powi(2);
        den += c * c;
        n += 1;
    }
    assert_eq!(n, gpu.len(), "gradient lengths differ");
    if den == 0.0 {
        assert!(
            num == 0.0,
            "the reference gradient is zero, the GPU's is not"
        );
        return 0.0;
    }
    (num / den).sqrt()
}

fn errors(gpu: &HostGrads, cpu: &ParamGrads) -> Vec<(&'static str, f64)> {
    let flat3 = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let screen = |k: usize| {
        gpu.screen
            .chunks_exact(10)
            .map(move |c| c[k])
            .collect::<Vec<f32>>()
    };
    let mut out = vec![
        (
            "means",
            rel_l2(&gpu.params.means, flat3(&cpu.means).into_iter()),
        ),
        (
            "log_scales",
            rel_l2(&gpu.params.log_scales, flat3(&cpu.log_scales).into_iter()),
        ),
        (
            "quats",
            rel_l2(&gpu.params.quats, cpu.quats.iter().flatten().copied()),
        ),
        (
            "opacity_logits",
            rel_l2(
                &gpu.params.opacity_logits,
                cpu.opacity_logits.iter().copied(),
            ),
        ),
        ("sh", rel_l2(&gpu.params.sh, cpu.sh.iter().copied())),
        (
            "mean2d.x",
            rel_l2(&screen(0), cpu.mean2d.iter().map(|m| m[0])),
        ),
        (
            "conic.A",
            rel_l2(&screen(2), cpu.conic.iter().map(|m| m[0])),
        ),
        ("opacity", rel_l2(&screen(5), cpu.opacity.iter().copied())),
        (
            "color.r",
            rel_l2(&screen(6), cpu.color.iter().map(|m| m[0])),
        ),
    ];
    if !cpu.logits.is_empty() {
        out.push(("logits", rel_l2(&gpu.logits, cpu.logits.iter().copied())));
    }
    out
}

struct Case {
    name: &'static str,
    scene: Gaussians,
    cam: Camera,
    mode: SemanticMode,
    background: [f32; 3],
    window: Option<u32>,
    /// The fixed-point accumulation (float_atomics is then ignored).
    deterministic: bool,
    float_atomics: bool,
    semantics_only: bool,
}

/// Runs the GPU backward on `gpu` and the reference backward on one case; returns the
/// worst relative error over the tensors.
fn compare(gpu: &Gpu, case: &Case) -> f64 {
    let g = common::separate_depth_ties(&case.scene, &case.cam);
    let channels = g.semantics.as_ref().map_or(0, |s| s.channels);
    let pixels = (case.cam.width * case.cam.height) as usize;
    let (rgb, alpha, sem, host) = upstream(pixels, channels, 11);
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let mut r = Rasterizer::new(gpu);
    if let Some(w) = case.window {
        r.set_window_len(w);
    }
    let opts = RenderOptions {
        background: case.background,
        semantics: Some(case.mode),
        ..Default::default()
    };
    let (_, grads) = r
        .render_backward(
            &scene,
            &case.cam,
            &opts,
            &HostPixelGrads {
                rgb: &rgb,
                alpha: &alpha,
                sem_norm: &sem,
            },
            BackwardVariant {
                deterministic: case.deterministic,
                float_atomics: case.float_atomics,
                semantics_only: case.semantics_only,
            },
        )
        .unwrap();
    let settings = RenderSettings {
        background: case.background.map(|v| v as f64),
        semantic_mode: match case.mode {
            SemanticMode::RawLogits => reference::SemanticMode::RawLogits,
            SemanticMode::Softmax => reference::SemanticMode::Softmax,
        },
        ..Default::default()
    };
    let cpu = backward(&g, &case.cam, &settings, &host);
    let errs = if case.semantics_only {
        for (name, v) in [
            ("means", &grads.params.means),
            ("sh", &grads.params.sh),
            ("screen", &grads.screen),
        ] {
            assert!(
                v.iter().all(|&x| x == 0.0),
                "semantics-only wrote {name} gradients"
            );
        }
        vec![("logits", rel_l2(&grads.logits, cpu.logits.iter().copied()))]
    } else {
        errors(&grads, &cpu)
    };
    let worst = errs.iter().map(|e| e.1).fold(0.0, f64::max);
    println!(
        "{}: worst {worst:.2e} {:?}",
        case.name,
        errs.iter()
            .map(|(n, e)| format!("{n} {e:.1e}"))
            .collect::<Vec<_>>()
    );
    worst
}

fn spec(n: usize, sh_degree: u32, channels: usize, seed: u64) -> RandomSceneSpec {
    RandomSceneSpec {
        n,
        sh_degree,
        channels,
        depth: (2.0, 7.0),
        spread: 0.6,
        scale: (0.02, 0.3),
        opacity_logit: (-2.0, 3.0),
        seed,
    }
}

/// Float32 on the GPU against float64: the GPU recovers T_i = T_{i+1} / (1 - alpha_i)
/// back to front and sums with atomics in arbitrary order, which costs a few 1e-5 of
/// relative accuracy per tensor (measured: 1e-6..1e-5, 1.1e-4 for the quaternions of the
/// edge-case scene); a flipped skip decision (alpha within an
/// ulp of 1/255, or T within an ulp of the stop) moves one pixel's share. 1e-3 is ~10x the
/// worst case measured; a wrong term (a dropped Gaussian Semantics Eq. 2 term, a sign, a
/// missing window) gives errors of 1e-1 and more.
const TOLERANCE: f64 = 1e-3;

/// Every SH degree with 0 to 17 channels, raw logits and softmax, on the default
/// accumulation (float atomics, whole lists).
fn channel_and_mode_cases(cam: &Camera) -> Vec<Case> {
    let mut cases = Vec::new();
    for (i, (sh, c, mode)) in [
        (0, 0, SemanticMode::RawLogits),
        (1, 3, SemanticMode::RawLogits),
        (2, 5, SemanticMode::Softmax),
        (3, 17, SemanticMode::RawLogits),
        (3, 17, SemanticMode::Softmax),
    ]
    .into_iter()
    .enumerate()
    {
        cases.push(Case {
            name: [
                "C0 sh0",
                "C3 sh1",
                "C5 sh2 softmax",
                "C17 sh3",
                "C17 sh3 softmax",
            ][i],
            scene: random_scene(&spec(300, sh, c, 20 + i as u64)),
            cam: cam.clone(),
            mode,
            background: [0.2, 0.5, 0.1],
            window: None,
            deterministic: false,
            float_atomics: true,
            semantics_only: false,
        });
    }
    cases
}

/// Windows carried between dispatches and the compare-and-swap atomics.
fn window_and_atomics_cases(cam: &Camera) -> Vec<Case> {
    vec![
        // Windows of 7 list entries: the per-pixel state is carried between backward
        // dispatches.
        Case {
            name: "windows of 7",
            scene: random_scene(&spec(300, 1, 4, 40)),
            cam: cam.clone(),
            mode: SemanticMode::RawLogits,
            background: [0.0; 3],
            window: Some(7),
            deterministic: false,
            float_atomics: true,
            semantics_only: false,
        },
        // The compare-and-swap path for devices without float atomics.
        Case {
            name: "cas atomics",
            scene: random_scene(&spec(300, 1, 4, 41)),
            cam: cam.clone(),
            mode: SemanticMode::RawLogits,
            background: [0.0; 3],
            window: None,
            deterministic: false,
            float_atomics: false,
            semantics_only: false,
        },
    ]
}

/// The semantic-only kernels and the deterministic fixed-point sums.
fn semantics_only_and_fixed_point_cases(cam: &Camera) -> Vec<Case> {
    let mut cases = Vec::new();
    // Logits only (geometry frozen): the semantic-only kernels, both accumulations.
    for float_atomics in [true, false] {
        cases.push(Case {
            name: "semantics only",
            scene: random_scene(&spec(300, 1, 6, 42)),
            cam: cam.clone(),
            mode: SemanticMode::RawLogits,
            background: [0.0; 3],
            window: Some(11),
            deterministic: false,
            float_atomics,
            semantics_only: true,
        });
    }
    // The deterministic 64-bit fixed-point sums, full (windows, several semantic chunks)
    // and semantic-only.
    for (name, semantics_only, channels) in [
        ("fixed point", false, 20),
        ("fixed point sem only", true, 6),
    ] {
        cases.push(Case {
            name,
            scene: random_scene(&spec(300, 2, channels, 43)),
            cam: cam.clone(),
            mode: SemanticMode::RawLogits,
            background: [0.2, 0.5, 0.1],
            window: Some(9),
            deterministic: true,
            float_atomics: false,
            semantics_only,
        });
    }
    cases
}

/// Both forms of the per-tile kernels (one pixel an invocation, and several: the default
/// on CPU devices), each against the reference: the wide form sums a step's values over
/// an invocation's pixels before the subgroup.
#[test]
fn gpu_backward_matches_the_reference_backward() {
    let cam = camera(80, 56);
    let mut cases = channel_and_mode_cases(&cam);
    cases.extend(window_and_atomics_cases(&cam));
    cases.extend(semantics_only_and_fixed_point_cases(&cam));
    for wide in [false, true] {
        assert_cases_match(common::gpu_with_cpu_forms(wide), &cases);
    }
}

/// Every case on `gpu` within the tolerance of the reference, and the validation silent.
fn assert_cases_match(gpu: &Gpu, cases: &[Case]) {
    let caps = gpu.caps();
    for case in cases {
        let worst = compare(gpu, case);
        assert!(
            worst < TOLERANCE,
            "{} (wide tiles: {}, int64 atomics: {}): relative error {worst:.2e}",
            case.name,
            caps.cpu_forms,
            caps.int64_atomics
        );
    }
    common::check_validation(gpu);
}

/// The deterministic sums on a device without 64-bit integer atomics: the `fixed32x2`
/// variants (two 32-bit halves), full and semantic-only, in both forms against the
/// reference. The device is opened without the feature, so a kernel that used 64-bit
/// atomics there would also fail the validation check.
#[test]
fn fixed_point_without_int64_atomics_matches_the_reference() {
    let cam = camera(80, 56);
    let cases: Vec<Case> = semantics_only_and_fixed_point_cases(&cam)
        .into_iter()
        .filter(|case| case.deterministic)
        .collect();
    assert_eq!(
        cases.len(),
        2,
        "the full and semantic-only fixed-point cases"
    );
    for wide in [false, true] {
        let gpu = common::gpu_without_int64_atomics(wide);
        assert!(!gpu.caps().int64_atomics);
        assert_cases_match(gpu, &cases);
    }
}

#[test]
fn gpu_backward_handles_the_forward_edge_cases() {
    let cam = camera(64, 48);
    // Opaque, deep stacks (alpha clamp at 0.999, pixels stopping at T = 1e-4), Gaussians
    // beyond the frustum edge (the clamped Jacobian), a needle-thin one, near-plane ones.
    let mut g = random_scene(&RandomSceneSpec {
        opacity_logit: (4.0, 9.0),
        ..spec(200, 1, 3, 50)
    });
    let mut wide = random_scene(&RandomSceneSpec {
        spread: 1.6,
        scale: (0.1, 0.6),
        ..spec(60, 1, 3, 51)
    });
    g.means.append(&mut wide.means);
    g.log_scales.append(&mut wide.log_scales);
    g.quats.append(&mut wide.quats);
    g.opacity_logits.append(&mut wide.opacity_logits);
    g.sh.append(&mut wide.sh);
    g.semantics
        .as_mut()
        .unwrap()
        .logits
        .append(&mut wide.semantics.unwrap().logits);
    g.log_scales[0] = [-6.0, 0.5, -6.0];
    g.means[1] = [0.01, 0.02, 0.05];
    // Both forms of the per-tile kernels: pixels of one invocation stop at different steps.
    for wide in [false, true] {
        let gpu = common::gpu_with_cpu_forms(wide);
        for deterministic in [false, true] {
            let worst = compare(
                gpu,
                &Case {
                    name: "edge cases",
                    scene: g.clone(),
                    cam: cam.clone(),
                    mode: SemanticMode::RawLogits,
                    background: [1.0, 1.0, 1.0],
                    window: None,
                    deterministic,
                    float_atomics: true,
                    semantics_only: false,
                },
            );
            assert!(
                worst < TOLERANCE,
                "edge cases (fixed point: {deterministic}, wide tiles: {wide}): relative error {worst:.2e}"
            );
        }
        common::check_validation(gpu);
    }
}

/// The GPU's gradients (default variant) of the objective the f32 upstream gradients
/// `rgb`, `alpha` and `sem` define on `g` seen by `cam`, over a grey background.
fn gpu_gradients(
    g: &Gaussians,
    cam: &Camera,
    rgb: &[f32],
    alpha: &[f32],
    sem: &[f32],
) -> HostGrads {
    let gpu = common::gpu();
    let scene = GpuScene::upload(gpu, g).unwrap();
    let mut r = Rasterizer::new(gpu);
    let opts = RenderOptions {
        background: [0.3, 0.3, 0.3],
        semantics: Some(SemanticMode::RawLogits),
        ..Default::default()
    };
    let (_, grads) = r
        .render_backward(
            &scene,
            cam,
            &opts,
            &HostPixelGrads {
                rgb,
                alpha,
                sem_norm: sem,
            },
            BackwardVariant::default(),
        )
        .unwrap();
    grads
}

/// Compares every stored parameter's GPU gradient with central differences of the f64
/// reference forward's objective (`host`, same grey background), where differences at h and
/// h/2 agree; returns how many were checked, how many skipped at a kink, and the worst
/// error relative to max(|FD|, 1).
fn compare_with_finite_differences(
    g: &Gaussians,
    cam: &Camera,
    host: &PixelGrads,
    grads: &HostGrads,
) -> (usize, usize, f64) {
    let settings = RenderSettings {
        background: [0.3; 3],
        ..Default::default()
    };
    let base = GaussianParams::from_gaussians(g);
    let fd = |get: &dyn Fn(&mut GaussianParams) -> &mut f64, h: f64| {
        let mut a = base.clone();
        *get(&mut a) += h;
        let mut b = base.clone();
        *get(&mut b) -= h;
        (objective(&a, cam, &settings, host) - objective(&b, cam, &settings, host)) / (2.0 * h)
    };
    let (mut checked, mut skipped, mut worst) = (0, 0, 0.0f64);
    let mut check = |get: &dyn Fn(&mut GaussianParams) -> &mut f64, gpu_value: f32| {
        let (d1, d2) = (fd(get, 1e-5), fd(get, 5e-6));
        if (d1 - d2).abs() > 1e-4 * d1.abs().max(1.0) {
            skipped += 1;
            return;
        }
        checked += 1;
        let err = (gpu_value as f64 - d2).abs() / d2.abs().max(1.0);
        worst = worst.max(err);
    };
    for i in 0..g.len() {
        for k in 0..3 {
            check(&|p| &mut p.means[i][k], grads.params.means[3 * i + k]);
            check(
                &|p| &mut p.log_scales[i][k],
                grads.params.log_scales[3 * i + k],
            );
        }
        for k in 0..4 {
            check(&|p| &mut p.quats[i][k], grads.params.quats[4 * i + k]);
        }
        check(
            &|p| &mut p.opacity_logits[i],
            grads.params.opacity_logits[i],
        );
        for k in 0..12 {
            check(&|p| &mut p.sh[12 * i + k], grads.params.sh[12 * i + k]);
        }
        for k in 0..3 {
            check(&|p| &mut p.logits[3 * i + k], grads.logits[3 * i + k]);
        }
    }
    (checked, skipped, worst)
}

/// An end-to-end check that does not go through the reference backward at all: central
/// differences of the f64 reference forward, at the parameters where the objective is
/// smooth at this step (the forward is piecewise: a pixel crossing alpha = 1/255 makes its
/// normalized semantics (Gaussian Semantics Eq. 2) jump, so differences at h and h/2 must
/// agree first).
#[test]
fn gpu_backward_matches_finite_differences() {
    let gpu = common::gpu();
    let cam = camera(48, 40);
    let g = common::separate_depth_ties(&random_scene(&spec(25, 1, 3, 60)), &cam);
    let (rgb, alpha, sem, host) = upstream(48 * 40, 3, 5);
    let grads = gpu_gradients(&g, &cam, &rgb, &alpha, &sem);
    let (checked, skipped, worst) = compare_with_finite_differences(&g, &cam, &host, &grads);
    println!("finite differences: {checked} checked, {skipped} at a kink, worst error {worst:.2e}");
    assert!(
        checked >= 9 * (checked + skipped) / 10,
        "too many kinks: {skipped} of {}",
        checked + skipped
    );
    assert!(
        worst < 2e-3,
        "worst error against finite differences {worst:.2e}"
    );
    common::check_validation(gpu);
}

#[test]
fn a_view_whose_lists_grow_counts_its_densification_statistics_once() {
    // Large Gaussians: far more (tile, Gaussian) pairs than the first guess at the lists (4
    // per Gaussian, at least 65,536), so the first attempt overflows and the view is
    // recorded again with larger lists. The overflowed attempt's backward must add nothing
    // to the densification statistics, which are not cleared between attempts (nor between
    // iterations): each visible Gaussian counts this view once.
    let gpu = common::gpu();
    let n = 2_000;
    let g = random_scene(&RandomSceneSpec {
        scale: (0.5, 1.0),
        ..spec(n, 1, 0, 61)
    });
    let cam = camera(512, 384);
    let pixels = (cam.width * cam.height) as usize;
    let (rgb, alpha, sem, _) = upstream(pixels, 0, 62);
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let opts = RenderOptions {
        semantics: None,
        ..Default::default()
    };
    let upstream = HostPixelGrads {
        rgb: &rgb,
        alpha: &alpha,
        sem_norm: &sem,
    };
    let variant = BackwardVariant {
        deterministic: false,
        float_atomics: true,
        semantics_only: false,
    };
    let (frame, grads) = Rasterizer::new(gpu)
        .render_backward(&scene, &cam, &opts, &upstream, variant)
        .unwrap();
    let first_guess = (4 * n).max(1 << 16);
    assert!(
        frame.intersections as usize > first_guess,
        "{} intersections: the lists would not have grown",
        frame.intersections
    );
    let most = grads.densify_count.iter().fold(0.0f32, |a, &c| a.max(c));
    assert_eq!(most, 1.0, "a Gaussian's view count");
    let counted = grads.densify_count.iter().filter(|&&c| c == 1.0).count();
    assert_eq!(counted, frame.visible as usize);
    common::check_validation(gpu);
}
