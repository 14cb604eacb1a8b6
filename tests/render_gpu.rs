//! The GPU rasterizer against the independent CPU reference (f64): images within 1e-4 and
//! the same (tile, Gaussian) intersection lists, on random scenes and edge cases.

mod common;

use common::{check_validation, gpu, separate_depth_ties};
use glam::DVec3;
use semsplat::contract::{MEDIAN_T, OPAQUE_T};
use semsplat::render::reference::{self, ProjectedGaussian, RenderSettings};
use semsplat::render::{
    BandWork, GpuScene, Rasterizer, RenderOptions, RenderedFrame, SemanticMode,
};
use semsplat::scene::random_scene::{random_scene, RandomSceneSpec};
use semsplat::scene::{Camera, Gaussians};
use std::collections::BTreeSet;

const TOL: f64 = 1e-4;

fn ref_mode(m: SemanticMode) -> reference::SemanticMode {
    match m {
        SemanticMode::RawLogits => reference::SemanticMode::RawLogits,
        SemanticMode::Softmax => reference::SemanticMode::Softmax,
    }
}

fn camera(name: &str, eye: DVec3, target: DVec3, w: u32, h: u32) -> Camera {
    Camera::look_at(name, eye, target, -DVec3::Y, w, h, 70.0)
}

/// A few poses around the random scenes (which fill a cone along +z from the origin).
fn poses(w: u32, h: u32) -> Vec<Camera> {
    vec![
        camera("front", DVec3::ZERO, DVec3::new(0.0, 0.0, 5.0), w, h),
        camera(
            "side",
            DVec3::new(-3.0, -1.0, 1.0),
            DVec3::new(0.5, 0.0, 5.0),
            w,
            h,
        ),
        camera(
            "far",
            DVec3::new(1.0, 2.0, -6.0),
            DVec3::new(0.0, 0.0, 4.0),
            w,
            h,
        ),
    ]
}

/// The largest difference of `gpu` and `cpu` and its index, over the pixels (of
/// `per_pixel` values each) not in `skipped`.
fn max_diff_outside(
    gpu: &[f32],
    cpu: impl Iterator<Item = f64>,
    per_pixel: usize,
    skipped: &BTreeSet<usize>,
) -> (f64, usize) {
    let mut worst = (0.0, 0);
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        let d = (*g as f64 - c).abs();
        if (d.is_nan() || d > worst.0) && !skipped.contains(&(i / per_pixel.max(1))) {
            worst = (d, i);
        }
    }
    worst
}

/// The pixels where some Gaussian's alpha at the pixel center lies within float32 rounding
/// (1e-5 relative) of the 1/255 cutoff: float32 and the f64 reference may keep or skip it
/// there, a step of up to 1/255 in the pixel's sums and one in its contributor count.
fn alpha_cutoff_pixels(projected: &[ProjectedGaussian], cam: &Camera) -> BTreeSet<usize> {
    let mut pixels = BTreeSet::new();
    for p in projected {
        for py in 0..cam.height {
            for px in 0..cam.width {
                let dx = p.mean2d.x - (px as f64 + 0.5);
                let dy = p.mean2d.y - (py as f64 + 0.5);
                let [a, b, c] = p.conic;
                let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
                let alpha = p.opacity * (-sigma).exp();
                if (alpha / reference::ALPHA_THRESHOLD - 1.0).abs() < 1e-5 {
                    pixels.insert((py * cam.width + px) as usize);
                }
            }
        }
    }
    pixels
}

/// `g` rendered by `raster` and by the f64 reference with the same background and
/// semantics, and the reference's settings.
fn render_both(
    raster: &mut Rasterizer,
    g: &Gaussians,
    cam: &Camera,
    mode: Option<SemanticMode>,
) -> (RenderedFrame, reference::ReferenceImage, RenderSettings) {
    let scene = GpuScene::upload(gpu(), g).unwrap();
    let opts = RenderOptions {
        background: [0.2, 0.4, 0.6],
        semantics: mode,
        ..Default::default()
    };
    let frame = raster.render(&scene, cam, &opts).unwrap();
    let settings = RenderSettings {
        background: [0.2, 0.4, 0.6],
        semantics: mode.is_some(),
        semantic_mode: ref_mode(mode.unwrap_or_default()),
        ..Default::default()
    };
    let r = reference::render(g, cam, &settings);
    (frame, r, settings)
}

/// Renders on both sides and checks every output and the intersection list.
fn compare(
    raster: &mut Rasterizer,
    g: &Gaussians,
    cam: &Camera,
    mode: Option<SemanticMode>,
    what: &str,
) -> RenderedFrame {
    compare_within(raster, g, cam, mode, what, TOL, true)
}

fn compare_within(
    raster: &mut Rasterizer,
    g: &Gaussians,
    cam: &Camera,
    mode: Option<SemanticMode>,
    what: &str,
    tol: f64,
    exact_lists: bool,
) -> RenderedFrame {
    let g = &separate_depth_ties(g, cam);
    let (frame, r, settings) = render_both(raster, g, cam, mode);
    assert_eq!(frame.channels as usize, r.channels, "{what}: channels");
    let projected = reference::project(g, cam, &settings);
    let cutoff = alpha_cutoff_pixels(&projected, cam);
    let pixels = (cam.width * cam.height) as usize;
    let checks: [(&str, &[f32], Vec<f64>); 5] = [
        ("rgb", &frame.rgb, r.rgb.iter().flatten().copied().collect()),
        ("alpha", &frame.alpha, r.alpha.clone()),
        ("final_t", &frame.final_t, r.final_t.clone()),
        ("sem", &frame.sem, r.sem.clone()),
        ("sem_norm", &frame.sem_norm, r.sem_norm.clone()),
    ];
    for (name, got, want) in checks {
        assert_eq!(got.len(), want.len(), "{what}: {name} length");
        let (d, i) = max_diff_outside(got, want.iter().copied(), got.len() / pixels, &cutoff);
        assert!(
            d <= tol,
            "{what}: {name} differs by {d:.3e} at element {i}: gpu {} cpu {}",
            got[i],
            want[i]
        );
    }
    // Expected depth is a ratio of sums: compare relative to the depth itself.
    for (i, (&gd, &cd)) in frame.depth.iter().zip(&r.depth).enumerate() {
        assert!(
            cutoff.contains(&i) || (gd as f64 - cd).abs() <= tol * cd.abs().max(1.0),
            "{what}: depth at {i}: gpu {gd} cpu {cd}"
        );
    }
    if !exact_lists {
        return frame;
    }
    let counts_differ = (frame.n_contrib.iter().zip(&r.n_contrib).enumerate())
        .find(|(i, (a, b))| a != b && !cutoff.contains(i));
    assert_eq!(counts_differ, None, "{what}: contributor counts");

    let want = reference::tile_intersections(&projected, cam);
    let got = raster.last_intersections().unwrap();
    assert_eq!(
        frame.visible as usize,
        projected.len(),
        "{what}: visible Gaussians"
    );
    if got != want {
        let first = (0..got.len().max(want.len()))
            .find(|&i| got.get(i) != want.get(i))
            .unwrap();
        panic!(
            "{what}: intersection lists differ (gpu {} entries, cpu {}); first difference at {first}: gpu {:?} cpu {:?}",
            got.len(),
            want.len(),
            got.get(first),
            want.get(first)
        );
    }
    frame
}

/// lavapipe's storage-buffer binding limit: the size the split tests are built around.
const LAVAPIPE_BINDING: u64 = 128 << 20;

#[test]
fn random_scenes_match_the_reference() {
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    // (n, C, SH degree, mode): every C of the issue, both modes, N up to 20k.
    let cases = [
        (2_000, 1, 0, SemanticMode::RawLogits),
        (5_000, 3, 1, SemanticMode::Softmax),
        (20_000, 8, 3, SemanticMode::RawLogits),
        (8_000, 17, 2, SemanticMode::Softmax),
        (3_000, 64, 3, SemanticMode::RawLogits),
        (3_000, 64, 0, SemanticMode::Softmax),
    ];
    for (k, &(n, c, deg, mode)) in cases.iter().enumerate() {
        let g = random_scene(&RandomSceneSpec {
            n,
            channels: c,
            sh_degree: deg,
            seed: 100 + k as u64,
            ..Default::default()
        });
        for cam in poses(97, 71) {
            compare(
                &mut raster,
                &g,
                &cam,
                Some(mode),
                &format!("n={n} C={c} deg={deg} {mode:?} {}", cam.name),
            );
        }
    }
    // RGB only on a scene that has semantics: C = 0 in the output.
    let g = random_scene(&RandomSceneSpec {
        n: 4_000,
        channels: 5,
        sh_degree: 3,
        seed: 9,
        ..Default::default()
    });
    let f = compare(&mut raster, &g, &poses(64, 48)[0], None, "rgb only");
    assert_eq!(f.channels, 0);
    assert!(f.sem.is_empty());
    check_validation(gpu);
}

/// The 500-Gaussian random scene each edge case edits.
fn edge_case_base(seed: u64) -> Gaussians {
    random_scene(&RandomSceneSpec {
        n: 500,
        channels: 3,
        sh_degree: 1,
        seed,
        ..Default::default()
    })
}

/// N = 0: background everywhere.
fn check_empty_scene(raster: &mut Rasterizer, cam: &Camera) {
    let empty = Gaussians {
        semantics: None,
        ..Default::default()
    };
    let f = compare(raster, &empty, cam, None, "empty scene");
    assert!(f.alpha.iter().all(|&a| a == 0.0));
    assert!((f.rgb[0] - 0.2).abs() < 1e-6 && (f.rgb[2] - 0.6).abs() < 1e-6);
}

/// Every Gaussian behind the camera, or between the camera and the near plane.
fn check_behind_and_inside_near_plane(raster: &mut Rasterizer, cam: &Camera) {
    let mut behind = edge_case_base(1);
    behind.means.iter_mut().for_each(|m| m[2] = -m[2]);
    let f = compare(
        raster,
        &behind,
        cam,
        Some(SemanticMode::RawLogits),
        "behind",
    );
    assert_eq!(f.visible, 0);
    let mut near = edge_case_base(2);
    near.means.iter_mut().for_each(|m| m[2] *= 0.001);
    compare(
        raster,
        &near,
        cam,
        Some(SemanticMode::RawLogits),
        "inside near plane",
    );
}

/// Scales much larger than the image, and tiny and degenerate ones (a zero-thickness disk,
/// a needle, a point).
fn check_extreme_scales(raster: &mut Rasterizer, cam: &Camera) {
    let mut huge = edge_case_base(3);
    huge.log_scales
        .iter_mut()
        .for_each(|s| *s = [2.0, 1.5, 2.5]);
    compare(raster, &huge, cam, Some(SemanticMode::Softmax), "huge");

    let mut tiny = edge_case_base(4);
    for (i, s) in tiny.log_scales.iter_mut().enumerate() {
        *s = match i % 3 {
            0 => [-20.0, -20.0, -20.0],
            1 => [-1.0, -30.0, -3.0],
            _ => [-30.0, -30.0, -1.0],
        };
    }
    compare(
        raster,
        &tiny,
        cam,
        Some(SemanticMode::RawLogits),
        "tiny scales",
    );
}

/// Extreme opacities (saturating: alpha clamped to 0.999, T stop; and invisible), and
/// zero quaternions, which are culled on both sides.
fn check_extreme_opacities_and_zero_quaternions(raster: &mut Rasterizer, cam: &Camera) {
    let mut opaque = edge_case_base(5);
    for (i, o) in opaque.opacity_logits.iter_mut().enumerate() {
        *o = if i % 2 == 0 { 30.0 } else { -30.0 };
    }
    compare(
        raster,
        &opaque,
        cam,
        Some(SemanticMode::RawLogits),
        "extreme opacity",
    );

    let mut zero_q = edge_case_base(6);
    zero_q
        .quats
        .iter_mut()
        .step_by(2)
        .for_each(|q| *q = [0.0; 4]);
    compare(
        raster,
        &zero_q,
        cam,
        Some(SemanticMode::RawLogits),
        "zero quaternions",
    );
}

/// Image sizes that are not multiples of 16, down to one pixel.
fn check_odd_image_sizes(raster: &mut Rasterizer) {
    let g = edge_case_base(7);
    for (w, h) in [(1, 1), (17, 15), (16, 33), (130, 7)] {
        let cam = camera("odd", DVec3::ZERO, DVec3::new(0.0, 0.0, 1.0), w, h);
        compare(
            raster,
            &g,
            &cam,
            Some(SemanticMode::Softmax),
            &format!("{w}x{h}"),
        );
    }
}

#[test]
fn edge_cases_match_the_reference() {
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    let cam = camera("c", DVec3::ZERO, DVec3::new(0.0, 0.0, 1.0), 53, 37);
    check_empty_scene(&mut raster, &cam);
    check_behind_and_inside_near_plane(&mut raster, &cam);
    check_extreme_scales(&mut raster, &cam);
    check_extreme_opacities_and_zero_quaternions(&mut raster, &cam);
    check_odd_image_sizes(&mut raster);
    check_validation(gpu);
}

#[test]
fn small_windows_carry_state_between_blend_dispatches() {
    // Windows of 50 entries split most tile lists; results must not change.
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    raster.set_window_len(50);
    let g = random_scene(&RandomSceneSpec {
        n: 3_000,
        channels: 17,
        sh_degree: 2,
        seed: 21,
        ..Default::default()
    });
    for cam in poses(80, 50) {
        compare(
            &mut raster,
            &g,
            &cam,
            Some(SemanticMode::RawLogits),
            &format!("window 50 {}", cam.name),
        );
    }
    check_validation(gpu);
}

#[test]
fn bands_of_tile_rows_match_the_reference() {
    // One tile row per dispatch, with windows of 50 entries (carried state) and 17
    // channels (two chunks): every per-pixel buffer is bound band by band.
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    raster.set_band_rows(1);
    raster.set_window_len(50);
    let g = random_scene(&RandomSceneSpec {
        n: 3_000,
        channels: 17,
        sh_degree: 1,
        seed: 27,
        ..Default::default()
    });
    for cam in poses(70, 53) {
        compare(
            &mut raster,
            &g,
            &cam,
            Some(SemanticMode::Softmax),
            &format!("bands of one row {}", cam.name),
        );
    }
    check_validation(gpu);
}

#[test]
fn views_binned_in_bands_of_rows_match_the_reference() {
    // Lists of at most a third of the view's pairs: the view is binned band by band of
    // tile rows, each band sorted and blended in turn.
    let gpu = gpu();
    let g = random_scene(&RandomSceneSpec {
        n: 3_000,
        channels: 3,
        sh_degree: 1,
        seed: 37,
        ..Default::default()
    });
    for cam in poses(96, 80) {
        let scene = GpuScene::upload(gpu, &separate_depth_ties(&g, &cam)).unwrap();
        let opts = RenderOptions::default();
        let whole = Rasterizer::new(gpu).render(&scene, &cam, &opts).unwrap();
        let mut banded = Rasterizer::new(gpu);
        // A third of the pairs, but at least the busiest row of tiles (a band's minimum).
        let tiles_x = cam.width.div_ceil(16);
        let pairs = reference::tile_intersections(
            &reference::project(&g, &cam, &RenderSettings::default()),
            &cam,
        );
        let mut per_row = vec![0u32; cam.height.div_ceil(16) as usize];
        pairs
            .iter()
            .for_each(|(tile, _)| per_row[(tile / tiles_x) as usize] += 1);
        let busiest = per_row.iter().copied().max().unwrap();
        banded.set_list_capacity(busiest.max(whole.intersections / 3));
        let run = banded
            .run_tiled_in_bands(&scene, &cam, &opts, BandWork::Overwrite, |_, _| Ok(()))
            .unwrap();
        assert!(
            run.list_bands >= 3,
            "{}: {} bands",
            cam.name,
            run.list_bands
        );
        // The lists are per band, so only the images (and contributor counts) compare.
        let frame = compare_within(
            &mut banded,
            &g,
            &cam,
            Some(SemanticMode::RawLogits),
            &format!("list bands {}", cam.name),
            TOL,
            false,
        );
        assert_eq!(frame.n_contrib, whole.n_contrib, "{}", cam.name);
        assert_eq!(frame.intersections, whole.intersections, "{}", cam.name);
    }
    check_validation(gpu);
}

#[test]
fn a_tile_longer_than_lavapipes_loop_cap_renders_whole() {
    // 70,000 faint Gaussians in one 16x16 tile, each covering about one pixel, in front of
    // one bright Gaussian that sits last in depth order. A pixel's loop walks the whole
    // list (about 273 of them blend at each pixel, T stays near 0.25), so a blend cut off
    // after 65,535 iterations would miss the bright one.
    let gpu = gpu();
    let n = 70_000;
    let (g, cam) = common::long_tile(n);
    let mut raster = Rasterizer::new(gpu);
    let f = compare(&mut raster, &g, &cam, None, "70k-entry tile");
    assert!(
        f.intersections as usize > n,
        "the tile list holds every Gaussian"
    );
    let bright_red = f.rgb.iter().step_by(3).fold(0.0f32, |m, &r| m.max(r));
    assert!(
        bright_red > 0.3,
        "the last Gaussian in the list was blended (red {bright_red})"
    );
    check_validation(gpu);
}

/// One Gaussian covering 257 x 257 tiles, more than lavapipe's loop cap of 65,535
/// iterations an invocation: emission takes the load-balanced form there, and every tile
/// draws it (one invocation writing its pairs stopped 4,653 tiles short of 69,696).
#[test]
fn a_gaussian_over_more_tiles_than_the_loop_cap_is_emitted_whole() {
    let side = 257 * 16;
    let g = common::spec_scene::scene(&[common::spec_scene::Spec {
        mean: [0.0, 0.0, 5.0],
        log_scale: [50f32.ln(); 3],
        quat: [1.0, 0.0, 0.0, 0.0],
        logit: 4.0,
        sh: vec![[0.5; 3]],
        logits: vec![],
    }]);
    let cam = camera("wide", DVec3::ZERO, DVec3::Z, side, side);
    for wide in [false, true] {
        let gpu = common::gpu_with_cpu_forms(wide);
        let scene = GpuScene::upload(gpu, &g).unwrap();
        let opts = RenderOptions {
            semantics: None,
            ..Default::default()
        };
        let frame = Rasterizer::new(gpu).render(&scene, &cam, &opts).unwrap();
        let empty = frame.alpha.iter().filter(|&&a| a < 0.5).count();
        assert_eq!(
            empty, 0,
            "wide forms {wide}: {empty} pixels without the Gaussian"
        );
        check_validation(gpu);
    }
}

#[test]
fn intersection_buffer_grows_on_overflow() {
    // 200 large Gaussians on a 640x480 image: ~240k intersections, past the first guess
    // (max(4N, 65536)); the frame is rendered again with room for all of them.
    let gpu = gpu();
    let mut g = random_scene(&RandomSceneSpec {
        n: 200,
        seed: 33,
        ..Default::default()
    });
    g.log_scales.iter_mut().for_each(|s| *s = [1.0, 1.0, 1.0]);
    let cam = camera("wide", DVec3::ZERO, DVec3::new(0.0, 0.0, 1.0), 640, 480);
    let mut raster = Rasterizer::new(gpu);
    let f = compare(&mut raster, &g, &cam, None, "overflow");
    assert!(
        f.intersections > 65_536,
        "test must overflow the first guess ({})",
        f.intersections
    );
    check_validation(gpu);
}

/// `n` Gaussians, each covering every tile of a 4096x4096 view (65,536 tiles).
fn view_covering(n: usize) -> (Gaussians, Camera) {
    let mut g = random_scene(&RandomSceneSpec {
        n,
        seed: 35,
        ..Default::default()
    });
    for (i, m) in g.means.iter_mut().enumerate() {
        *m = [0.0, 0.0, 5.0 + i as f32 * 1e-3];
    }
    g.log_scales.iter_mut().for_each(|s| *s = [4.0; 3]);
    g.opacity_logits.iter_mut().for_each(|o| *o = 5.0);
    let cam = camera("huge", DVec3::ZERO, DVec3::new(0.0, 0.0, 1.0), 4096, 4096);
    (g, cam)
}

/// Intersection totals past what 32 bits or one binding hold: a clear error, never a
/// silent result. 65,536 view-covering Gaussians at 4096x4096 make exactly 2^32 pairs
/// (a 32-bit total wraps to 0, which once read as "every Gaussian unseen"); one fewer
/// makes 2^32 - 65,536, past lavapipe's 128 MiB binding (once a bare vkCreateBuffer error).
#[test]
fn intersection_totals_past_32_bits_or_a_binding_are_clear_errors() {
    let gpu = gpu();
    let opts = RenderOptions {
        semantics: None,
        ..Default::default()
    };
    for (n, expect) in [(65_536, "more than 2^32 - 1"), (65_535, "binding limit")] {
        let (g, cam) = view_covering(n);
        let scene = GpuScene::upload(gpu, &g).unwrap();
        let mut raster = Rasterizer::new(gpu);
        let err = match raster.run_tiled(&scene, &cam, &opts, |_, _| Ok(())) {
            Ok(run) => panic!(
                "{n} Gaussians: no error, {} intersections",
                run.intersections
            ),
            Err(e) => format!("{e:#}"),
        };
        assert!(err.contains(expect), "{n} Gaussians: {err}");
    }
    check_validation(gpu);
}

#[test]
fn frames_report_stage_times() {
    let gpu = gpu();
    let g = random_scene(&RandomSceneSpec {
        n: 2_000,
        channels: 4,
        ..Default::default()
    });
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let mut raster = Rasterizer::new(gpu);
    let f = raster
        .render(&scene, &poses(64, 64)[0], &RenderOptions::default())
        .unwrap();
    let s = f.stages;
    for (name, v) in [
        ("project", s.project_ms),
        ("depth sort", s.depth_sort_ms),
        ("bin", s.bin_ms),
        ("blend", s.blend_ms),
    ] {
        assert!(v.is_finite() && v > 0.0, "{name}: {v} ms");
    }
    check_validation(gpu);
}

#[test]
fn float32_projection_matches_the_reference_too() {
    // Devices without shaderFloat64 project the means in float32: the camera-space mean
    // then carries ~1e-6 relative error, ~1e-5 px in the 2D mean, which shows as up to
    // ~2e-4 in alpha on these scenes (measured); this path is held to 1e-3, and a Gaussian
    // at the 1/255 alpha or extent boundary may flip, so lists are not compared exactly.
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    raster.set_float64_projection(false);
    let g = random_scene(&RandomSceneSpec {
        n: 6_000,
        channels: 3,
        sh_degree: 2,
        seed: 77,
        ..Default::default()
    });
    for cam in poses(97, 71) {
        compare_within(
            &mut raster,
            &g,
            &cam,
            Some(SemanticMode::RawLogits),
            &format!("float32 {}", cam.name),
            1e-3,
            false,
        );
    }
    check_validation(gpu);
}

#[test]
fn projection_in_chunks_matches_the_reference() {
    // Chunks of 256 Gaussians: each dispatch binds its part of every per-Gaussian buffer.
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    raster.set_projection_chunk(256);
    let g = random_scene(&RandomSceneSpec {
        n: 3_000,
        channels: 5,
        sh_degree: 3,
        seed: 23,
        ..Default::default()
    });
    for cam in poses(80, 50) {
        compare(
            &mut raster,
            &g,
            &cam,
            Some(SemanticMode::RawLogits),
            &format!("chunks of 256 {}", cam.name),
        );
    }
    check_validation(gpu);
}

#[test]
fn a_scene_whose_sh_passes_one_binding_renders() {
    // 750k Gaussians of SH degree 3: 144 MB of SH coefficients, over lavapipe's 128 MiB
    // binding limit, so projection runs in chunks. Every 150th Gaussian is in view and the
    // rest behind the camera, so the visible ones come from every chunk while the image
    // stays comparable with the reference pixel for pixel (as many Gaussians per pixel as
    // the other tests, not thousands).
    let gpu = gpu();
    let n = 750_000;
    let mut g = random_scene(&RandomSceneSpec {
        n,
        sh_degree: 3,
        seed: 29,
        ..Default::default()
    });
    for (i, m) in g.means.iter_mut().enumerate() {
        if i % 150 != 0 {
            m[2] = -m[2].abs() - 1.0;
        }
    }
    let sh_bytes = g.sh.len() as u64 * 4;
    assert!(sh_bytes > LAVAPIPE_BINDING, "{sh_bytes}");
    let mut raster = Rasterizer::new(gpu);
    if sh_bytes <= gpu.caps().max_storage_buffer_range {
        // A device with a larger binding limit (4 GiB on NVIDIA) would project it whole:
        // split it as lavapipe must, so the chunked path is what this test checks.
        raster.set_projection_chunk((LAVAPIPE_BINDING / (16 * 3 * 4)) as u32);
    }
    let cam = camera("front", DVec3::ZERO, DVec3::new(0.0, 0.0, 5.0), 64, 48);
    let frame = compare(&mut raster, &g, &cam, None, "750k SH3");
    assert!(frame.visible > 4_000, "{} visible", frame.visible);
    check_validation(gpu);
}

/// Renders `g` on both sides and compares rgb, alpha and the semantic channels, allowing
/// a few threshold pixels: where a Gaussian's alpha lies within float rounding of 1/255 (or
/// T of 1e-4) the two sides may keep or skip it, which moves a pixel by about alpha_min
/// times a colour difference. Millions of pixels make a few such pixels likely; a wrong
/// band would change whole rows of tiles.
/// Blending runs in bands of tile rows of at most lavapipe's binding, `bytes_per_pixel` of
/// the widest per-pixel buffer, also on a device whose binding limit would take it whole.
fn compare_allowing_threshold_pixels(
    g: &Gaussians,
    cam: &Camera,
    mode: Option<SemanticMode>,
    bytes_per_pixel: u64,
) {
    let g = &separate_depth_ties(g, cam);
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    let per_tile_row = bytes_per_pixel * cam.width as u64 * 16;
    if per_tile_row * cam.height.div_ceil(16) as u64 <= gpu.caps().max_storage_buffer_range {
        raster.set_band_rows((LAVAPIPE_BINDING / per_tile_row) as u32);
    }
    let (frame, r, _) = render_both(&mut raster, g, cam, mode);
    let pixels = (cam.width * cam.height) as usize;
    let checks: [(&str, &[f32], Vec<f64>); 3] = [
        ("rgb", &frame.rgb, r.rgb.iter().flatten().copied().collect()),
        ("alpha", &frame.alpha, r.alpha.clone()),
        ("sem", &frame.sem, r.sem.clone()),
    ];
    for (name, got, want) in checks {
        assert_eq!(got.len(), want.len(), "{}: {name} length", cam.name);
        let per_pixel = got.len() / pixels;
        let mut off = BTreeSet::new();
        for (i, (&a, &b)) in got.iter().zip(&want).enumerate() {
            let d = (a as f64 - b).abs();
            assert!(d <= 0.02, "{}: {name}[{i}] gpu {a} cpu {b}", cam.name);
            if d > TOL {
                off.insert(i / per_pixel.max(1));
            }
        }
        assert!(
            off.len() <= 20,
            "{}: {name}: {} pixels differ",
            cam.name,
            off.len()
        );
    }
}

#[test]
fn large_images_and_many_classes_render_in_bands() {
    // 4096x3072 RGB (151 MB of rgb) and 1920x1080 with 64 classes (531 MB of semantic
    // channels): both over lavapipe's 128 MiB binding, so blending runs in bands. A sparse
    // scene keeps the f64 reference quick at these sizes.
    let gpu = gpu();
    let g = random_scene(&RandomSceneSpec {
        n: 300,
        channels: 64,
        sh_degree: 1,
        seed: 33,
        ..Default::default()
    });
    let big = camera("4k", DVec3::ZERO, DVec3::new(0.0, 0.0, 5.0), 4096, 3072);
    let rgb_bytes = 4096u64 * 3072 * 12;
    assert!(rgb_bytes > LAVAPIPE_BINDING);
    compare_allowing_threshold_pixels(&g, &big, None, 12);
    let hd = camera("hd", DVec3::ZERO, DVec3::new(0.0, 0.0, 5.0), 1920, 1080);
    compare_allowing_threshold_pixels(&g, &hd, Some(SemanticMode::Softmax), 64 * 4);
    check_validation(gpu);
}

/// Median depth (the occlusion test of segment consensus): per pixel, the depth of the
/// Gaussian that takes the transmittance below one half, against the f64 reference's
/// contributions; in windows of 50 entries, so the state is carried between dispatches.
/// Forward blending with one pixel an invocation (a GPU's form) and with several (a CPU
/// driver's, `*_wide`): each pixel blends the same entries in the same order, so every
/// output is the same bit for bit (RGB with 17 channels, whole and in windows of 50
/// entries, and the median depth). The reference checks above run the device's default
/// form; this carries them to the other.
#[test]
fn both_tile_forms_render_the_same_bytes() {
    let g = random_scene(&RandomSceneSpec {
        n: 3_000,
        channels: 17,
        sh_degree: 1,
        seed: 41,
        ..Default::default()
    });
    let opts = RenderOptions {
        semantics: Some(SemanticMode::RawLogits),
        ..Default::default()
    };
    for window_len in [None, Some(50)] {
        for cam in poses(80, 50) {
            let [one, several] = [false, true].map(|wide| {
                let gpu = common::gpu_with_cpu_forms(wide);
                let mut raster = Rasterizer::new(gpu);
                if let Some(len) = window_len {
                    raster.set_window_len(len);
                }
                let scene = GpuScene::upload(gpu, &g).unwrap();
                let f = raster.render(&scene, &cam, &opts).unwrap();
                raster
                    .run_tiled_in_bands(&scene, &cam, &opts, BandWork::Overwrite, |rec, tiles| {
                        tiles.record_median_depth(rec)
                    })
                    .unwrap();
                let n = (cam.width * cam.height) as usize;
                let median: Vec<f32> = gpu.download(raster.depth(), 0, n).unwrap();
                (
                    f.rgb,
                    f.alpha,
                    f.depth,
                    f.final_t,
                    f.last,
                    f.n_contrib,
                    f.sem,
                    f.sem_norm,
                    median,
                )
            });
            assert!(
                one.1.iter().any(|&a| a > 0.5),
                "{}: nothing rendered",
                cam.name
            );
            assert!(
                one == several,
                "{} windows {window_len:?}: the tile forms differ",
                cam.name
            );
        }
    }
    for wide in [false, true] {
        check_validation(common::gpu_with_cpu_forms(wide));
    }
}

/// The median-depth kernel's two depths, each against the f64 reference's contributions:
/// the median (transmittance below one half) and the opaque depth (below `OPAQUE_T`).
#[test]
fn median_depth_matches_the_reference() {
    let gpu = gpu();
    let mut raster = Rasterizer::new(gpu);
    raster.set_window_len(50);
    let g = random_scene(&RandomSceneSpec {
        n: 3_000,
        channels: 5,
        seed: 33,
        ..Default::default()
    });
    for cam in poses(80, 50) {
        let g = separate_depth_ties(&g, &cam);
        let scene = GpuScene::upload(gpu, &g).unwrap();
        // Semantics on: the kernel's carried state must not follow the frame's channels.
        let opts = RenderOptions::default();
        raster
            .run_tiled_in_bands(&scene, &cam, &opts, BandWork::Overwrite, |rec, tiles| {
                tiles.record_median_depth(rec)
            })
            .unwrap();
        let pixels = (cam.width * cam.height) as usize;
        let depths = raster.occlusion_depths();
        for (buffer, threshold) in [(depths.median, MEDIAN_T), (depths.opaque, OPAQUE_T)] {
            let got: Vec<f32> = gpu.download(buffer, 0, pixels).unwrap();
            let want = common::reference_depth_below(&g, &cam, threshold as f64);
            check_depths(&got, &want, &format!("{} below {threshold}", cam.name));
        }
    }
    check_validation(gpu);
}

/// `got` within the tolerance of `want` wherever the reference decides, most pixels
/// decided, pixels of both kinds (a surface, none) among them.
fn check_depths(got: &[f32], want: &[Option<f64>], what: &str) {
    let (mut surface, mut empty) = (0, 0);
    for (i, (&got, want)) in got.iter().zip(want).enumerate() {
        let Some(want) = *want else { continue };
        let d = (got as f64 - want).abs();
        assert!(
            d <= TOL * want.max(1.0),
            "{what}: pixel {i}: gpu {got} cpu {want}"
        );
        match want > 0.0 {
            true => surface += 1,
            false => empty += 1,
        }
    }
    assert!(
        surface > 500 && empty > 0,
        "{what}: {surface} surface, {empty} empty"
    );
    assert!(
        surface + empty > want.len() * 9 / 10,
        "{what}: too few pixels checked: {surface} {empty} of {}",
        want.len()
    );
}
