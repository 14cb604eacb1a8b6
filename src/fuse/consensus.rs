//! Segment consensus (`--method segment-consensus`): lifting robust to per-view label noise.
//! Per view, the GPU finds the pixel under every Gaussian's visible center (occlusion-checked
//! against the rendered median depth), that pixel's label and connected label region, and
//! the host reads those of the observed Gaussians. Neighbouring Gaussians that share a
//! region in the views that see both form 3D segments; each segment's class is voted with
//! every view counting once, and each Gaussian takes its segment's class
//! (docs/robustness.md).

use std::sync::Arc;

use anyhow::{ensure, Result};

use super::accumulate::{FuseConfig, FuseStats, LabelSource};
use super::assign::Assignment;
use super::consensus_cluster::cluster_segments_timed;
use super::consensus_decide::{decide_timed, Consensus, ConsensusParams};
use super::consensus_footprints::ViewFootprints;
pub use super::consensus_observe::{observe, Kept, ViewsObserved};
use super::consensus_order::SpatialOrder;
use super::consensus_relabel::fuse_relabeled;
use super::consensus_segments::Observations;
use super::consensus_split::split_near_ties;
use super::consensus_surface::{GaussianShapes, SurfaceNormals};
use super::method::Method;
use super::neighbours::nearest_neighbours;
use super::scores::ClassScores;
use super::shared_counts::SharedCounts;
use crate::gpu::Gpu;
use crate::render::GpuScene;
use crate::scene::Camera;

/// What a consensus method lifts: the scene on the GPU and its shapes on the host (the
/// neighbour graph is built from the centers, the surfaces from the scales and rotations),
/// the cameras and their label maps in compact class ids.
#[derive(Clone, Copy)]
pub struct ConsensusInput<'a> {
    pub gpu: &'a Gpu,
    pub scene: &'a GpuScene,
    pub shapes: GaussianShapes<'a>,
    pub cams: &'a [Camera],
    pub labels: &'a dyn LabelSource,
    pub classes: usize,
}

/// Lifts the labels of `input` by segment consensus.
pub fn fuse_consensus(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    params: &ConsensusParams,
) -> Result<(Consensus, FuseStats)> {
    let run = consensus_run(input, cfg, params, Kept::Observations, &mut |_, _| {})?;
    Ok((run.consensus, run.stats))
}

/// A segment consensus run and what it was decided from.
pub struct ConsensusRun {
    pub consensus: Consensus,
    /// The Gaussians' observations, numbered by `order`.
    pub observations: Observations,
    /// Per view, (Gaussian, pixel under its center) of every observation (empty lists with
    /// [`Kept::Observations`]).
    pub centers: Vec<Vec<(u32, u32)>>,
    /// Per view, the footprints per label region with [`Kept::Footprints`] (else empty).
    pub footprints: Vec<ViewFootprints>,
    /// [n][params.neighbours] nearest neighbours, numbered by `order`
    /// ([`SpatialOrder::neighbours_to_scene`] gives them in the scene's numbering).
    pub knn: Vec<u32>,
    /// The numbering in space the Gaussians were observed, clustered and decided in;
    /// `consensus` and `centers` are in the scene's.
    pub order: SpatialOrder,
    pub stats: FuseStats,
}

/// [`fuse_consensus`], keeping the observations, the neighbour graph and what `kept` asks
/// for; `progress` gets (views observed, views).
pub fn consensus_run(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    params: &ConsensusParams,
    kept: Kept,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ConsensusRun> {
    let start = std::time::Instant::now();
    let shapes = &input.shapes;
    ensure!(
        [shapes.log_scales.len(), shapes.quats.len()] == [shapes.len(); 2]
            && shapes.len() == input.scene.n as usize,
        "{} centers, {} scales and {} rotations for a scene of {} Gaussians",
        shapes.len(),
        shapes.log_scales.len(),
        shapes.quats.len(),
        input.scene.n
    );
    // The host work numbers the Gaussians in space (consensus_order.rs): the observations
    // and the neighbour graph by that number, the results given back in the scene's.
    let order = SpatialOrder::of(shapes.means);
    let order_s = start.elapsed().as_secs_f64();
    let views_start = std::time::Instant::now();
    // The neighbour graph and the surfaces read only the shapes: found on the host while
    // the views keep the GPU busy, and waited for after them. `neighbours_s` is that wait.
    let (observed, found) = std::thread::scope(|scope| {
        let search = scope.spawn(|| {
            let knn = nearest_neighbours(&order.to_spatial(shapes.means), params.neighbours);
            (knn, SurfaceNormals::of(shapes, &order, params))
        });
        let observed = observe(input, cfg, params.occlusion, kept, Some(&order), progress);
        (observed, search.join())
    });
    let ViewsObserved {
        observations,
        centers,
        footprints,
        mut stats,
    } = observed?;
    stats.view_s = views_start.elapsed().as_secs_f64();
    let (knn, surfaces) = found.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
    let neighbours_s = views_start.elapsed().as_secs_f64() - stats.view_s;
    let clustered;
    (clustered, stats.clustering) = cluster_segments_timed(&observations, &knn, &surfaces, params);
    (stats.clustering.order_s, stats.clustering.neighbours_s) = (order_s, neighbours_s);
    let segment = split_near_ties(
        &observations,
        clustered,
        input.classes,
        params,
        &mut stats.clustering,
    );
    stats.segments_s = views_start.elapsed().as_secs_f64() - stats.view_s;
    let decide_start = std::time::Instant::now();
    let consensus;
    (consensus, stats.decision) = decide_timed(&observations, &knn, segment, input.classes, params);
    let consensus = order.consensus_to_scene(consensus);
    stats.decide_s = decide_start.elapsed().as_secs_f64();
    stats.finish(start);
    Ok(ConsensusRun {
        consensus,
        observations,
        centers,
        footprints,
        knn,
        order,
        stats,
    })
}

/// What a consensus method (`segment-consensus`, `segment-consensus --relabel`) gives.
pub struct ConsensusLift {
    /// Class per Gaussian, and as its confidence the posterior mean of that class under the
    /// view votes the consensus decided from ([`Consensus::evidence`]).
    pub assignment: Assignment,
    /// The segments, their vote splits and flags, and each Gaussian's entropy.
    pub consensus: Consensus,
    /// Per Gaussian, the evidence its class is the argmax of: what `--save-contrib` writes.
    /// The consensus counts ([`Consensus::evidence`], shared); with `--relabel`, FlashSplat's
    /// sums over the relabeled views where they decided, else the consensus counts.
    pub evidence: Arc<SharedCounts>,
    pub stats: FuseStats,
}

/// Lifts the labels by `cfg.method`, one of the consensus methods ([`Method::is_consensus`]);
/// `progress` gets (views done, views to do).
pub fn lift_by_consensus(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    params: &ConsensusParams,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ConsensusLift> {
    ensure!(
        cfg.method.is_consensus(),
        "{} is not a consensus method",
        cfg.method.name()
    );
    if cfg.method == Method::SegmentConsensusRelabel {
        return fuse_relabeled(input, cfg, params, progress);
    }
    let run = consensus_run(input, cfg, params, Kept::Observations, progress)?;
    let evidence = Arc::clone(&run.consensus.evidence);
    Ok(ConsensusLift {
        assignment: run.consensus.assignment.clone(),
        consensus: run.consensus,
        evidence,
        stats: run.stats,
    })
}

/// A consensus method as an evidence matrix, for the callers of [`super::accumulate`]
/// (`bench fuse`, through `accumulate_assigned`, which assigns it on the host): the argmax
/// of each column is the method's class except in exact ties.
pub fn consensus_evidence(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
) -> Result<(ClassScores, FuseStats)> {
    let n = scene.n as usize;
    let mut means: Vec<[f32; 3]> = gpu.download(&scene.params.means, 0, n)?;
    scene.means_to_world(&mut means);
    let log_scales: Vec<[f32; 3]> = gpu.download(&scene.params.log_scales, 0, n)?;
    let quats: Vec<[f32; 4]> = gpu.download(&scene.params.quats, 0, n)?;
    let params = ConsensusParams::of(cfg);
    let input = ConsensusInput {
        gpu,
        scene,
        shapes: GaussianShapes {
            means: &means,
            log_scales: &log_scales,
            quats: &quats,
        },
        cams,
        labels,
        classes,
    };
    let lift = lift_by_consensus(&input, cfg, &params, &mut |_, _| {})?;
    Ok((lift.evidence.to_scores(), lift.stats))
}
