//! Label maps rendered from classified Gaussians (`eval`, `fuse --render-views`, `render
//! --semantics` on a fused scene): the GPU's running argmax over one-hot classes equals the
//! argmax of the full one-hot semantic render, and needs no per-class memory, so a million
//! Gaussians with 300 classes render.

mod common;

use common::{check_validation, gpu, separate_depth_ties};
use glam::DVec3;
use semsplat::eval::label_render::LabelRenderer;
use semsplat::render::{GpuScene, Rasterizer, RenderOptions, SemanticMode};
use semsplat::scene::random_scene::{random_scene, RandomSceneSpec};
use semsplat::scene::{Camera, Gaussians, SemanticLogits};
use semsplat::util::Rng;

fn camera(w: u32, h: u32) -> Camera {
    Camera::look_at(
        "front",
        DVec3::ZERO,
        DVec3::new(0.0, 0.0, 5.0),
        -DVec3::Y,
        w,
        h,
        70.0,
    )
}

/// Random user class ids among `ids` (a tenth unclassified, -1).
fn random_classes(n: usize, ids: &[i32], seed: u64) -> Vec<i32> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            if rng.bool(0.1) {
                -1
            } else {
                ids[rng.below(ids.len() as u64) as usize]
            }
        })
        .collect()
}

/// The labels the plain way: every Gaussian carries its one-hot vector over the sorted
/// ids, all channels are rendered, and each pixel takes the last largest normalized share
/// (None where it is 0).
fn one_hot_labels(g: &Gaussians, class_ids: &[i32], cam: &Camera) -> Vec<Option<u32>> {
    let mut ids: Vec<i32> = class_ids.iter().copied().filter(|&c| c >= 0).collect();
    ids.sort_unstable();
    ids.dedup();
    let c = ids.len();
    let mut logits = vec![0.0f32; g.len() * c];
    for (i, id) in class_ids.iter().enumerate() {
        if let Ok(k) = ids.binary_search(id) {
            logits[i * c + k] = 1.0;
        }
    }
    let mut scene = g.clone();
    scene.semantics = Some(SemanticLogits {
        channels: c,
        logits,
    });
    let gpu_scene = GpuScene::upload(gpu(), &scene).unwrap();
    let opts = RenderOptions {
        semantics: Some(SemanticMode::RawLogits),
        ..Default::default()
    };
    let f = Rasterizer::new(gpu())
        .render(&gpu_scene, cam, &opts)
        .unwrap();
    f.sem_norm
        .chunks(c)
        .map(|s| {
            let (k, &v) = s.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
            (v > 0.0).then_some(ids[k] as u32)
        })
        .collect()
}

#[test]
fn label_renders_equal_the_argmax_of_one_hot_semantics() {
    // 40 classes: three chunks of 16, so the argmax is carried between dispatches.
    let cam = camera(96, 72);
    let g = separate_depth_ties(
        &random_scene(&RandomSceneSpec {
            n: 3_000,
            seed: 41,
            ..Default::default()
        }),
        &cam,
    );
    let ids: Vec<i32> = (0..40).map(|k| 7 + 3 * k).collect();
    let classes = random_classes(g.len(), &ids, 43);
    let want = one_hot_labels(&g, &classes, &cam);
    let labelled = want.iter().filter(|l| l.is_some()).count();
    assert!(labelled > want.len() / 2, "{labelled} labelled pixels");
    // Both forms of the per-tile kernels: one pixel an invocation and several (`*_wide`).
    for wide in [false, true] {
        let gpu = common::gpu_with_cpu_forms(wide);
        let got = LabelRenderer::new(gpu, &g, &classes)
            .unwrap()
            .render_ids(&cam)
            .unwrap();
        assert_eq!(got, want, "wide tiles {wide}");
        check_validation(gpu);
    }
    check_validation(gpu());
}

#[test]
fn a_million_gaussians_with_300_classes_render_labels() {
    // One-hot vectors would take 1.2 GB (over any binding); class indices take 4 MB. Every
    // 1,000th Gaussian is in view and the rest behind the camera, so the in-view subset
    // rendered the plain way (300 channels of 1,000 Gaussians) gives the expected labels.
    let cam = camera(64, 48);
    let n = 1_000_000;
    let mut g = random_scene(&RandomSceneSpec {
        n,
        seed: 47,
        ..Default::default()
    });
    let behind: Vec<bool> = (0..n).map(|i| i % 1_000 != 0).collect();
    for (m, &b) in g.means.iter_mut().zip(&behind) {
        if b {
            m[2] = -m[2].abs() - 1.0;
        }
    }
    // Near-ties in depth separated among the Gaussians in view, in both scenes alike.
    let keep: Vec<bool> = behind.iter().map(|b| !b).collect();
    let subset = separate_depth_ties(&g.select(&keep), &cam);
    for (k, i) in (0..n).step_by(1_000).enumerate() {
        g.means[i] = subset.means[k];
    }
    let ids: Vec<i32> = (0..300).collect();
    let classes = random_classes(n, &ids, 53);
    let got = LabelRenderer::new(gpu(), &g, &classes)
        .unwrap()
        .render_ids(&cam)
        .unwrap();
    let subset_classes: Vec<i32> = (0..n).step_by(1_000).map(|i| classes[i]).collect();
    let want = one_hot_labels(&subset, &subset_classes, &cam);
    assert!(want.iter().filter(|l| l.is_some()).count() > 100);
    assert_eq!(got, want);
    check_validation(gpu());
}
