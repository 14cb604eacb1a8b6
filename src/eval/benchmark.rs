//! Runs lifting methods on a synthetic scene with exact truth and scores them: fuse on the
//! train views (true or noisy labels), render labels of the held-out test views from the
//! lifted scene (2D mIoU and pixel accuracy against the true maps), and compare every
//! Gaussian's class with its true class (3D accuracy). Behind `semsplat demo` and `sweep`.

use std::time::Instant;

use anyhow::{ensure, Result};
use serde::Serialize;

use super::label_render::LabelRenderer;
use super::metrics::{gaussian_accuracy, ClassIou, Confusion};
use crate::fuse::{accumulate, assign_semantic, FuseConfig, Method, NO_LABEL};
use crate::gpu::Gpu;
use crate::render::GpuScene;
use crate::scene::classes::CompactClasses;
use crate::scene::labels::LabelMap;
use crate::scene::synth::SynthScene;
use crate::scene::{Camera, Split};
use crate::train::loss::IGNORE_LABEL;
use crate::train::views::TrainView;

/// The name a method goes by in tables and charts.
pub fn method_name(m: Method) -> &'static str {
    match m {
        Method::Vote => "vote",
        Method::VoteOcclusion => "vote --occlusion",
        Method::VoteWeighted => "vote --weighted",
        Method::FlashSplat => "flashsplat",
    }
}

pub const ALL_METHODS: [Method; 4] = [
    Method::Vote,
    Method::VoteOcclusion,
    Method::VoteWeighted,
    Method::FlashSplat,
];

#[derive(Clone, Debug, Serialize)]
pub struct MethodScore {
    pub method: &'static str,
    /// Wall time of lifting (upload, all views, assignment).
    pub seconds: f64,
    /// 2D, on the held-out views: mean IoU over the classes present there.
    pub miou: f64,
    pub pixel_accuracy: f64,
    /// 3D: fraction of Gaussians given their true class (unseen counts as wrong).
    pub gaussian_accuracy: f64,
    pub peak_device_bytes: u64,
    pub per_class: Vec<ClassIou>,
    /// User class id per Gaussian (-1: unseen), for strips and further analysis.
    #[serde(skip)]
    pub classes: Vec<i32>,
    /// The winning class's share of each Gaussian's evidence.
    #[serde(skip)]
    pub confidence: Vec<f32>,
}

/// How a method treated one consistently mislabeled object (paper 000's limitation: a
/// majority of wrong views wins), and whether its confidence flags it.
#[derive(Clone, Debug, Serialize)]
pub struct MislabelFollow {
    pub object: String,
    pub true_class: String,
    pub wrong_class: String,
    /// Fraction of the train views that showed the object with the wrong class.
    pub wrong_view_rate: f64,
    /// Fraction of the object's Gaussians assigned the wrong class.
    pub assigned_wrong: f64,
    /// Mean confidence on the object's Gaussians, and on every other seen Gaussian.
    pub confidence_on_object: f64,
    pub confidence_elsewhere: f64,
}

/// For every consistently mislabeled object of the scene's noise: what `score` assigned.
pub fn mislabel_follow(s: &SynthScene, score: &MethodScore) -> Vec<MislabelFollow> {
    let (Some(noisy), Some(instances)) = (&s.noisy, &s.gaussians.instance_ids) else {
        return Vec::new();
    };
    noisy
        .report
        .consistent
        .iter()
        .map(|m| {
            let on_object = |i: usize| instances[i] == m.instance as i32;
            let mean = |sel: &dyn Fn(usize) -> bool| {
                let v: Vec<f64> = (0..instances.len())
                    .filter(|&i| sel(i) && score.classes[i] >= 0)
                    .map(|i| score.confidence[i] as f64)
                    .collect();
                v.iter().sum::<f64>() / v.len().max(1) as f64
            };
            let members: Vec<usize> = (0..instances.len()).filter(|&i| on_object(i)).collect();
            let wrong = members
                .iter()
                .filter(|&&i| score.classes[i] == m.wrong_class as i32)
                .count();
            MislabelFollow {
                object: m.instance_name.clone(),
                true_class: m.true_class_name.clone(),
                wrong_class: m.wrong_class_name.clone(),
                wrong_view_rate: m.rate,
                assigned_wrong: wrong as f64 / members.len().max(1) as f64,
                confidence_on_object: mean(&on_object),
                confidence_elsewhere: mean(&|i| !on_object(i)),
            }
        })
        .collect()
}

/// Which train labels the methods see.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrainLabels {
    True,
    Noisy,
}

/// The train-view label maps (compact classes) the methods fuse.
fn train_labels(
    s: &SynthScene,
    which: TrainLabels,
    compact: &CompactClasses,
) -> Result<Vec<Option<Vec<u32>>>> {
    if which == TrainLabels::Noisy {
        ensure!(
            s.noisy.is_some(),
            "the scene was generated without label noise"
        );
    }
    Ok(s.cameras
        .iter()
        .enumerate()
        .map(|(i, cam)| {
            (cam.split == Split::Train).then(|| {
                let map: &[u16] = match (which, &s.noisy) {
                    (TrainLabels::Noisy, Some(n)) => &n.maps[i],
                    _ => &s.views[i].labels,
                };
                map.iter()
                    .map(|&l| {
                        if l == LabelMap::IGNORE {
                            NO_LABEL
                        } else {
                            compact.compact_of(l as u32).map_or(NO_LABEL, u32::from)
                        }
                    })
                    .collect()
            })
        })
        .collect())
}

/// The scene's train views as training input: ray-cast images and the chosen label maps
/// (compact classes).
pub fn synth_train_views(
    s: &SynthScene,
    which: TrainLabels,
    compact: &CompactClasses,
) -> Result<Vec<TrainView>> {
    let labels = train_labels(s, which, compact)?;
    Ok(s.cameras
        .iter()
        .zip(&s.views)
        .zip(labels)
        .filter_map(|((cam, view), labels)| {
            labels.map(|labels| TrainView {
                camera: cam.clone(),
                rgb: view.rgb.iter().map(|&v| v as f32 / 255.0).collect(),
                labels: labels
                    .into_iter()
                    .map(|l| if l == NO_LABEL { IGNORE_LABEL } else { l })
                    .collect(),
            })
        })
        .collect())
}

/// Lifts the scene's labels with each method and scores it.
pub fn score_methods(
    gpu: &Gpu,
    s: &SynthScene,
    which: TrainLabels,
    methods: &[Method],
    mut progress: impl FnMut(&str),
) -> Result<Vec<MethodScore>> {
    let truth = s.gaussians.class_ids.clone().unwrap_or_default();
    let compact = CompactClasses::from_table(&s.room.classes)?;
    let labels = train_labels(s, which, &compact)?;
    let test: Vec<(usize, &Camera)> = s
        .cameras
        .iter()
        .enumerate()
        .filter(|(_, c)| c.split == Split::Test)
        .collect();
    ensure!(
        !test.is_empty(),
        "the scene has no held-out test views to evaluate on"
    );
    let mut out = Vec::new();
    for &method in methods {
        progress(method_name(method));
        let start = Instant::now();
        let scene = GpuScene::upload(gpu, &s.gaussians)?;
        let cfg = FuseConfig {
            method,
            ..Default::default()
        };
        let (evidence, stats) = accumulate(
            gpu,
            &scene,
            &s.cameras,
            &labels,
            compact.len(),
            &cfg,
            |_, _| {},
        )?;
        let assignment = assign_semantic(&evidence);
        let classes: Vec<i32> = assignment
            .class
            .iter()
            .map(|c| {
                c.and_then(|e| compact.user_of(e))
                    .map_or(-1, |id| id as i32)
            })
            .collect();
        let seconds = start.elapsed().as_secs_f64();

        let mut confusion = Confusion::default();
        let mut renderer = LabelRenderer::new(gpu, &s.gaussians, &classes)?;
        for &(i, cam) in &test {
            confusion.add(&s.views[i].labels, &renderer.render(cam)?, LabelMap::IGNORE);
        }
        let seg = confusion.scores();
        out.push(MethodScore {
            method: method_name(method),
            seconds,
            miou: seg.miou,
            pixel_accuracy: seg.pixel_accuracy,
            gaussian_accuracy: gaussian_accuracy(&classes, &truth),
            peak_device_bytes: stats.peak_device_bytes,
            per_class: seg.per_class,
            classes,
            confidence: assignment.confidence,
        });
    }
    Ok(out)
}
