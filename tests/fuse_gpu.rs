//! Fusion on the GPU against plain CPU computations: vote counts exactly, FlashSplat's A
//! against the CPU reference renderer, determinism, batching, and FlashSplat's Listing 1.1
//! (docs/papers.md).

mod common;

use common::{check_validation, gpu, separate_depth_ties};
use glam::DVec3;
use semsplat::fuse::{
    accumulate, assign_one_vs_rest, assign_semantic, Accumulation, ClassScores, FuseConfig,
    LabelSource, Method, NO_LABEL,
};
use semsplat::gpu::Gpu;
use semsplat::render::rasterizer::SplitSizes;
use semsplat::render::reference::{self, RenderSettings};
use semsplat::render::GpuScene;
use semsplat::scene::random_scene::{random_scene, RandomSceneSpec};
use semsplat::scene::{Camera, Gaussians};
use semsplat::util::Rng;

const CLASSES: usize = 5;

fn cameras() -> Vec<Camera> {
    let cam = |name: &str, eye: DVec3, target: DVec3| {
        Camera::look_at(name, eye, target, -DVec3::Y, 61, 45, 70.0)
    };
    vec![
        cam("a", DVec3::ZERO, DVec3::new(0.0, 0.0, 5.0)),
        cam("b", DVec3::new(-2.0, -1.0, 0.5), DVec3::new(0.5, 0.0, 5.0)),
        cam("c", DVec3::new(1.5, 1.0, -1.0), DVec3::new(0.0, 0.0, 4.0)),
    ]
}

/// Label maps in 6x6-pixel blocks of random classes, a few blocks unlabeled.
fn label_maps(cams: &[Camera], seed: u64) -> Vec<Option<Vec<u32>>> {
    let mut rng = Rng::new(seed);
    cams.iter()
        .map(|c| {
            let (bw, bh) = (c.width.div_ceil(6), c.height.div_ceil(6));
            let blocks: Vec<u32> = (0..bw * bh)
                .map(|_| {
                    if rng.bool(0.15) {
                        NO_LABEL
                    } else {
                        rng.below(CLASSES as u64) as u32
                    }
                })
                .collect();
            Some(
                (0..c.width * c.height)
                    .map(|i| blocks[((i / c.width / 6) * bw + (i % c.width) / 6) as usize])
                    .collect(),
            )
        })
        .collect()
}

fn scene(n: usize, seed: u64) -> Gaussians {
    random_scene(&RandomSceneSpec {
        n,
        seed,
        scale: (0.01, 0.1),
        ..Default::default()
    })
}

fn run(
    g: &Gaussians,
    cams: &[Camera],
    labels: &Vec<Option<Vec<u32>>>,
    cfg: &FuseConfig,
) -> ClassScores {
    run_on(gpu(), g, cams, labels, cfg)
}

fn run_on(
    gpu: &Gpu,
    g: &Gaussians,
    cams: &[Camera],
    labels: &Vec<Option<Vec<u32>>>,
    cfg: &FuseConfig,
) -> ClassScores {
    let scene = GpuScene::upload(gpu, g).unwrap();
    accumulate(gpu, &scene, cams, labels, CLASSES, cfg, |_, _| {})
        .unwrap()
        .0
}

#[test]
fn vote_counts_equal_a_cpu_count() {
    let g = scene(3_000, 1);
    let cams = cameras();
    let labels = label_maps(&cams, 2);
    let got = run(
        &g,
        &cams,
        &labels,
        &FuseConfig {
            method: Method::Vote,
            ..Default::default()
        },
    );
    let mut want = ClassScores::zeros(CLASSES, g.len());
    // Centers within 1e-4 px of a pixel edge may land on either side in f32: leave them out.
    let mut ambiguous = vec![false; g.len()];
    for (cam, map) in cams.iter().zip(&labels) {
        let map = map.as_ref().unwrap();
        for (i, m) in g.means.iter().enumerate() {
            let p = cam.world_to_camera(DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64));
            if p.z <= 0.01 {
                continue;
            }
            let (u, v) = cam.project_camera_point(p);
            let near_edge = |x: f64| (x - x.round()).abs() < 1e-4;
            if near_edge(u) || near_edge(v) {
                ambiguous[i] = true;
            }
            if u < 0.0 || v < 0.0 || u >= cam.width as f64 || v >= cam.height as f64 {
                continue;
            }
            let label = map[v as usize * cam.width as usize + u as usize];
            if label != NO_LABEL {
                want.data[label as usize * g.len() + i] += 1.0;
            }
        }
    }
    let left_out = ambiguous.iter().filter(|&&a| a).count();
    assert!(left_out < g.len() / 100, "{left_out} ambiguous centers");
    let mut compared = 0;
    for i in (0..g.len()).filter(|&i| !ambiguous[i]) {
        for e in 0..CLASSES {
            assert_eq!(got.get(e, i), want.get(e, i), "gaussian {i} class {e}");
        }
        compared += 1;
    }
    assert!(
        want.data.iter().sum::<f64>() > 1000.0,
        "the scene must produce votes"
    );
    assert!(compared > 2_900);
    check_validation(gpu());
}

/// Which pixels count, and how much.
#[derive(Clone, Copy, PartialEq)]
enum Weights {
    /// alpha * T at every pixel (FlashSplat's A).
    Every,
    /// alpha * T at the pixel holding the Gaussian's center only (weighted vote).
    CenterOnly,
    /// alpha * T over the Gaussian's footprint in the view: 2 pi opacity sqrt(det cov2d).
    PerView,
}

/// A[label(pixel)][g] += alpha * T over every pixel, from the f64 reference renderer.
fn reference_contributions(
    g: &Gaussians,
    cams: &[Camera],
    labels: &[Option<Vec<u32>>],
    weights: Weights,
) -> ClassScores {
    let mut a = ClassScores::zeros(CLASSES, g.len());
    let settings = RenderSettings {
        semantics: false,
        ..Default::default()
    };
    let center_only = weights == Weights::CenterOnly;
    for (cam, map) in cams.iter().zip(labels) {
        let map = map.as_ref().unwrap();
        let footprint: Vec<f64> = (0..g.len())
            .map(|i| match reference::project_one(g, i, cam, &settings) {
                Ok(p) if weights == Weights::PerView => {
                    let [xx, xy, yy] = p.cov2d;
                    std::f64::consts::TAU * p.opacity * (xx * yy - xy * xy).sqrt()
                }
                _ => 1.0,
            })
            .collect();
        let centers: Vec<(i64, i64)> = g
            .means
            .iter()
            .map(|m| {
                let p = cam.world_to_camera(DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64));
                let (u, v) = cam.project_camera_point(p);
                (u.floor() as i64, v.floor() as i64)
            })
            .collect();
        reference::for_each_contribution(g, cam, &settings, |px, py, id, w| {
            let label = map[(py * cam.width + px) as usize];
            if label == NO_LABEL || (center_only && centers[id as usize] != (px as i64, py as i64))
            {
                return;
            }
            a.data[label as usize * g.len() + id as usize] += w / footprint[id as usize];
        });
    }
    a
}

fn assert_close(got: &ClassScores, want: &ClassScores, what: &str) {
    assert_eq!((got.classes, got.n), (want.classes, want.n));
    // 1e-5 relative; the absolute floor covers entries made of a few tiny weights, where
    // float32 alpha (about 1e-7 relative per term) dominates.
    for (k, (&a, &b)) in got.data.iter().zip(&want.data).enumerate() {
        assert!(
            (a - b).abs() <= 1e-5 * b.abs() + 1e-6,
            "{what}: entry {k} (class {}, gaussian {}): gpu {a} cpu {b}",
            k / got.n,
            k % got.n
        );
    }
}

/// Plain (fixed point and float atomics) and per-view A, view by view.
#[test]
fn flashsplat_contributions_match_the_reference() {
    let cams = cameras();
    let labels = label_maps(&cams, 5);
    // Each view's near-ties separated for all views at once is not possible; one view's
    // ordering is what matters per comparison, so compare view by view.
    for (v, cam) in cams.iter().enumerate() {
        let g = separate_depth_ties(&scene(4_000, 7), cam);
        let one_cam = std::slice::from_ref(cam);
        let one_map = vec![labels[v].clone()];
        let got = run(&g, one_cam, &one_map, &FuseConfig::default());
        let want = reference_contributions(&g, one_cam, &one_map, Weights::Every);
        assert!(
            want.data.iter().sum::<f64>() > 10.0,
            "view {v} must see the scene"
        );
        assert_close(&got, &want, &format!("view {}", cam.name));
        let float = run(
            &g,
            one_cam,
            &one_map,
            &FuseConfig {
                accumulation: Accumulation::Float,
                ..Default::default()
            },
        );
        assert_close(&float, &want, &format!("float atomics, view {}", cam.name));

        let per_view_cfg = FuseConfig {
            method: Method::FlashSplatPerView,
            ..Default::default()
        };
        let per_view = run(&g, one_cam, &one_map, &per_view_cfg);
        let want_per_view = reference_contributions(&g, one_cam, &one_map, Weights::PerView);
        // The normalization must change A (or this would pass on plain FlashSplat); a
        // Gaussian the view sees whole sums to about 1 over the labels.
        assert!(
            (want_per_view.data.iter().sum::<f64>() - want.data.iter().sum::<f64>()).abs() > 1.0,
            "view {v}: footprint normalization changed nothing"
        );
        assert_close(
            &per_view,
            &want_per_view,
            &format!("per view, view {}", cam.name),
        );
    }
    check_validation(gpu());
}

#[test]
fn fixed_point_is_deterministic_and_batching_changes_nothing() {
    let g = scene(5_000, 11);
    let cams = cameras();
    let labels = label_maps(&cams, 12);
    let dense = run(&g, &cams, &labels, &FuseConfig::default());
    let again = run(&g, &cams, &labels, &FuseConfig::default());
    assert!(
        dense.data == again.data,
        "fixed-point A differs between two runs"
    );
    // A budget of one class row at a time: five passes over the views.
    let one_row = 5_000 * 8;
    let batched = run(
        &g,
        &cams,
        &labels,
        &FuseConfig {
            mem_budget: Some(one_row),
            ..Default::default()
        },
    );
    assert!(dense.data == batched.data, "batched A differs from dense A");
    let votes = run(
        &g,
        &cams,
        &labels,
        &FuseConfig {
            method: Method::Vote,
            ..Default::default()
        },
    );
    let votes_batched = run(
        &g,
        &cams,
        &labels,
        &FuseConfig {
            method: Method::Vote,
            mem_budget: Some(5_000 * 4 * 2),
            ..Default::default()
        },
    );
    assert!(votes.data == votes_batched.data);
    check_validation(gpu());
}

#[test]
fn weighted_votes_match_the_reference_at_center_pixels() {
    let cams = cameras();
    let labels = label_maps(&cams, 9);
    let cam = &cams[0];
    let mut g = separate_depth_ties(&scene(3_000, 13), cam);
    // Keep centers away from pixel edges, where f32 and f64 may pick different pixels.
    for m in g.means.iter_mut() {
        let p = cam.world_to_camera(DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64));
        let (u, v) = cam.project_camera_point(p);
        let snap = |x: f64, f: f64, c: f64| ((x.floor() + 0.5) - c) / f * p.z;
        let (x, y) = (snap(u, cam.fx, cam.cx), snap(v, cam.fy, cam.cy));
        let world = cam.rotation.transpose() * (DVec3::new(x, y, p.z) - cam.translation);
        *m = [world.x as f32, world.y as f32, world.z as f32];
    }
    let one_map = vec![labels[0].clone()];
    let cfg = FuseConfig {
        method: Method::VoteWeighted,
        ..Default::default()
    };
    let got = run(&g, std::slice::from_ref(cam), &one_map, &cfg);
    let want =
        reference_contributions(&g, std::slice::from_ref(cam), &one_map, Weights::CenterOnly);
    assert!(want.data.iter().filter(|&&v| v > 0.0).count() > 100);
    assert_close(&got, &want, "weighted votes");
    check_validation(gpu());
}

#[test]
fn occlusion_keeps_hidden_gaussians_from_voting() {
    // A wall of opaque Gaussians at z = 3 hides a second wall at z = 6; the label map is
    // one class. Plain votes count both walls; occlusion-checked votes only the front.
    let cam = Camera::look_at("o", DVec3::ZERO, DVec3::Z, -DVec3::Y, 48, 48, 50.0);
    let mut g = Gaussians::default();
    for (z, _) in [(3.0f32, 0), (6.0, 1)] {
        for iy in 0..30 {
            for ix in 0..30 {
                let (x, y) = (
                    (ix as f32 - 14.5) * 0.05 * z / 3.0,
                    (iy as f32 - 14.5) * 0.05 * z / 3.0,
                );
                g.means.push([x, y, z]);
                g.log_scales.push([
                    (0.05 * z / 3.0f32).ln(),
                    (0.05 * z / 3.0f32).ln(),
                    (0.001f32).ln(),
                ]);
                g.quats.push([1.0, 0.0, 0.0, 0.0]);
                g.opacity_logits.push(6.0);
                g.sh.extend([0.5, 0.5, 0.5]);
            }
        }
    }
    let labels = vec![Some(vec![2u32; 48 * 48])];
    let cams = [cam];
    let plain = run(
        &g,
        &cams,
        &labels,
        &FuseConfig {
            method: Method::Vote,
            ..Default::default()
        },
    );
    let occl = run(
        &g,
        &cams,
        &labels,
        &FuseConfig {
            method: Method::VoteOcclusion,
            ..Default::default()
        },
    );
    let front_plain: f64 = plain.row(2)[..900].iter().sum();
    let back_plain: f64 = plain.row(2)[900..].iter().sum();
    let front_occl: f64 = occl.row(2)[..900].iter().sum();
    let back_occl: f64 = occl.row(2)[900..].iter().sum();
    assert!(
        front_plain > 500.0 && back_plain > 500.0,
        "{front_plain} {back_plain}"
    );
    assert!(
        front_occl > 0.9 * front_plain,
        "visible centers still vote: {front_occl} of {front_plain}"
    );
    assert_eq!(back_occl, 0.0, "hidden centers must not vote");
    check_validation(gpu());
}

/// Listing 1.1 of FlashSplat (docs/papers.md), transcribed line by line.
fn listing_1_1(all_contrib: &[Vec<f64>], gamma: f64) -> Vec<Vec<u8>> {
    let obj_num = all_contrib.len();
    let gs_num = all_contrib[0].len();
    // all_contrib_sum = all_contrib.sum(dim=0)
    let all_contrib_sum: Vec<f64> = (0..gs_num)
        .map(|j| (0..obj_num).map(|i| all_contrib[i][j]).sum())
        .collect();
    let mut all_obj_labels = vec![vec![0u8; gs_num]; obj_num];
    for (obj_idx, obj_contrib) in all_contrib.iter().enumerate() {
        for j in 0..gs_num {
            // other_contrib = all_contrib_sum - obj_contrib; stack([other, obj])
            let mut pair = [all_contrib_sum[j] - obj_contrib[j], obj_contrib[j]];
            // F.normalize(dim=0, p=1): divide by max(L1 norm, eps = 1e-12)
            let norm = (pair[0].abs() + pair[1].abs()).max(1e-12);
            pair = [pair[0] / norm, pair[1] / norm];
            // obj_contrib[0, :] += gamma
            pair[0] += gamma;
            // argmax over dim 0; the first maximum wins
            all_obj_labels[obj_idx][j] = if pair[1] > pair[0] { 1 } else { 0 };
        }
    }
    all_obj_labels
}

#[test]
fn one_vs_rest_assignment_is_listing_1_1() {
    let mut rng = Rng::new(3);
    let (e, n) = (6, 2_000);
    let mut a = ClassScores::zeros(e, n);
    for (k, v) in a.data.iter_mut().enumerate() {
        // Sparse, skewed evidence, some all-zero columns (unseen Gaussians).
        *v = if k % n < 50 || rng.bool(0.4) {
            0.0
        } else {
            rng.f64().powi(3) * 10.0
        };
    }
    let rows: Vec<Vec<f64>> = (0..e).map(|r| a.row(r).to_vec()).collect();
    // One departure from the listing: a column without evidence (no view saw the
    // Gaussian) is of no class, where the listing puts it in every class at any gamma < 0.
    let unseen = |j: usize| (0..e).all(|r| rows[r][j] == 0.0);
    for gamma in [-0.3, 0.0, 0.1, 0.25, 0.6] {
        let want = listing_1_1(&rows, gamma);
        let got = assign_one_vs_rest(&a, gamma);
        for r in 0..e {
            for j in 0..n {
                let want = if unseen(j) { 0 } else { want[r][j] };
                assert_eq!(
                    got[r][j] as u8, want,
                    "gamma {gamma} class {r} gaussian {j}"
                );
            }
        }
        if gamma < 0.0 {
            assert!((0..e).all(|r| listing_1_1(&rows, gamma)[r][0] == 1 && !got[r][0]));
        }
    }
}

#[test]
fn semantic_assignment_takes_the_largest_share() {
    let a = ClassScores {
        classes: 3,
        n: 4,
        data: vec![1.0, 0.0, 0.0, 2.0, 3.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.5, 0.0],
    };
    let s = assign_semantic(&a);
    // Gaussian 3 ties classes 0 and 1 (2 each): not broken by class id but by the scene's
    // evidence per class (class 1 holds 5 in all, class 0 holds 3).
    assert_eq!(s.class, vec![Some(1), None, Some(2), Some(1)]);
    assert_eq!(s.confidence[0], 0.75);
    assert_eq!(s.confidence[1], 0.0);
    assert_eq!(s.confidence[2], 1.0);
    assert_eq!(s.confidence[3], 0.5);
}

/// The suite runs with overflow checks on (Cargo.toml's release profile), so a host-side
/// u32 overflow such as a window start past 2^32 panics in a test instead of wrapping.
#[test]
fn host_arithmetic_overflow_panics() {
    let max = std::hint::black_box(u32::MAX);
    let wrapped = std::panic::catch_unwind(|| max + std::hint::black_box(1));
    assert!(
        wrapped.is_err(),
        "overflow checks are off: u32::MAX + 1 did not panic"
    );
}

/// The per-tile kernels with one pixel an invocation (a GPU's form) and with several (a CPU
/// driver's, `*_wide`) walk each pixel's list in the same order and sum the same
/// fixed-point weights: the same evidence, bit for bit, in every method that walks the
/// tiles (occlusion reads the forward render's depth), whole and in windows of 50 entries.
#[test]
fn both_tile_forms_give_the_same_evidence() {
    let g = scene(2_000, 19);
    let cams = cameras();
    let labels = label_maps(&cams, 20);
    let both_forms = |cfg: &FuseConfig| {
        [false, true].map(|wide| run_on(common::gpu_with_cpu_forms(wide), &g, &cams, &labels, cfg))
    };
    for method in [
        Method::VoteOcclusion,
        Method::VoteWeighted,
        Method::FlashSplat,
        Method::FlashSplatPerView,
    ] {
        for window_len in [None, Some(50)] {
            let cfg = FuseConfig {
                method,
                split: SplitSizes {
                    window_len,
                    ..Default::default()
                },
                ..Default::default()
            };
            let [one, several] = both_forms(&cfg);
            assert!(one.data.iter().any(|&v| v > 0.0), "{method:?}: no evidence");
            assert_eq!(
                one.data, several.data,
                "{method:?}, windows {window_len:?}: the tile forms differ"
            );
        }
    }
    // Float atomics sum in the order they land: the two forms agree to rounding.
    let cfg = FuseConfig {
        method: Method::FlashSplat,
        accumulation: Accumulation::Float,
        ..Default::default()
    };
    let [one, several] = both_forms(&cfg);
    let top = one.data.iter().fold(0.0f64, |m, &v| m.max(v));
    for (i, (a, b)) in one.data.iter().zip(&several.data).enumerate() {
        assert!(
            (a - b).abs() <= 1e-5 * top,
            "float entry {i}: {a} against {b}"
        );
    }
    for wide in [false, true] {
        check_validation(common::gpu_with_cpu_forms(wide));
    }
}

/// A tile list longer than lavapipe's loop cap (70,000 entries, one 16x16 tile) under a
/// label map of four classes in bands of four pixel rows, so the wide form's invocations
/// (a column of the tile each) hold four rows of the evidence at every step: the whole
/// list is walked (the Gaussian last in depth order gets its share) and A matches the
/// reference, in both forms.
#[test]
fn a_tile_longer_than_the_loop_cap_accumulates_whole() {
    let n = 70_000;
    let (g, cam) = common::long_tile(n);
    let cams = vec![cam];
    let labels = vec![Some(
        (0..256u32).map(|p| (p / 16) / 4).collect::<Vec<u32>>(),
    )];
    let want = reference_contributions(&g, &cams, &labels, Weights::Every);
    for wide in [false, true] {
        let gpu = common::gpu_with_cpu_forms(wide);
        let got = run_on(gpu, &g, &cams, &labels, &FuseConfig::default());
        let last: f64 = (0..CLASSES).map(|e| got.get(e, n)).sum();
        assert!(
            last > 0.01,
            "wide tiles {wide}: the last entry added {last}"
        );
        assert_close(&got, &want, &format!("70k-entry tile, wide tiles {wide}"));
        check_validation(gpu);
    }
}

/// Every tiled method walks the tile lists in many small windows (per-pixel state carried
/// between dispatches) and gets exactly what one window per list gives. The occlusion vote
/// once computed its window starts from a window length of u32::MAX / 2, which overflowed
/// from the third window on.
#[test]
fn many_windows_and_bands_give_the_same_evidence() {
    let g = scene(600, 9);
    let cams = cameras();
    let labels = label_maps(&cams, 10);
    for method in [
        Method::VoteOcclusion,
        Method::VoteWeighted,
        Method::FlashSplat,
        Method::FlashSplatPerView,
    ] {
        let cfg = |split| FuseConfig {
            method,
            split,
            ..Default::default()
        };
        let whole = run(&g, &cams, &labels, &cfg(SplitSizes::default()));
        assert!(
            whole.data.iter().any(|&v| v > 0.0),
            "{method:?}: no evidence"
        );
        // Windows of 50 entries, one tile row per dispatch, lists of at most 400 pairs
        // (views binned in bands of rows), and all three.
        let window = SplitSizes {
            window_len: Some(50),
            ..Default::default()
        };
        let band = SplitSizes {
            band_rows: Some(1),
            ..Default::default()
        };
        let lists = SplitSizes {
            list_capacity: Some(400),
            ..Default::default()
        };
        let all = SplitSizes {
            window_len: Some(50),
            band_rows: Some(1),
            list_capacity: Some(400),
        };
        for split in [window, band, lists, all] {
            let split_run = run(&g, &cams, &labels, &cfg(split));
            assert_eq!(
                whole.data, split_run.data,
                "{method:?}: {split:?} changed the evidence"
            );
        }
    }
    check_validation(gpu());
}

/// Views binned in bands where some bands' lists overflow and others' do not: the bands
/// that fitted have added their evidence, and only the others run again (running the whole
/// view again counted the rest twice). Tall views of uneven density, in an order where the
/// band count one view leaves is too few for the next, over a range of list capacities.
#[test]
fn bands_that_fitted_are_not_counted_again_when_others_overflow() {
    let g = scene(2_000, 12);
    let tall = |name: &str, eye: DVec3, target: DVec3| {
        Camera::look_at(name, eye, target, -DVec3::Y, 48, 160, 70.0)
    };
    let cams = vec![
        tall("a", DVec3::new(0.0, -1.5, 0.0), DVec3::new(0.0, 0.5, 5.0)),
        tall("b", DVec3::ZERO, DVec3::new(0.0, 0.0, 5.0)),
        tall("c", DVec3::new(0.0, 1.5, 0.5), DVec3::new(0.0, -0.5, 5.0)),
        tall("d", DVec3::new(-1.0, 0.0, -1.0), DVec3::new(0.0, 0.0, 4.0)),
    ];
    let labels = label_maps(&cams, 13);
    for method in [Method::FlashSplat, Method::VoteWeighted] {
        let cfg = |list_capacity| FuseConfig {
            method,
            split: SplitSizes {
                list_capacity,
                ..Default::default()
            },
            views_in_flight: 1,
            ..Default::default()
        };
        let whole = run(&g, &cams, &labels, &cfg(None));
        for capacity in [1_200, 1_600, 2_100, 2_800, 3_600] {
            let banded = run(&g, &cams, &labels, &cfg(Some(capacity)));
            let differ = (whole.data.iter().zip(&banded.data))
                .filter(|(a, b)| a != b)
                .count();
            assert_eq!(
                differ, 0,
                "{method:?}: lists of {capacity} pairs changed {differ} evidence entries"
            );
        }
    }
    check_validation(gpu());
}

#[test]
fn each_method_uploads_only_what_it_reads_and_gets_the_same_evidence() {
    let gpu = gpu();
    let g = random_scene(&RandomSceneSpec {
        n: 2_000,
        sh_degree: 3,
        seed: 31,
        scale: (0.01, 0.1),
        ..Default::default()
    });
    let cams = cameras();
    let labels = label_maps(&cams, 9);
    let full = GpuScene::upload(gpu, &g).unwrap();
    for spelling in semsplat::fuse::SPELLINGS {
        let cfg = FuseConfig {
            method: spelling.method,
            ..Default::default()
        };
        let attributes = spelling.method.scene_attributes();
        let partial = GpuScene::upload_for(gpu, &g, attributes).unwrap();
        assert!(
            partial.device_bytes() < full.device_bytes() / 2,
            "{}: {attributes:?} holds {} of {} bytes",
            spelling.name,
            partial.device_bytes(),
            full.device_bytes()
        );
        let evidence = |scene: &GpuScene| {
            accumulate(gpu, scene, &cams, &labels, CLASSES, &cfg, |_, _| {})
                .unwrap()
                .0
        };
        let want = evidence(&full);
        assert!(want.data.iter().sum::<f64>() > 10.0, "{}", spelling.name);
        assert_eq!(evidence(&partial).data, want.data, "{}", spelling.name);
    }
    check_validation(gpu);
}

/// FlashSplat with lists of at most 400 pairs, so the first view of every lane overflows
/// and runs again, and `views_in_flight` views at most in flight.
fn flashsplat_overflowing(views_in_flight: usize) -> FuseConfig {
    FuseConfig {
        method: Method::FlashSplat,
        split: SplitSizes {
            list_capacity: Some(400),
            ..Default::default()
        },
        views_in_flight,
        ..Default::default()
    }
}

/// A scene of 600 Gaussians (of `seed`), `views` cameras cycling through [`cameras`], and
/// label maps for them (of `seed + 1`): the runs with several views in flight.
fn scene_and_views(seed: u64, views: usize) -> (Gaussians, Vec<Camera>, Vec<Option<Vec<u32>>>) {
    let g = scene(600, seed);
    let cams: Vec<Camera> = cameras().into_iter().cycle().take(views).collect();
    let labels = label_maps(&cams, seed + 1);
    (g, cams, labels)
}

/// Label maps that fail to load at one view, as a corrupt file would.
struct FailingAt(usize, Vec<Option<Vec<u32>>>);

impl LabelSource for FailingAt {
    fn labels(&self, view: usize, cam: &Camera) -> anyhow::Result<Option<Vec<u32>>> {
        anyhow::ensure!(view != self.0, "label map of view {} is corrupt", cam.name);
        self.1.labels(view, cam)
    }
}

/// Views run two at a time: an error while earlier views are still on the GPU (their lists
/// overflowing, so they would run again) is returned as it is, after they finish, and leaves
/// nothing behind that changes the next run.
#[test]
fn an_error_with_views_in_flight_is_returned_and_changes_nothing_after() {
    let gpu = gpu();
    let (g, cams, labels) = scene_and_views(11, 6);
    let cfg = flashsplat_overflowing(semsplat::fuse::LANES);
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let failing = FailingAt(4, labels.clone());
    let err = accumulate(gpu, &scene, &cams, &failing, CLASSES, &cfg, |_, _| {})
        .map(|_| ())
        .unwrap_err();
    assert!(
        format!("{err:#}").contains("label map of view b is corrupt"),
        "{err:#}"
    );
    let after = run(&g, &cams, &labels, &cfg);
    let fresh = run(
        &g,
        &cams,
        &labels,
        &FuseConfig {
            split: SplitSizes::default(),
            ..cfg
        },
    );
    assert_eq!(after.data, fresh.data);
    check_validation(gpu);
}

/// Label maps that load, and a stop asked for before one view's GPU work (Ctrl-C).
struct StopBefore(usize, Vec<Option<Vec<u32>>>);

impl LabelSource for StopBefore {
    fn labels(&self, view: usize, cam: &Camera) -> anyhow::Result<Option<Vec<u32>>> {
        self.1.labels(view, cam)
    }

    fn before_view(&self, view: usize) -> anyhow::Result<()> {
        anyhow::ensure!(view != self.0, "stopped before view {view}");
        Ok(())
    }
}

/// A stop asked for before a view ends the run there, whether or not the maps of later
/// views were read ahead (a large scene's few views were all read before the first one's
/// GPU work ended, and Ctrl-C, checked only as a map was read, went unheeded until every
/// view had run).
#[test]
fn a_stop_before_a_view_ends_the_run_there() {
    let gpu = gpu();
    let (g, cams, labels) = scene_and_views(15, 6);
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let cfg = FuseConfig {
        method: Method::FlashSplat,
        ..Default::default()
    };
    let stopping = StopBefore(2, labels);
    let mut reported = Vec::new();
    let progress = |done: usize, _: usize| reported.push(done);
    let err = accumulate(gpu, &scene, &cams, &stopping, CLASSES, &cfg, progress)
        .map(|_| ())
        .unwrap_err();
    assert!(
        format!("{err:#}").contains("stopped before view 2"),
        "{err:#}"
    );
    assert!(reported.iter().all(|&done| done <= 2), "{reported:?}");
    check_validation(gpu);
}

/// One view in flight, two (the default, where the device has room) or the most: the same
/// evidence, and the run says how many it kept.
#[test]
fn views_in_flight_change_nothing_but_the_overlap() {
    let gpu = gpu();
    let (g, cams, labels) = scene_and_views(13, 5);
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let run = |views_in_flight: usize| {
        let cfg = flashsplat_overflowing(views_in_flight);
        accumulate(gpu, &scene, &cams, &labels, CLASSES, &cfg, |_, _| {}).unwrap()
    };
    let (one, one_stats) = run(1);
    let (two, two_stats) = run(semsplat::fuse::LANES);
    let (most, most_stats) = run(semsplat::fuse::MAX_LANES);
    assert_eq!(one_stats.views_in_flight, 1);
    assert_eq!(two_stats.views_in_flight, 2, "lavapipe has room for two");
    assert_eq!(most_stats.views_in_flight, 4, "and for four");
    assert!(one.data.iter().any(|&v| v > 0.0));
    assert_eq!(one.data, two.data);
    assert_eq!(one.data, most.data);
    check_validation(gpu);
}

/// A device without 64-bit integer atomics: fixed-point fusion (the default) is refused
/// with an error that names the way out, and float atomics fuse as on any device.
#[test]
fn fixed_point_without_int64_atomics_is_a_clear_error() {
    let gpu = common::gpu_without_int64_atomics(true);
    let g = scene(300, 23);
    let cams = cameras();
    let labels = label_maps(&cams, 24);
    let scene = GpuScene::upload(gpu, &g).unwrap();
    let cfg = FuseConfig {
        method: Method::FlashSplat,
        ..Default::default()
    };
    assert_eq!(cfg.accumulation, Accumulation::FixedPoint);
    let err = accumulate(gpu, &scene, &cams, &labels, CLASSES, &cfg, |_, _| {})
        .expect_err("fixed point needs 64-bit atomics")
        .to_string();
    assert!(
        err.contains("64-bit integer atomics") && err.contains("float atomics"),
        "{err}"
    );
    let cfg = FuseConfig {
        accumulation: Accumulation::Float,
        ..cfg
    };
    let float = run_on(gpu, &g, &cams, &labels, &cfg);
    let want = run_on(common::gpu_with_cpu_forms(true), &g, &cams, &labels, &cfg);
    let top = want.data.iter().fold(0.0f64, |m, &v| m.max(v));
    assert!(top > 0.0, "no evidence");
    for (i, (a, b)) in float.data.iter().zip(&want.data).enumerate() {
        assert!((a - b).abs() <= 1e-5 * top, "entry {i}: {a} against {b}");
    }
    check_validation(gpu);
}
