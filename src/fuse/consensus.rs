//! Segment consensus (`--method segment-consensus`): lifting robust to per-view label noise.
//! Per view, the GPU finds the pixel under every Gaussian's visible center (occlusion-checked
//! against the rendered median depth); the host reads that pixel's label and
//! connected label region. Neighbouring Gaussians that share a region in the views that see
//! both form 3D segments; each segment's class is voted with every view counting once, and
//! each Gaussian takes its segment's class (docs/robustness.md).

use std::sync::Arc;

use anyhow::{ensure, Result};

use super::accumulate::{
    center_params, check_map_size, FuseConfig, FuseStats, LabelSource, LABELS_AHEAD, LABEL_THREADS,
    NO_LABEL,
};
use super::assign::Assignment;
use super::consensus_cluster::cluster_segments;
use super::consensus_decide::{decide, Consensus, ConsensusParams};
use super::consensus_relabel::fuse_relabeled;
use super::consensus_segments::{nearest_neighbours, Observations, ViewEntry};
use super::method::Method;
use super::regions_gpu::RegionFinder;
use super::scores::{ClassScores, EvidenceRows, SharedCounts};
use crate::contract::REGION_EDGE_BIT;
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, Recorder};
use crate::render::{GpuScene, Rasterizer};
use crate::scene::Camera;
use crate::util::{parallel_map, prefetch_ordered, split_parts, take_part};

/// What a consensus method lifts: the scene on the GPU and its centers (the host builds the
/// neighbour graph from them), the cameras and their label maps in compact class ids.
#[derive(Clone, Copy)]
pub struct ConsensusInput<'a> {
    pub gpu: &'a Gpu,
    pub scene: &'a GpuScene,
    pub means: &'a [[f32; 3]],
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
    let run = consensus_run(input, cfg, params, &mut |_, _| {})?;
    Ok((run.consensus, run.stats))
}

/// A segment consensus run and what it was decided from.
pub struct ConsensusRun {
    pub consensus: Consensus,
    pub observations: Observations,
    /// Per view, (Gaussian, pixel under its center) of every observation.
    pub centers: Vec<Vec<(u32, u32)>>,
    /// [n][params.neighbours] nearest neighbours.
    pub knn: Vec<u32>,
    pub stats: FuseStats,
}

/// [`fuse_consensus`], keeping the observations and the neighbour graph; `progress` gets
/// (views observed, views).
pub fn consensus_run(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    params: &ConsensusParams,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ConsensusRun> {
    let start = std::time::Instant::now();
    ensure!(
        input.means.len() == input.scene.n as usize,
        "{} centers for a scene of {} Gaussians",
        input.means.len(),
        input.scene.n
    );
    let (observations, centers, mut stats) = observe(input, cfg, params.occlusion, progress)?;
    stats.view_s = start.elapsed().as_secs_f64();
    let knn = nearest_neighbours(input.means, params.neighbours);
    let segment = cluster_segments(&observations, &knn, params);
    stats.segments_s = start.elapsed().as_secs_f64() - stats.view_s;
    let decide_start = std::time::Instant::now();
    let consensus = decide(&observations, &knn, segment, input.classes, params);
    stats.decide_s = decide_start.elapsed().as_secs_f64();
    stats.wall_s = start.elapsed().as_secs_f64();
    stats.views_per_s = stats.views as f64 / stats.wall_s.max(1e-9);
    Ok(ConsensusRun {
        consensus,
        observations,
        centers,
        knn,
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
    pub evidence: LiftEvidence,
    pub stats: FuseStats,
}

/// A consensus lift's evidence per Gaussian.
#[derive(Clone, Debug, PartialEq)]
pub enum LiftEvidence {
    /// The consensus counts ([`Consensus::evidence`], shared).
    Consensus(Arc<SharedCounts>),
    /// `--relabel`: FlashSplat's over the relabeled views where it decided, else the
    /// consensus counts; most Gaussians hold a column of their own.
    Relabeled(ClassScores),
}

impl LiftEvidence {
    /// As a matrix [classes][n].
    pub fn into_scores(self) -> ClassScores {
        match self {
            LiftEvidence::Consensus(counts) => counts.to_scores(),
            LiftEvidence::Relabeled(scores) => scores,
        }
    }

    /// Read a class row at a time (the consensus counts never as a whole matrix).
    pub fn into_rows(self) -> Box<dyn EvidenceRows> {
        match self {
            LiftEvidence::Consensus(counts) => Box::new(counts),
            LiftEvidence::Relabeled(scores) => Box::new(scores),
        }
    }
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
    let run = consensus_run(input, cfg, params, progress)?;
    let evidence = LiftEvidence::Consensus(Arc::clone(&run.consensus.evidence));
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
    let flat: Vec<f32> = gpu.download(&scene.params.means, 0, 3 * n)?;
    let means: Vec<[f32; 3]> = flat.chunks_exact(3).map(|m| [m[0], m[1], m[2]]).collect();
    let params = ConsensusParams::default();
    let input = ConsensusInput {
        gpu,
        scene,
        means: &means,
        cams,
        labels,
        classes,
    };
    let lift = lift_by_consensus(&input, cfg, &params, &mut |_, _| {})?;
    Ok((lift.evidence.into_scores(), lift.stats))
}

/// Every view's observations of every Gaussian: label and region under its center (with
/// `occlusion`, only where the center is within the depth tolerance of the rendered median
/// depth), and per view the (Gaussian, pixel) of each observation.
#[allow(clippy::type_complexity)]
pub fn observe(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    occlusion: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Observations, Vec<Vec<(u32, u32)>>, FuseStats)> {
    let ConsensusInput {
        gpu,
        scene,
        cams,
        labels,
        classes,
        ..
    } = *input;
    let n = scene.n as usize;
    let mut stats = FuseStats {
        views: cams.len(),
        passes: 1,
        rows_per_pass: classes,
        ..Default::default()
    };
    let pixels_buf = gpu.buffer("center-pixels", (n.max(1) * 4) as u64)?;
    let mut finder = RegionFinder::new(gpu, n)?;
    let mut raster = Rasterizer::new(gpu);
    raster.set_split_sizes(cfg.split);
    let mut per_view = Vec::with_capacity(cams.len());
    let mut pixels = Vec::with_capacity(cams.len());
    // Label maps are read (decoded) and checked on worker threads a few views ahead, as
    // the FlashSplat pass does, instead of in turn between the views' GPU work.
    let read = |view: usize| -> Result<Option<Vec<u32>>> {
        let (cam, map) = (&cams[view], labels.labels(view, &cams[view])?);
        if let Some(map) = &map {
            check_map_size(cam, map)?;
            ensure!(
                map.iter().all(|&l| l == NO_LABEL || (l as usize) < classes),
                "labels of view {} hold a class outside the {classes} classes",
                cam.name
            );
        }
        Ok(map)
    };
    let mut waited_since = std::time::Instant::now();
    prefetch_ordered(
        cams.len(),
        LABEL_THREADS,
        LABELS_AHEAD,
        read,
        |view, map| {
            stats.label_wait_s += waited_since.elapsed().as_secs_f64();
            progress(view, cams.len());
            let Some(map) = map else {
                per_view.push(Vec::new());
                pixels.push(Vec::new());
                waited_since = std::time::Instant::now();
                return Ok(());
            };
            let cam = &cams[view];
            stats.views_with_labels += 1;
            let rendering = std::time::Instant::now();
            stats.gpu_ms += center_pixels(&mut raster, scene, cam, &pixels_buf, cfg, occlusion)?;
            stats.peak_device_bytes = stats.peak_device_bytes.max(gpu.memory_reserved());
            stats.observe.render_s += rendering.elapsed().as_secs_f64();
            let finding = std::time::Instant::now();
            let mut gather_s = 0.0;
            // Gathered straight from the readback (a million Gaussians' words, not copied).
            let (observed, seen) = finder.regions_with(&map, cam.width, &pixels_buf, |c, r| {
                let gathering = std::time::Instant::now();
                let gathered = view_observations(&map, c, r);
                gather_s = gathering.elapsed().as_secs_f64();
                gathered
            })?;
            stats.observe.regions_s += finding.elapsed().as_secs_f64() - gather_s;
            stats.observe.gather_s += gather_s;
            per_view.push(observed);
            pixels.push(seen);
            waited_since = std::time::Instant::now();
            Ok(())
        },
    )?;
    progress(cams.len(), cams.len());
    stats.gpu_ms += finder.stats.gpu_ms;
    stats.region_host_fallbacks = finder.stats.host_fallbacks;
    let gathering = std::time::Instant::now();
    let observations = Observations::from_views(n, &per_view);
    stats.observe.gather_s += gathering.elapsed().as_secs_f64();
    Ok((observations, pixels, stats))
}

/// One view's observations from its readback (per Gaussian, the pixel under its center and
/// that pixel's region, [`NO_LABEL`] where unobserved): (Gaussian, label, region, edge) and
/// (Gaussian, pixel), in Gaussian order. On every core, in blocks of Gaussians: each view
/// reads an entry for every Gaussian of the scene (a million, most unobserved). Each block's
/// observations are counted, then written into its part of the lists.
fn view_observations(
    map: &[u32],
    centers: &[u32],
    regions: &[u32],
) -> (Vec<ViewEntry>, Vec<(u32, u32)>) {
    const BLOCK: usize = 1 << 16;
    let block = |b: usize| b * BLOCK..regions.len().min((b + 1) * BLOCK);
    let blocks = regions.len().div_ceil(BLOCK);
    let counts = parallel_map(blocks, |b| {
        regions[block(b)].iter().filter(|&&r| r != NO_LABEL).count()
    });
    let total = counts.iter().sum();
    let (mut observed, mut seen) = (vec![(0, 0, 0, false); total], vec![(0, 0); total]);
    let observed_parts = split_parts(&mut observed, counts.iter().copied());
    let seen_parts = split_parts(&mut seen, counts);
    parallel_map(blocks, |b| {
        let (mut observed, mut seen) = (take_part(&observed_parts[b]), take_part(&seen_parts[b]));
        let mut at = 0;
        for g in block(b) {
            let (p, r) = (centers[g], regions[g]);
            if r != NO_LABEL {
                let (region, edge) = (r & !REGION_EDGE_BIT, r & REGION_EDGE_BIT != 0);
                observed[at] = (g as u32, map[p as usize], region, edge);
                seen[at] = (g as u32, p);
                at += 1;
            }
        }
    });
    drop((observed_parts, seen_parts));
    (observed, seen)
}

/// Writes the pixel under every Gaussian's visible center into `out`; returns GPU ms.
fn center_pixels(
    raster: &mut Rasterizer,
    scene: &GpuScene,
    cam: &Camera,
    out: &Buffer,
    cfg: &FuseConfig,
    occlusion: bool,
) -> Result<f64> {
    if !occlusion {
        let mut rec = Recorder::new(raster.gpu())?;
        let m0 = rec.mark();
        dispatch_center_pixels(&mut rec, scene, cam, None, out, cfg)?;
        let m1 = rec.mark();
        let t = rec.submit_and_wait()?;
        return Ok(t.between(m0, m1).unwrap_or(0.0) * 1e-6);
    }
    // The centers are looked up once the whole view's depth is rendered (every Gaussian's
    // entry is written, so a binning that overflowed and runs again leaves nothing behind).
    // The median depth, not the expected one `vote --occlusion` tests against: a pixel
    // stops at the surface in front instead of at saturation (a third of the consensus's
    // time on lavapipe), and on an object's silhouette it is the depth of one of the two
    // surfaces, not a blend that matches neither.
    let run = raster.run_tiled_in_bands(scene, cam, &cfg.render_options(), |rec, tiles| {
        tiles.record_median_depth(rec)?;
        if !tiles.is_last_band() {
            return Ok(());
        }
        rec.barrier();
        dispatch_center_pixels(rec, scene, cam, Some(tiles.depth()), out, cfg)
    })?;
    Ok(run.timings.total_ns() * 1e-6)
}

fn dispatch_center_pixels(
    rec: &mut Recorder,
    scene: &GpuScene,
    cam: &Camera,
    depth: Option<&Buffer>,
    out: &Buffer,
    cfg: &FuseConfig,
) -> Result<()> {
    // No class rows: the observations take every label.
    let params = center_params(
        cam,
        scene,
        cfg,
        depth.is_some(),
        (0, 0),
        out.address_words(4)?,
    )?;
    rec.dispatch(
        ids::FUSE_CENTER_PIXEL,
        &[
            // Never read without occlusion: any readable buffer fills the binding.
            ("depth", depth.unwrap_or(&scene.params.means)),
        ],
        &params,
        ids::FUSE_CENTER_PIXEL.groups_for(scene.n),
    )?;
    rec.barrier();
    Ok(())
}
