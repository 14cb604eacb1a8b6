//! `fuse --method segment-consensus [--relabel]`: the consensus methods decide from every
//! view at once and give more than classes: each Gaussian's entropy and segment (PLY
//! properties `class_entropy`, `segment`), and the segments whose views disagree (the
//! report's `segments`).

use anyhow::Result;

use super::fuse::Evidence;
use super::progress::{follow, views_bar};
use super::Interruptible;
use semsplat::dataset::Dataset;
use semsplat::fuse::consensus_report::{segment_report, SegmentReport};
use semsplat::fuse::{
    lift_by_consensus, ConsensusInput, ConsensusParams, FuseConfig, GaussianShapes, Method,
};
use semsplat::gpu::Gpu;
use semsplat::render::GpuScene;
use semsplat::scene::Gaussians;

/// What the consensus methods add to a fused scene and its report.
pub(super) struct ConsensusOutputs {
    /// Entropy (nats) of each Gaussian's class posterior.
    pub entropy: Vec<f32>,
    /// Segment per Gaussian.
    pub segment: Vec<i32>,
    pub report: SegmentReport,
}

impl ConsensusOutputs {
    /// Puts the entropy and segments on the Gaussians (written as PLY properties).
    pub fn annotate(self, g: &mut Gaussians) -> SegmentReport {
        g.class_entropy = Some(self.entropy);
        g.segment_ids = Some(self.segment);
        self.report
    }
}

/// Fuses `data` onto `g` by the consensus method of `cfg`.
pub(super) fn fuse_by_consensus(
    g: &Gaussians,
    data: Dataset,
    cfg: &FuseConfig,
) -> Result<Evidence> {
    let gpu = Gpu::new()?;
    let scene = GpuScene::upload_for(&gpu, g, cfg.method.scene_attributes())?;
    let params = ConsensusParams::of(cfg);
    // The relabeled method visits every view twice (the second time its labels, or a walk
    // where its footprints were not kept): the bar counts visits.
    let visits = if cfg.method == Method::SegmentConsensusRelabel {
        2
    } else {
        1
    };
    let bar = views_bar(visits * data.cameras.len());
    let track = follow(&bar);
    let input = ConsensusInput {
        gpu: &gpu,
        scene: &scene,
        shapes: GaussianShapes::of(g),
        cams: &data.cameras,
        labels: &Interruptible(&data),
        classes: data.classes.len(),
    };
    let views = data.cameras.len();
    let mut observed_all = false;
    let lift = lift_by_consensus(&input, cfg, &params, &mut |done, total| {
        track(done, total);
        // Once every view is observed the segments are clustered and decided: seconds on a
        // million Gaussians with no view to count, so the bar says what it waits for until
        // the next report (`--relabel`'s second visit starts at `views` too).
        let clustering = done >= views && !observed_all;
        observed_all |= done >= views;
        bar.set_message(if clustering {
            "clustering segments"
        } else {
            ""
        });
    })?;
    bar.finish_and_clear();
    let names: Vec<String> = data.table.classes.iter().map(|c| c.name.clone()).collect();
    let cameras: Vec<String> = data.cameras.iter().map(|c| c.name.clone()).collect();
    let outputs = ConsensusOutputs {
        entropy: lift.consensus.entropy.clone(),
        segment: lift.consensus.segment.iter().map(|&s| s as i32).collect(),
        report: segment_report(
            &lift.consensus,
            &names,
            &cameras,
            &g.means,
            params.min_segment,
        ),
    };
    Ok(Evidence {
        assignment: lift.assignment,
        rows: Some(Box::new(lift.evidence)),
        table: data.table,
        stats: Some(lift.stats),
        consensus: Some(outputs),
    })
}
