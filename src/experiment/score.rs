//! Runs lifting methods on a synthetic scene with exact truth and scores them: fuse on the
//! train views (true or noisy labels), render labels of the held-out test views from the
//! lifted scene (2D mIoU and pixel accuracy against the true maps), and compare every
//! Gaussian's class with its true class (3D accuracy).

use std::time::Instant;

use anyhow::{ensure, Result};
use serde::Serialize;

use super::lifter::{JointSchedule, Lifter};
use crate::dataset::{user_classes, CompactClasses};
use crate::eval::image_quality::{image_quality, ImageQuality};
use crate::eval::label_render::LabelRenderer;
use crate::eval::metrics::{gaussian_accuracy, ClassIou, Confusion, SegmentationScores};
use crate::fuse::{
    accumulate_assigned, lift_by_consensus, AssignOnGpu, Clustering, ConsensusInput,
    ConsensusParams, FuseConfig, GaussianShapes, SegmentVotes, TieNeighbours, TIE_NEIGHBOURS,
};
use crate::gpu::Gpu;
use crate::render::GpuScene;
use crate::scene::labels::LabelMap;
use crate::scene::Gaussians;
use crate::scene::{Camera, Split};
use crate::synth::SynthScene;
use crate::train::config::TrainConfig;
use crate::train::trainer::{classes_from_logits, with_initial_logits, LogitInit, Trainer};
use crate::train::views::TrainView;

#[derive(Clone, Debug, Serialize)]
pub struct MethodScore {
    /// The name in tables and charts ("vote --occlusion").
    pub method: &'static str,
    /// The name `--methods` takes ("vote-occlusion"; the oracle: "oracle").
    pub key: &'static str,
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
    /// The scene `classes` refer to when the method changed the Gaussians (joint full);
    /// None: the input scene.
    #[serde(skip)]
    pub lifted: Option<LiftedScene>,
    /// PSNR and SSIM of the held-out views rendered from the lifted scene, for methods that
    /// change appearance (joint).
    pub image_quality: Option<ImageQuality>,
    /// Segment consensus: its segments (vote split per class) and each Gaussian's segment.
    #[serde(skip)]
    pub segments: Option<(Vec<SegmentVotes>, Vec<u32>)>,
}

/// A scene a method rebuilt, with the truth carried through densification.
#[derive(Clone, Debug)]
pub struct LiftedScene {
    pub gaussians: Gaussians,
    /// True class and instance per Gaussian (-1: none).
    pub truth: Vec<i32>,
    pub instances: Vec<i32>,
}

impl MethodScore {
    /// The Gaussians `classes` label.
    pub fn scene<'a>(&'a self, input: &'a Gaussians) -> &'a Gaussians {
        self.lifted.as_ref().map_or(input, |l| &l.gaussians)
    }
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
                compact.compact_labels(map)
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
                rgb: view.rgb_unit(),
                labels,
            })
        })
        .collect())
}

/// Lifts the scene's labels with each method and scores it.
pub fn score_methods(
    gpu: &Gpu,
    s: &SynthScene,
    which: TrainLabels,
    methods: &[Lifter],
    joint: &JointSchedule,
    clustering: Clustering,
    mut progress: impl FnMut(&str),
) -> Result<Vec<MethodScore>> {
    let truth0 = s.gaussians.class_ids.clone().unwrap_or_default();
    let compact = CompactClasses::from_table(&s.room.classes)?;
    let labels = train_labels(s, which, &compact)?;
    ensure!(
        s.cameras.iter().any(|c| c.split == Split::Test),
        "the scene has no held-out test views to evaluate on"
    );
    let mut out = Vec::new();
    for &lifter in methods {
        progress(lifter.name());
        let start = Instant::now();
        let lifted = match lifter {
            Lifter::Fuse(method) => {
                let cfg = FuseConfig {
                    method,
                    clustering,
                    ..Default::default()
                };
                fuse_lifted(gpu, s, &cfg, &labels, &compact)?
            }
            Lifter::JointSemantics | Lifter::JointFull => {
                joint_lifted(gpu, s, which, lifter == Lifter::JointFull, joint, &compact)?
            }
        };
        let seconds = start.elapsed().as_secs_f64();
        if lifted.classes.iter().all(|&c| c < 0) {
            // `fuse` refuses such a run; here it is a score, and says so.
            eprintln!(
                "note: {} classified no Gaussian (every score of it here is 0)",
                lifter.name()
            );
        }
        let Lifted {
            classes,
            confidence,
            lifted,
            peak_device_bytes,
            segments,
        } = lifted;
        let scene = lifted.as_ref().map_or(&s.gaussians, |l| &l.gaussians);
        let truth = lifted.as_ref().map_or(&truth0, |l| &l.truth);

        let seg = held_out_segmentation(gpu, s, scene, &classes)?;
        let image_quality = match &lifted {
            Some(l) => Some(held_out_quality(gpu, s, &l.gaussians)?),
            None => None,
        };
        out.push(MethodScore {
            method: lifter.name(),
            key: lifter.key(),
            seconds,
            miou: seg.miou,
            pixel_accuracy: seg.pixel_accuracy,
            gaussian_accuracy: gaussian_accuracy(&classes, truth),
            peak_device_bytes,
            per_class: seg.per_class,
            classes,
            confidence,
            lifted,
            image_quality,
            segments,
        });
    }
    Ok(out)
}

/// Segmentation scores of `classes` (user ids per Gaussian of `scene`, -1: none) rendered
/// from the held-out views against their true label maps, classes named from the room.
pub fn held_out_segmentation(
    gpu: &Gpu,
    s: &SynthScene,
    scene: &Gaussians,
    classes: &[i32],
) -> Result<SegmentationScores> {
    let mut confusion = Confusion::default();
    let mut renderer = LabelRenderer::new(gpu, scene, classes)?;
    for (cam, view) in s.cameras.iter().zip(&s.views) {
        if cam.split == Split::Test {
            confusion.add(&view.labels, &renderer.render_ids(cam)?, LabelMap::IGNORE);
        }
    }
    let mut seg = confusion.scores();
    seg.name_classes(&s.room.classes);
    Ok(seg)
}

/// PSNR and SSIM of `g` rendered from the scene's held-out views against their images.
pub fn held_out_quality(gpu: &Gpu, s: &SynthScene, g: &Gaussians) -> Result<ImageQuality> {
    let test: Vec<usize> = (0..s.cameras.len())
        .filter(|&i| s.cameras[i].split == Split::Test)
        .collect();
    let images: Vec<Vec<f32>> = test.iter().map(|&i| s.views[i].rgb_unit()).collect();
    let pairs: Vec<(&Camera, &[f32])> = test
        .iter()
        .zip(&images)
        .map(|(&i, im)| (&s.cameras[i], im.as_slice()))
        .collect();
    image_quality(gpu, g, &pairs)
}

/// What a method produced: classes (user ids, -1 unseen) and confidences per Gaussian of
/// the scene it returns (None: the input scene, unchanged), and the truth for that scene
/// when its Gaussians differ from the input's.
struct Lifted {
    classes: Vec<i32>,
    confidence: Vec<f32>,
    lifted: Option<LiftedScene>,
    peak_device_bytes: u64,
    segments: Option<(Vec<SegmentVotes>, Vec<u32>)>,
}

fn fuse_lifted(
    gpu: &Gpu,
    s: &SynthScene,
    cfg: &FuseConfig,
    labels: &Vec<Option<Vec<u32>>>,
    compact: &CompactClasses,
) -> Result<Lifted> {
    let method = cfg.method;
    let scene = GpuScene::upload_for(gpu, &s.gaussians, method.scene_attributes())?;
    if method.is_consensus() {
        let input = ConsensusInput {
            gpu,
            scene: &scene,
            shapes: GaussianShapes::of(&s.gaussians),
            cams: &s.cameras,
            labels,
            classes: compact.len(),
        };
        let lift = lift_by_consensus(&input, cfg, &ConsensusParams::of(cfg), &mut |_, _| {})?;
        return Ok(Lifted {
            classes: user_classes(compact.user_ids(), lift.assignment.class.iter().copied()),
            confidence: lift.assignment.confidence,
            lifted: None,
            peak_device_bytes: lift.stats.peak_device_bytes,
            segments: Some((lift.consensus.segments, lift.consensus.segment)),
        });
    }
    // Ties go to the class the Gaussian's nearest neighbours hold most evidence for.
    let with = AssignOnGpu {
        knn: Some(TieNeighbours::Search(&s.gaussians.means, TIE_NEIGHBOURS)),
        rows: None,
    };
    let (assignment, stats) = accumulate_assigned(
        gpu,
        &scene,
        &s.cameras,
        labels,
        compact.len(),
        cfg,
        with,
        |_, _| {},
    )?;
    let classes = user_classes(compact.user_ids(), assignment.class.iter().copied());
    Ok(Lifted {
        classes,
        confidence: assignment.confidence,
        lifted: None,
        peak_device_bytes: stats.peak_device_bytes,
        segments: None,
    })
}

/// Joint optimization from the scene's Gaussians (the trained 3DGS every method gets),
/// its logits started as `train` starts them ([`LogitInit::default_for`]); full mode also
/// refines geometry and densifies.
fn joint_lifted(
    gpu: &Gpu,
    s: &SynthScene,
    which: TrainLabels,
    full: bool,
    schedule: &JointSchedule,
    compact: &CompactClasses,
) -> Result<Lifted> {
    let views = synth_train_views(s, which, compact)?;
    let start = LogitInit::default_for(!full);
    let init = with_initial_logits(&s.gaussians, compact.len(), start, s.config.seed);
    // Truth and instances ride along through densification (small integers, exact in f32).
    let rider = |v: &Option<Vec<i32>>| -> Vec<f32> {
        v.as_ref()
            .map(|c| c.iter().map(|&v| v as f32).collect())
            .unwrap_or_else(|| vec![-1.0; s.gaussians.len()])
    };
    let riders = [
        rider(&s.gaussians.class_ids),
        rider(&s.gaussians.instance_ids),
    ];
    let cfg = if full {
        let mut cfg = TrainConfig::new(schedule.full_iters);
        if let Some(d) = &mut cfg.densify {
            d.max_gaussians = (s.gaussians.len() as f64 * schedule.max_growth) as u32;
        }
        cfg
    } else {
        TrainConfig::semantics_only(schedule.semantics_only_iters)
    };
    let mut trainer = Trainer::new(gpu, &init, &views, cfg.clone(), &riders)?;
    for _ in 0..cfg.iters {
        trainer.step()?;
    }
    let out = trainer.finish()?;
    let (compact_classes, confidence) = classes_from_logits(&out.gaussians, &out.seen);
    let classes = user_classes(
        compact.user_ids(),
        compact_classes.iter().map(|c| c.map(|c| c as usize)),
    );
    let ints = |v: &[f32]| v.iter().map(|&v| v as i32).collect();
    Ok(Lifted {
        classes,
        confidence,
        lifted: Some(LiftedScene {
            truth: ints(&out.riders[0]),
            instances: ints(&out.riders[1]),
            gaussians: out.gaussians,
        }),
        peak_device_bytes: out.peak_device_bytes,
        segments: None,
    })
}
