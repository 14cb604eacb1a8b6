//! Segment consensus (`--method segment-consensus`): lifting robust to per-view label noise.
//! Per view, the GPU finds the pixel under every Gaussian's visible center (occlusion-checked
//! against the rendered depth, as `vote --occlusion`); the host reads that pixel's label and
//! connected label region. Neighbouring Gaussians that share a region in the views that see
//! both form 3D segments; each segment's class is voted with every view counting once, and
//! each Gaussian takes its segment's class (docs/robustness.md).

use anyhow::{ensure, Result};

use super::accumulate::{
    center_params, check_map_size, FuseConfig, FuseStats, LabelSource, NO_LABEL,
};
use super::consensus_cluster::cluster_segments;
use super::consensus_decide::{decide, Consensus, ConsensusParams};
use super::consensus_segments::{label_regions, nearest_neighbours, region_edges, Observations};
use super::scores::ClassScores;
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, Recorder};
use crate::render::{GpuScene, Rasterizer};
use crate::scene::Camera;

/// Lifts the labels of `cams` by segment consensus. `means` are the scene's centers (the
/// host builds the neighbour graph from them).
#[allow(clippy::too_many_arguments)]
pub fn fuse_consensus(
    gpu: &Gpu,
    scene: &GpuScene,
    means: &[[f32; 3]],
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
    params: &ConsensusParams,
) -> Result<(Consensus, FuseStats)> {
    let start = std::time::Instant::now();
    ensure!(
        means.len() == scene.n as usize,
        "{} centers for a scene of {} Gaussians",
        means.len(),
        scene.n
    );
    let (obs, mut stats) = observe(gpu, scene, cams, labels, classes, cfg, params.occlusion)?;
    let knn = nearest_neighbours(means, params.neighbours);
    let segment = cluster_segments(&obs, &knn, params);
    let consensus = decide(&obs, &knn, segment, classes, params);
    stats.wall_s = start.elapsed().as_secs_f64();
    stats.views_per_s = stats.views as f64 / stats.wall_s.max(1e-9);
    Ok((consensus, stats))
}

/// Segment consensus as an evidence matrix, for the callers of [`super::accumulate`] (`fuse`
/// and `bench fuse`, through `accumulate_assigned`, which assigns it on the host): each Gaussian's column holds the counts its class was decided from (its
/// segment's vote split, or its own views), so the argmax is that class except in exact ties.
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
    let (consensus, stats) =
        fuse_consensus(gpu, scene, &means, cams, labels, classes, cfg, &params)?;
    let mut scores = ClassScores::zeros(classes, n);
    for (g, counts) in consensus.evidence.iter().enumerate() {
        for (c, &v) in counts.iter().enumerate() {
            scores.data[c * n + g] = v;
        }
    }
    Ok((scores, stats))
}

/// Every view's observations of every Gaussian: label and region under its center (with
/// `occlusion`, only where the center is within the depth tolerance of the rendered depth).
pub fn observe(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
    occlusion: bool,
) -> Result<(Observations, FuseStats)> {
    let n = scene.n as usize;
    let mut stats = FuseStats {
        views: cams.len(),
        passes: 1,
        rows_per_pass: classes,
        ..Default::default()
    };
    let pixels_buf = gpu.buffer("center-pixels", (n.max(1) * 4) as u64)?;
    let mut raster = Rasterizer::new(gpu);
    raster.set_split_sizes(cfg.split);
    let mut per_view = Vec::with_capacity(cams.len());
    for (view, cam) in cams.iter().enumerate() {
        let Some(map) = labels.labels(view, cam)? else {
            per_view.push(Vec::new());
            continue;
        };
        check_map_size(cam, &map)?;
        ensure!(
            map.iter().all(|&l| l == NO_LABEL || (l as usize) < classes),
            "labels of view {} hold a class outside the {classes} classes",
            cam.name
        );
        stats.views_with_labels += 1;
        stats.gpu_ms += center_pixels(&mut raster, scene, cam, &pixels_buf, cfg, occlusion)?;
        stats.peak_device_bytes = stats.peak_device_bytes.max(gpu.memory_reserved());
        let centers: Vec<u32> = gpu.download(&pixels_buf, 0, n)?;
        let regions = label_regions(&map, cam.width as usize);
        let edges = region_edges(&regions, cam.width as usize);
        per_view.push(
            centers
                .iter()
                .enumerate()
                .filter(|&(_, &p)| p != NO_LABEL && map[p as usize] != NO_LABEL)
                .map(|(g, &p)| {
                    let p = p as usize;
                    (g as u32, map[p], regions[p], edges[p])
                })
                .collect(),
        );
    }
    Ok((Observations::from_views(n, &per_view), stats))
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
    let run = raster.run_tiled_in_bands(scene, cam, &cfg.render_options(), |rec, tiles| {
        tiles.record_blend(rec)?;
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
