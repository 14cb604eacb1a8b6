//! Gathers per-class evidence for every Gaussian on the GPU, view by view: votes of the
//! projected centers (Semantic Fusion, plus occlusion-checked and alpha*T-weighted variants) or
//! FlashSplat's contribution matrix A (docs/papers.md). Label maps stream one view at a time;
//! the evidence matrix stays dense while it fits the memory budget, else the classes are
//! processed in batches of rows (each batch walks every view again; results are the same).

use std::borrow::Cow;
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, ensure, Result};
use serde::Serialize;

use super::assign::{assign_semantic_near, Assignment};
use super::assign_gpu::GpuAssigner;
use super::consensus_cluster::ClusterProfile;
use super::consensus_decide::{Clustering, DecideProfile};
use super::method::Method;
use super::neighbours::nearest_neighbours;
use super::partial::{fixed_to_f64, EvidenceKind, RawEvidence};
use super::scores::ClassScores;
use super::shared_counts::SumsByGaussian;
use crate::contract::params::{CenterParams, ContribParams};
use crate::gpu::kernel_table::ids;
use crate::gpu::kernel_table::Kernel;
use crate::gpu::staging::grown;
use crate::gpu::timings::KernelTotal;
use crate::gpu::{Buffer, BufferRange, Gpu, Recorder, Timings};
use crate::render::rasterizer::{BandWork, OcclusionDepths, SplitSizes, TileLists};
use crate::render::{camera_rows_f32, GpuScene, Rasterizer, RenderOptions};
use crate::scene::Camera;
use crate::util::{prefetch_ordered, BusyTime};

/// Marks a pixel without a label (or with a class outside the table).
pub use crate::dataset::NO_LABEL;

/// How the weighted methods accumulate on the GPU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Accumulation {
    /// 64-bit fixed point (2^-32 resolution): identical from run to run.
    #[default]
    FixedPoint,
    /// float32 atomics: sums depend on the order of the atomics.
    Float,
}

#[derive(Clone, Debug)]
pub struct FuseConfig {
    pub method: Method,
    pub accumulation: Accumulation,
    /// Bytes the evidence matrix may take on the device; None: a quarter of the
    /// device-local memory, capped by the largest buffer a kernel can bind.
    pub mem_budget: Option<u64>,
    /// Relative depth tolerance of the visibility tests: `VoteOcclusion`'s against the
    /// expected depth, the consensus's against the median depth.
    pub depth_tolerance: f32,
    /// The consensus's visibility test also hides a center that lies behind the farthest
    /// opaque depth (where the transmittance falls below `OPAQUE_T`) of its pixel and the
    /// pixel's eight neighbours by more than this fraction of the median depth.
    pub behind_tolerance: f32,
    pub near: f32,
    pub far: f32,
    /// How finely views are split (windows of the tile lists, bands of tile rows); the
    /// device's sizes by default, small ones in tests so small scenes walk the split paths.
    pub split: SplitSizes,
    /// Views the tiled methods keep in flight at most (1..=[`MAX_LANES`], [`LANES`] by
    /// default); fewer where the device has no room for another view's buffers (see
    /// [`Lanes`]).
    pub views_in_flight: usize,
    /// Segment consensus's clustering.
    pub clustering: Clustering,
}

impl Default for FuseConfig {
    fn default() -> Self {
        FuseConfig {
            method: Method::FlashSplat,
            accumulation: Accumulation::FixedPoint,
            mem_budget: None,
            depth_tolerance: 0.05,
            behind_tolerance: 0.01,
            near: 0.01,
            far: 1e10,
            split: SplitSizes::default(),
            views_in_flight: LANES,
            clustering: Clustering::Order,
        }
    }
}

impl FuseConfig {
    /// How the tiled methods bin a view: RGB only, with this config's clip planes (also the
    /// forward render `bench fuse` compares against).
    pub fn render_options(&self) -> RenderOptions {
        RenderOptions {
            near: self.near,
            far: self.far,
            semantics: None,
            ..Default::default()
        }
    }
}

/// Gives the label map of a view as compact class indices per pixel ([`NO_LABEL`] where
/// unlabeled), or None when the view has no labels. Called once per view and pass, from
/// worker threads a few views ahead of the GPU (hence `Sync`).
pub trait LabelSource: Sync {
    fn labels(&self, view: usize, cam: &Camera) -> Result<Option<Vec<u32>>>;

    /// Called before each view's GPU work, on the thread that submits it; an error stops
    /// the run there. The maps are read ahead (every map of a few views of a large scene
    /// is read before the first view's GPU work ends), so a stop asked for in `labels`
    /// alone would come only after the views already read.
    fn before_view(&self, _view: usize) -> Result<()> {
        Ok(())
    }
}

impl LabelSource for Vec<Option<Vec<u32>>> {
    fn labels(&self, view: usize, _cam: &Camera) -> Result<Option<Vec<u32>>> {
        Ok(self.get(view).cloned().flatten())
    }
}

/// What a fusion run measured.
#[derive(Clone, Debug, Default, Serialize)]
pub struct FuseStats {
    pub views: usize,
    pub views_with_labels: usize,
    /// Passes over the views (1 when the evidence matrix fits the budget).
    pub passes: usize,
    /// Views the tiled methods and the consensus's observation pass had in flight at once
    /// (1 for the votes).
    pub views_in_flight: usize,
    pub rows_per_pass: usize,
    /// GPU time (timestamps): binning + per-tile stages, and the vote kernels.
    pub gpu_ms: f64,
    /// GPU time per kernel, over all views.
    pub kernels: Vec<KernelTotal>,
    pub wall_s: f64,
    /// Where the wall time went on the host: waiting for label maps (read and staged on
    /// worker threads), and running each view (uploading its labels, recording,
    /// submitting and waiting for its GPU work).
    pub label_wait_s: f64,
    pub view_s: f64,
    /// The worker threads' time reading (decoding and checking) the label maps, and, for
    /// the tiled methods, copying them into their staging buffers, summed over the
    /// threads: what `label_wait_s` waited for, where it is not the room ahead.
    pub label_read_s: f64,
    pub label_stage_s: f64,
    /// Setting up the evidence and, after each pass, assigning it on the GPU (or
    /// downloading and widening it for the host), streaming rows where asked.
    pub evidence_s: f64,
    /// Consensus methods: the host's neighbour search and clustering of the segments, and
    /// the segments' decision. Their `view_s` is the whole observation pass over the views
    /// (its label waits included; with `--relabel` plus FlashSplat's pass).
    pub segments_s: f64,
    pub decide_s: f64,
    /// Consensus methods: their observation pass split (`view_s` holds it all).
    pub observe: ObserveTimes,
    /// Consensus methods: `segments_s` split, with what the clustering did.
    pub clustering: ClusterProfile,
    /// Consensus methods: `decide_s` split.
    pub decision: DecideProfile,
    /// Views a second: each view once, however many passes over the views the evidence
    /// took (`passes`).
    pub views_per_s: f64,
    pub peak_device_bytes: u64,
    /// Device memory of the scene as this method uploaded it (only what it reads).
    pub scene_device_bytes: u64,
    /// Peak resident memory of the process so far (Linux; 0 where unknown).
    pub peak_host_bytes: u64,
    /// Segment consensus: views whose label regions the GPU left incomplete (a CPU
    /// driver's loop cap), found again on the host (src/fuse/regions_gpu.rs); with
    /// `--relabel`, also the views it relabeled on the host.
    pub region_host_fallbacks: usize,
    /// `--relabel`: views whose footprints the observation pass did not keep
    /// (src/fuse/consensus_footprints.rs), walked again by FlashSplat's pass.
    pub walked_again: usize,
}

/// Segment consensus's observation pass, split (host seconds, GPU waits included, summed
/// over its lanes: with two views in flight the parts overlap and add up to more than
/// `view_s`): each
/// view's median-depth render and center-pixel lookup; its label regions, with the label
/// map's upload and the readback of every center's pixel and region; and the host's
/// gathering of those into observations. On a GPU the pass is host-bound: on an H100, 22
/// ms a view against 3.2 ms of GPU time, 12 ms of it the gathering (since done on every
/// core: 12 ms a view in all, docs/gpu.md).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ObserveTimes {
    pub render_s: f64,
    pub regions_s: f64,
    pub gather_s: f64,
    /// GPU time of the label regions' kernels (the regions, each center's lookup and the
    /// observations' compaction; with `--relabel` also its relabeling's), in `gpu_ms`:
    /// the renderer's kernels are listed by name, these are not. 0 where the host finds
    /// the regions (a CPU device).
    pub regions_gpu_ms: f64,
}

fn bytes_per_entry(method: Method, acc: Accumulation) -> u64 {
    match (method, acc) {
        (Method::Vote | Method::VoteOcclusion, _) => 4,
        (_, Accumulation::FixedPoint) => 8,
        (_, Accumulation::Float) => 4,
    }
}

/// Rows of the evidence matrix one pass holds, and the passes over the views its `classes`
/// rows take.
pub fn evidence_passes(
    gpu: &Gpu,
    cfg: &FuseConfig,
    classes: usize,
    n: usize,
) -> Result<(usize, usize)> {
    let rows = rows_per_pass(gpu, cfg, classes, n)?;
    Ok((rows, classes.div_ceil(rows).max(1)))
}

/// Rows of the evidence matrix one pass holds.
fn rows_per_pass(gpu: &Gpu, cfg: &FuseConfig, classes: usize, n: usize) -> Result<usize> {
    let per_row = bytes_per_entry(cfg.method, cfg.accumulation) * n.max(1) as u64;
    let caps = gpu.caps();
    // The kernels reach the rows by address, so a pass is one allocation of at most
    // 2^31 words (a kernel's index is a signed 32-bit value), not one binding.
    let one_buffer = caps.max_allocation.min(i32::MAX as u64 * 4);
    let budget = cfg
        .mem_budget
        .unwrap_or(caps.device_local_bytes() / 4)
        .min(one_buffer);
    let rows = (budget / per_row) as usize;
    if rows == 0 {
        bail!(
            "one class row of the evidence matrix takes {per_row} bytes for {n} Gaussians, over the memory budget \
             of {budget} bytes (raise --mem-budget; one buffer holds at most {one_buffer} bytes on this device)"
        );
    }
    Ok(rows.min(classes.max(1)))
}

/// Refuses an accumulation mode the device lacks the atomics for.
fn check_atomics(gpu: &Gpu, acc: Accumulation) -> Result<()> {
    let caps = gpu.caps();
    match acc {
        Accumulation::FixedPoint if !caps.int64_atomics => bail!(
            "fixed-point accumulation needs 64-bit integer atomics, which {} lacks; use float atomics",
            caps.name
        ),
        Accumulation::Float if !caps.float_atomic_add => bail!(
            "float accumulation needs VK_EXT_shader_atomic_float, which {} lacks",
            caps.name
        ),
        _ => Ok(()),
    }
}

/// The class rows of the evidence one pass over the views accumulates.
struct EvidencePass {
    evidence: Buffer,
    row_begin: usize,
    rows: usize,
}

impl EvidencePass {
    /// Zeroed evidence for rows `row_begin..row_begin + rows` of `n` Gaussians.
    fn new(gpu: &Gpu, row_begin: usize, rows: usize, n: usize, entry: u64) -> Result<Self> {
        let evidence = gpu.buffer("evidence", (rows * n) as u64 * entry)?;
        let mut rec = Recorder::new(gpu)?;
        rec.fill(&evidence, 0, evidence.size(), 0);
        rec.submit_and_wait()?;
        Ok(EvidencePass {
            evidence,
            row_begin,
            rows,
        })
    }
}

/// The per-view device inputs, grown to the largest view: the label map and the per-pixel
/// state the tiled methods carry between windows.
#[derive(Default)]
struct ViewInputs {
    labels: Option<Buffer>,
    carry: Option<Buffer>,
}

impl ViewInputs {
    /// (labels, carry) for a view of `pixels` pixels.
    fn for_pixels(&mut self, gpu: &Gpu, pixels: u64) -> Result<(&Buffer, &Buffer)> {
        if self.labels.as_ref().is_none_or(|b| b.size() < pixels * 4) {
            self.labels = Some(gpu.buffer("labels", pixels * 4)?);
            self.carry = Some(gpu.buffer("contrib-carry", pixels * CONTRIB_CARRY_BYTES)?);
        }
        Ok(self.current())
    }

    /// A view of `pixels` pixels whose labels are staged in `staged`: its label upload, and
    /// the carry.
    fn for_view<'a>(
        &'a mut self,
        gpu: &Gpu,
        staged: &'a Buffer,
        pixels: u64,
    ) -> Result<(ViewLabels<'a>, &'a Buffer)> {
        let (device, carry) = self.for_pixels(gpu, pixels)?;
        let labels = ViewLabels {
            staged,
            device,
            bytes: pixels * 4,
        };
        Ok((labels, carry))
    }

    /// (labels, carry) as last allocated.
    fn current(&self) -> (&Buffer, &Buffer) {
        let (Some(labels), Some(carry)) = (&self.labels, &self.carry) else {
            unreachable!("allocated together");
        };
        (labels, carry)
    }
}

/// A rasterizer and the device inputs of the views it runs. The tiled methods keep up to
/// `views_in_flight` of them ([`LANES`] by default) and give view `v` to lane `v % lanes`:
/// the host records and submits a view while the GPU still runs the previous ones, instead
/// of leaving the GPU idle while it records (about 3 ms a view at 1080p).
struct Lane {
    /// The first field: a dropped lane waits for its view before its inputs are freed.
    raster: Rasterizer,
    inputs: ViewInputs,
    /// The view submitted on this lane and not yet finished.
    view: Option<usize>,
}

/// Views in flight at once by default (each with its own rasterizer buffers).
pub const LANES: usize = 2;

/// Views in flight at once at most ([`FuseConfig::views_in_flight`]): more lanes hide more
/// of each view's host work (recording, the label upload, the gathering) where the GPU's own
/// work per view is short; whether they pay on a GPU is measured with `bench fuse
/// --views-in-flight` (docs/gpu.md), so the default stays at [`LANES`].
pub const MAX_LANES: usize = 4;

/// Share of the device-local memory the lanes may fill before no further lane is added.
const LANE_MEMORY_SHARE: f64 = 0.8;

/// The lanes of one fusion run. It starts with one; the first tiled view runs alone, which
/// shows what a lane's buffers take for these views, and further lanes (up to
/// `views_in_flight`) are added only while the device has room for them, so keeping views
/// in flight never makes a run fail that fits one view at a time.
struct Lanes {
    lanes: Vec<Lane>,
    /// Whether the first tiled view has run (and the lane count is settled).
    settled: bool,
}

impl Lanes {
    fn new(gpu: &Gpu, cfg: &FuseConfig) -> Lanes {
        Lanes {
            lanes: vec![Lane::new(gpu, cfg.split)],
            settled: false,
        }
    }

    /// Submits a tiled method's view on its lane; returns the GPU work of the views that
    /// finished meanwhile.
    fn submit(
        &mut self,
        ctx: &PassContext,
        view: usize,
        staged: &Buffer,
        pixels: u64,
    ) -> Result<ViewGpu> {
        if self.settled {
            let count = self.lanes.len();
            return self.lanes[view % count].submit(ctx, view, staged, pixels);
        }
        let before = ctx.gpu.memory_reserved();
        let mut work = self.lanes[0].submit(ctx, view, staged, pixels)?;
        work.add(self.lanes[0].finish(ctx)?);
        let lane_bytes = ctx.gpu.memory_reserved().saturating_sub(before);
        for _ in 1..lanes_that_fit(ctx.gpu, ctx.cfg, lane_bytes) {
            self.lanes.push(Lane::new(ctx.gpu, ctx.cfg.split));
        }
        self.settled = true;
        Ok(work)
    }
}

/// How many lanes to keep (1..=`cfg.views_in_flight`, at most [`MAX_LANES`]) when one took
/// `lane_bytes` of device memory for its first view: more only while the device-local
/// memory has room for their buffers too.
pub(crate) fn lanes_that_fit(gpu: &Gpu, cfg: &FuseConfig, lane_bytes: u64) -> usize {
    let budget = gpu.caps().device_local_bytes() as f64 * LANE_MEMORY_SHARE;
    let mut lanes = 1;
    while lanes < cfg.views_in_flight.clamp(1, MAX_LANES)
        && (gpu.memory_reserved() + lanes as u64 * lane_bytes) as f64 <= budget
    {
        lanes += 1;
    }
    lanes
}

/// What every view of one pass shares.
struct PassContext<'a> {
    gpu: &'a Gpu,
    scene: &'a GpuScene,
    cams: &'a [Camera],
    pass: &'a EvidencePass,
    cfg: &'a FuseConfig,
    opts: RenderOptions,
}

impl Lane {
    fn new(gpu: &Gpu, split: SplitSizes) -> Lane {
        let mut raster = Rasterizer::new(gpu);
        raster.set_split_sizes(split);
        Lane {
            raster,
            inputs: ViewInputs::default(),
            view: None,
        }
    }

    /// Records a tiled method's view (its labels staged in `staged`) and submits it,
    /// after finishing the lane's previous view; returns that one's GPU work.
    fn submit(
        &mut self,
        ctx: &PassContext,
        view: usize,
        staged: &Buffer,
        pixels: u64,
    ) -> Result<ViewGpu> {
        let finished = self.finish(ctx)?;
        let (labels, carry) = self.inputs.for_view(ctx.gpu, staged, pixels)?;
        let n = ctx.scene.n;
        self.raster.submit_tiled_in_bands(
            ctx.scene,
            &ctx.cams[view],
            &ctx.opts,
            BandWork::Add,
            |rec, tiles| {
                if tiles.band() == 0 {
                    labels.record_upload(rec); // every band reads the whole map
                }
                record_contrib(rec, tiles, n, labels.device, carry, ctx.pass, ctx.cfg)
            },
        )?;
        self.view = Some(view);
        Ok(finished)
    }

    /// Waits for the lane's submitted view, if any, and runs the rows of the bands whose
    /// lists overflowed again (those bands added nothing, the others their part); returns
    /// its GPU work.
    fn finish(&mut self, ctx: &PassContext) -> Result<ViewGpu> {
        let Some(view) = self.view.take() else {
            return Ok(ViewGpu::default());
        };
        let run = match self.raster.wait_tiled()? {
            Some(run) => run,
            None => {
                // The first attempt copied the labels in; the lane's buffer still holds them.
                let (labels, carry) = self.inputs.current();
                let n = ctx.scene.n;
                self.raster.run_tiled_in_bands(
                    ctx.scene,
                    &ctx.cams[view],
                    &ctx.opts,
                    BandWork::Add,
                    |rec, tiles| record_contrib(rec, tiles, n, labels, carry, ctx.pass, ctx.cfg),
                )?
            }
        };
        Ok(ViewGpu::of(&run.timings))
    }
}

/// GPU work of finished views: time, and time per kernel.
#[derive(Default)]
struct ViewGpu {
    ms: f64,
    kernels: Vec<KernelTotal>,
}

impl ViewGpu {
    /// Adds `other`'s work to this one.
    fn add(&mut self, other: ViewGpu) {
        self.ms += other.ms;
        KernelTotal::add_all(&mut self.kernels, other.kernels);
    }

    /// A whole submission's work.
    fn of(timings: &Timings) -> ViewGpu {
        ViewGpu {
            ms: timings.total_ns() * 1e-6,
            kernels: timings.by_kernel(),
        }
    }
}

impl FuseStats {
    /// A run's last figures: its wall time since `start`, the views with a label map a
    /// second (each once, however many passes took it; views without one cost no work),
    /// and the process's peak resident memory so far.
    pub(crate) fn finish(&mut self, start: Instant) {
        self.wall_s = start.elapsed().as_secs_f64();
        self.views_per_s = self.views_with_labels as f64 / self.wall_s.max(1e-9);
        self.peak_host_bytes = crate::util::memory::peak_host_bytes().unwrap_or(0);
    }

    fn add_gpu(&mut self, work: ViewGpu) {
        self.gpu_ms += work.ms;
        KernelTotal::add_all(&mut self.kernels, work.kernels);
    }
}

/// Host buffers the label maps are staged in by the worker threads that read them: one
/// slot per view in flight (view `v` uses slot `v % slots`). A slot is written again only
/// once the GPU has run its view: workers run at most [`LABELS_AHEAD`] views ahead of the
/// view being recorded, the GPU at most [`MAX_LANES`] views behind it, and there are more
/// slots than both together.
struct LabelStaging {
    slots: Vec<Mutex<Option<Buffer>>>,
}

impl LabelStaging {
    fn new() -> LabelStaging {
        LabelStaging {
            slots: (0..LABELS_AHEAD + MAX_LANES + 1)
                .map(|_| Mutex::new(None))
                .collect(),
        }
    }

    fn slot(&self, view: usize) -> std::sync::MutexGuard<'_, Option<Buffer>> {
        let slot = &self.slots[view % self.slots.len()];
        slot.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Copies `map` into view `view`'s slot (grown as needed).
    fn stage(&self, gpu: &Gpu, view: usize, map: &[u32]) -> Result<()> {
        let bytes = std::mem::size_of_val(map) as u64;
        grown(&mut self.slot(view), gpu, bytes, Gpu::staging_buffer)?.write_mapped(map);
        Ok(())
    }
}

/// A view's label map: staged on the host, copied to `device` at the start of the view's
/// GPU work (in the same submission).
struct ViewLabels<'a> {
    staged: &'a Buffer,
    device: &'a Buffer,
    bytes: u64,
}

impl ViewLabels<'_> {
    fn record_upload(&self, rec: &mut Recorder) {
        rec.copy(self.staged, 0, self.device, 0, self.bytes);
        rec.barrier();
    }
}

/// How many views the workers reading label maps may run ahead of the GPU (each a label
/// map in memory and a staging buffer).
pub(crate) const LABELS_AHEAD: usize = 8;

/// Worker threads reading label maps ahead of the GPU: one a core, at least 4 and at most
/// [`LABELS_AHEAD`] (more could not run). On a GPU the views are a few milliseconds each,
/// about what reading a 1080p map takes, so 4 workers on a 16-core machine kept the GPU
/// waiting (an H200: 1.5 s of FlashSplat's 1.9 s over 190 views).
pub(crate) fn label_threads() -> usize {
    std::thread::available_parallelism().map_or(4, |n| n.get().clamp(4, LABELS_AHEAD))
}

/// Bytes per pixel of the weighted methods' carried state between windows: (T, done).
pub(crate) const CONTRIB_CARRY_BYTES: u64 = 8;

/// Runs `cfg.method` over every view and returns the evidence [classes][n].
pub fn accumulate(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
    progress: impl FnMut(usize, usize),
) -> Result<(ClassScores, FuseStats)> {
    if cfg.method.is_consensus() {
        return super::consensus::consensus_evidence(gpu, scene, cams, labels, classes, cfg);
    }
    let n = scene.n as usize;
    let mut scores = ClassScores::zeros(classes, n);
    let stats = accumulate_passes(gpu, scene, cams, labels, classes, cfg, progress, |pass| {
        let dst = &mut scores.data[pass.row_begin * n..(pass.row_begin + pass.rows) * n];
        download_rows(gpu, pass, cfg, 0..pass.rows, dst)
    })?;
    Ok((scores, stats))
}

/// [`accumulate`] with the evidence kept per Gaussian by its nonzero sums, a row downloaded
/// at a time: for a method's evidence over many classes, of which each Gaussian sees few
/// (`--relabel`'s second visit of the views).
pub fn accumulate_by_gaussian(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
    progress: impl FnMut(usize, usize),
) -> Result<(SumsByGaussian<f64>, FuseStats)> {
    let n = scene.n as usize;
    let (mut sums, mut row) = (SumsByGaussian::new(n), vec![0.0; n]);
    let stats = accumulate_passes(gpu, scene, cams, labels, classes, cfg, progress, |pass| {
        for r in 0..pass.rows {
            download_rows(gpu, pass, cfg, r..r + 1, &mut row)?;
            let class = (pass.row_begin + r) as u32;
            for (g, &x) in row.iter().enumerate().filter(|&(_, &x)| x != 0.0) {
                sums.add(g, class, x);
            }
        }
        Ok(())
    })?;
    Ok((sums, stats))
}

/// Receives the evidence rows of [`accumulate_assigned`] one at a time, in class order:
/// (compact class, its row over every Gaussian).
pub type RowSink<'s> = &'s mut dyn FnMut(usize, &[f64]) -> Result<()>;

/// What [`accumulate_assigned`] assigns with, and where the evidence rows go.
#[derive(Default)]
pub struct AssignOnGpu<'s> {
    /// Nearest neighbours: ties go to the class the neighbours hold most evidence for.
    pub knn: Option<TieNeighbours<'s>>,
    /// Where every row goes, for outputs that need the evidence itself (none by default:
    /// then the rows never leave the device).
    pub rows: Option<RowSink<'s>>,
}

/// The nearest neighbours that break [`accumulate_assigned`]'s ties.
#[derive(Clone, Copy)]
pub enum TieNeighbours<'s> {
    /// Found already: [n][k] (`bench fuse` searches once for every method it times).
    Found(&'s [u32], usize),
    /// The k nearest of these centers, searched for on a thread while the views keep the
    /// GPU busy, and waited for when the first pass's evidence is assigned: they read only
    /// the centers, and on the H100 the search of the 978k room (the grid it had then) took
    /// half as long as FlashSplat's 200 views of it (docs/fusion-speed.md).
    Search(&'s [[f32; 3]], usize),
}

/// [`accumulate`] followed by [`super::assign_semantic_near`]. Where [`gpu_assignable`]
/// (evidence in exact integers: votes and fixed point, on a device with shaderInt64), the
/// assignment is folded on the GPU after each pass ([`GpuAssigner`]) and the host holds a
/// few words per Gaussian instead of the evidence matrix; else (float atomics, the segment
/// consensus) the matrix is downloaded and assigned on the host. The result is the same.
#[allow(clippy::too_many_arguments)]
pub fn accumulate_assigned(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
    with: AssignOnGpu,
    progress: impl FnMut(usize, usize),
) -> Result<(Assignment, FuseStats)> {
    let AssignOnGpu { knn, rows } = with;
    let run = FusionRun {
        gpu,
        scene,
        cams,
        labels,
        classes,
        cfg,
    };
    match knn {
        None => run.assigned(rows, || None, progress),
        Some(TieNeighbours::Found(knn, k)) => {
            run.assigned(rows, || Some((Cow::Borrowed(knn), k)), progress)
        }
        Some(TieNeighbours::Search(means, k)) => std::thread::scope(|scope| {
            let search = scope.spawn(move || nearest_neighbours(means, k));
            let neighbours = || {
                let knn = search
                    .join()
                    .unwrap_or_else(|p| std::panic::resume_unwind(p));
                Some((Cow::Owned(knn), k))
            };
            run.assigned(rows, neighbours, progress)
        }),
    }
}

/// Tie neighbours as [`assign_semantic_near`] and [`GpuAssigner::new`] take them.
type Neighbours<'k> = Option<(Cow<'k, [u32]>, usize)>;

fn borrowed<'a>(knn: &'a Neighbours) -> Option<(&'a [u32], usize)> {
    knn.as_ref().map(|(knn, k)| (&**knn, *k))
}

/// The arguments of one [`accumulate_assigned`] call.
struct FusionRun<'a> {
    gpu: &'a Gpu,
    scene: &'a GpuScene,
    cams: &'a [Camera],
    labels: &'a dyn LabelSource,
    classes: usize,
    cfg: &'a FuseConfig,
}

impl FusionRun<'_> {
    /// [`accumulate`]: the evidence matrix, for the host to assign.
    fn accumulate(&self, progress: impl FnMut(usize, usize)) -> Result<(ClassScores, FuseStats)> {
        let (gpu, scene, cams, labels) = (self.gpu, self.scene, self.cams, self.labels);
        accumulate(gpu, scene, cams, labels, self.classes, self.cfg, progress)
    }

    /// [`accumulate_passes`]: each pass's rows to `on_pass`, on the device.
    fn passes(
        &self,
        progress: impl FnMut(usize, usize),
        on_pass: impl FnMut(&EvidencePass) -> Result<()>,
    ) -> Result<FuseStats> {
        let (gpu, scene, cams, labels) = (self.gpu, self.scene, self.cams, self.labels);
        accumulate_passes(
            gpu,
            scene,
            cams,
            labels,
            self.classes,
            self.cfg,
            progress,
            on_pass,
        )
    }

    /// [`accumulate_assigned`] with its tie neighbours from `neighbours`, called once, when
    /// the first evidence is assigned (after the first pass's views).
    fn assigned<'k>(
        &self,
        mut rows: Option<RowSink>,
        neighbours: impl FnOnce() -> Neighbours<'k>,
        progress: impl FnMut(usize, usize),
    ) -> Result<(Assignment, FuseStats)> {
        let (gpu, cfg, classes) = (self.gpu, self.cfg, self.classes);
        let Some(kind) = gpu_assignable(gpu, cfg) else {
            let (scores, stats) = self.accumulate(progress)?;
            if let Some(sink) = rows.as_mut() {
                for e in 0..classes {
                    sink(e, scores.row(e))?;
                }
            }
            let knn = neighbours();
            return Ok((assign_semantic_near(&scores, borrowed(&knn)), stats));
        };
        let n = self.scene.n as usize;
        let mut assigner = LazyAssigner {
            gpu,
            n,
            classes,
            kind,
            neighbours: Some(neighbours),
            made: None,
        };
        let on_pass = |pass: &EvidencePass| {
            assigner
                .get()?
                .fold(&pass.evidence, pass.row_begin, pass.rows)?;
            let Some(sink) = rows.as_mut() else {
                return Ok(());
            };
            let mut row = vec![0.0; n];
            for r in 0..pass.rows {
                download_rows(gpu, pass, cfg, r..r + 1, &mut row)?;
                sink(pass.row_begin + r, &row)?;
            }
            Ok(())
        };
        let stats = self.passes(progress, on_pass)?;
        Ok((assigner.finish()?, stats))
    }
}

/// A [`GpuAssigner`] made when first needed, with the neighbours `neighbours` gives then.
struct LazyAssigner<'g, F> {
    gpu: &'g Gpu,
    n: usize,
    classes: usize,
    kind: EvidenceKind,
    neighbours: Option<F>,
    made: Option<GpuAssigner<'g>>,
}

impl<'g, 'k, F: FnOnce() -> Neighbours<'k>> LazyAssigner<'g, F> {
    fn get(&mut self) -> Result<&mut GpuAssigner<'g>> {
        if let Some(neighbours) = self.neighbours.take() {
            let knn = neighbours();
            let assigner =
                GpuAssigner::new(self.gpu, self.n, self.classes, self.kind, borrowed(&knn))?;
            self.made = Some(assigner);
        }
        Ok(self.made.as_mut().expect("made on the first call"))
    }

    /// Every Gaussian's class ([`GpuAssigner::finish`]), made now if no pass ran.
    fn finish(mut self) -> Result<Assignment> {
        self.get()?;
        self.made.take().expect("made by get").finish()
    }
}

/// The integer kind of `cfg`'s evidence when [`accumulate_assigned`] can assign it on
/// `gpu`; None where the host must ([`accumulate`]).
pub fn gpu_assignable(gpu: &Gpu, cfg: &FuseConfig) -> Option<EvidenceKind> {
    let kind = EvidenceKind::of(cfg.method, cfg.accumulation)?;
    (!cfg.method.is_consensus() && gpu.caps().int64).then_some(kind)
}

/// Runs every pass over the views; `on_pass` takes each pass's finished rows.
#[allow(clippy::too_many_arguments)]
fn accumulate_passes(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
    mut progress: impl FnMut(usize, usize),
    mut on_pass: impl FnMut(&EvidencePass) -> Result<()>,
) -> Result<FuseStats> {
    let start = Instant::now();
    let n = scene.n as usize;
    check_atomics(gpu, cfg.accumulation)?;
    let (rows, passes) = evidence_passes(gpu, cfg, classes, n)?;
    let entry = bytes_per_entry(cfg.method, cfg.accumulation);
    let mut stats = FuseStats {
        views: cams.len(),
        passes,
        rows_per_pass: rows,
        ..Default::default()
    };
    let mut lanes = Lanes::new(gpu, cfg);
    let staging = LabelStaging::new();
    for pass_index in 0..passes {
        let row_begin = pass_index * rows;
        let pass = EvidencePass::new(gpu, row_begin, rows.min(classes - row_begin), n, entry)?;
        let ctx = PassContext {
            gpu,
            scene,
            cams,
            pass: &pass,
            cfg,
            opts: cfg.render_options(),
        };
        let views = cams.len();
        let pass_progress = |view: usize| progress(pass_index * views + view, passes * views);
        run_pass(
            &ctx,
            &mut lanes,
            labels,
            &staging,
            &mut stats,
            pass_progress,
        )?;
        let evidence_start = Instant::now();
        on_pass(&pass)?;
        stats.evidence_s += evidence_start.elapsed().as_secs_f64();
    }
    progress(passes * cams.len(), passes * cams.len());
    // The passes' throughput is `bench fuse`'s, which divides views x passes.
    stats.finish(start);
    stats.views_in_flight = lanes.lanes.len();
    stats.scene_device_bytes = scene.device_bytes();
    Ok(stats)
}

/// Runs every view of one pass, `progress(view)` before each: label maps are read
/// (decoded, converted) and staged on worker threads a few views ahead while the GPU works on
/// the current ones. Every view has finished on the GPU when it returns, error or not.
fn run_pass(
    ctx: &PassContext,
    lanes: &mut Lanes,
    labels: &dyn LabelSource,
    staging: &LabelStaging,
    stats: &mut FuseStats,
    mut progress: impl FnMut(usize),
) -> Result<()> {
    let (cams, gpu) = (ctx.cams, ctx.gpu);
    let first_pass = ctx.pass.row_begin == 0;
    let (read, staged) = (BusyTime::default(), BusyTime::default());
    let produce = |view: usize| -> Result<Option<u64>> {
        let Some(map) = read.time(|| labels.labels(view, &cams[view]))? else {
            return Ok(None);
        };
        check_map_size(&cams[view], &map)?;
        staged.time(|| staging.stage(gpu, view, &map))?;
        Ok(Some(map.len() as u64))
    };
    let mut waited_since = Instant::now();
    let produced = prefetch_ordered(
        cams.len(),
        label_threads(),
        LABELS_AHEAD,
        produce,
        |view, staged| {
            stats.label_wait_s += waited_since.elapsed().as_secs_f64();
            labels.before_view(view)?;
            progress(view);
            if let Some(pixels) = staged {
                stats.views_with_labels += usize::from(first_pass);
                let view_start = Instant::now();
                let slot = staging.slot(view);
                let staged = slot.as_ref().expect("staged by the producer");
                let finished = run_view(lanes, ctx, view, staged, pixels)?;
                stats.add_gpu(finished);
                stats.view_s += view_start.elapsed().as_secs_f64();
                stats.peak_device_bytes = stats.peak_device_bytes.max(gpu.memory_reserved());
            }
            waited_since = Instant::now();
            Ok(())
        },
    );
    // Every lane is waited for, even after an error: the pass's evidence is read (or freed)
    // next.
    let finish_start = Instant::now();
    let finished: Vec<Result<ViewGpu>> = lanes.lanes.iter_mut().map(|l| l.finish(ctx)).collect();
    stats.label_read_s += read.seconds();
    stats.label_stage_s += staged.seconds();
    produced?;
    for work in finished {
        stats.add_gpu(work?);
    }
    stats.view_s += finish_start.elapsed().as_secs_f64();
    Ok(())
}

/// Like [`accumulate`], but returns the evidence [classes][n] as the integers the GPU summed
/// (fixed-point u64 or vote counts u32), so partial sums over disjoint sets of views add up
/// exactly to the sum over all of them (`semsplat merge`). Float accumulation has no exact
/// partial sums and is refused.
pub fn accumulate_raw(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    labels: &dyn LabelSource,
    classes: usize,
    cfg: &FuseConfig,
    progress: impl FnMut(usize, usize),
) -> Result<(RawEvidence, FuseStats)> {
    let n = scene.n as usize;
    ensure!(
        !cfg.method.is_consensus(),
        "{} decides its segments from every view at once: its evidence cannot be split into \
         parts (fuse --shard) and summed",
        cfg.method.name()
    );
    let Some(kind) = EvidenceKind::of(cfg.method, cfg.accumulation) else {
        bail!("float accumulation has no exact integer evidence to save; use fixed point");
    };
    let mut raw = RawEvidence::zeros(kind, classes * n);
    let stats = accumulate_passes(gpu, scene, cams, labels, classes, cfg, progress, |pass| {
        let (begin, end) = (pass.row_begin * n, (pass.row_begin + pass.rows) * n);
        match &mut raw {
            RawEvidence::Fixed(out) => out[begin..end].copy_from_slice(&gpu.download::<u64>(
                &pass.evidence,
                0,
                end - begin,
            )?),
            RawEvidence::Counts(out) => out[begin..end].copy_from_slice(&gpu.download::<u32>(
                &pass.evidence,
                0,
                end - begin,
            )?),
        }
        Ok(())
    })?;
    Ok((raw, stats))
}

/// Refuses a label map whose size is not the camera's.
pub(crate) fn check_map_size(cam: &Camera, map: &[u32]) -> Result<()> {
    let pixels = cam.width as usize * cam.height as usize;
    ensure!(
        map.len() == pixels,
        "labels of view {} have {} pixels, the camera {pixels}",
        cam.name,
        map.len()
    );
    Ok(())
}

/// Adds one view's evidence into the pass: the tiled methods submit it on its lane (and
/// finish the lane's previous view), the votes run it whole. Returns the GPU work of the
/// views finished.
fn run_view(
    lanes: &mut Lanes,
    ctx: &PassContext,
    view: usize,
    staged: &Buffer,
    pixels: u64,
) -> Result<ViewGpu> {
    let cfg = ctx.cfg;
    if cfg.method.is_tiled() {
        return lanes.submit(ctx, view, staged, pixels);
    }
    // The votes run each view whole, on the first lane.
    let lane = &mut lanes.lanes[0];
    let (labels, _) = lane.inputs.for_view(ctx.gpu, staged, pixels)?;
    let cam = &ctx.cams[view];
    match cfg.method {
        Method::Vote => run_vote(ctx, cam, &labels, None),
        Method::VoteOcclusion => vote_occluded(&mut lane.raster, ctx, cam, &labels),
        _ => bail!("{} has no per-view evidence pass", cfg.method.name()),
    }
}

/// Occlusion-checked vote of one view: its centers vote once the whole view's depth is
/// rendered, in a submission of its own (a binning that overflowed runs again, and must not
/// have voted). Returns its GPU work.
fn vote_occluded(
    raster: &mut Rasterizer,
    ctx: &PassContext,
    cam: &Camera,
    labels: &ViewLabels,
) -> Result<ViewGpu> {
    let run = raster.run_tiled_in_bands(
        ctx.scene,
        cam,
        &ctx.opts,
        BandWork::Overwrite,
        |rec, tiles| tiles.record_blend(rec),
    )?;
    let mut work = ViewGpu::of(&run.timings);
    work.add(run_vote(ctx, cam, labels, Some(raster.depth()))?);
    Ok(work)
}

/// Records the weighted methods' accumulation over the binned view: every window of the
/// tile lists adds alpha * T per (label, Gaussian) into the pass's evidence.
fn record_contrib(
    rec: &mut Recorder,
    tiles: &TileLists,
    n: u32,
    labels: &Buffer,
    carry: &Buffer,
    pass: &EvidencePass,
    cfg: &FuseConfig,
) -> Result<()> {
    let kernel = match cfg.accumulation {
        Accumulation::FixedPoint => {
            ids::FUSE_CONTRIB_FIXED.for_device(ids::FUSE_CONTRIB_FIXED_WIDE, rec.gpu())
        }
        Accumulation::Float => {
            ids::FUSE_CONTRIB_FLOAT.for_device(ids::FUSE_CONTRIB_FLOAT_WIDE, rec.gpu())
        }
    };
    let walk = ContribWalk {
        kernel,
        labels,
        carry,
        contrib_addr: pass.evidence.address_words(4)?,
        rows: (pass.row_begin as u32, pass.rows as u32),
        center_only: cfg.method == Method::VoteWeighted,
        per_view: cfg.method == Method::FlashSplatPerView,
        depths: None,
    };
    record_contrib_walk(rec, tiles, n, &walk)
}

/// One walk of a binned view's tile lists by a kernel of fuse/contrib_body.glsl: what it
/// reads per pixel, where it adds, and how.
pub(crate) struct ContribWalk<'a> {
    pub kernel: Kernel<ContribParams>,
    /// Per pixel, the row its weights add to (NO_LABEL: none).
    pub labels: &'a Buffer,
    /// Per pixel, [`CONTRIB_CARRY_BYTES`] carried between windows.
    pub carry: &'a Buffer,
    /// Where the kernel adds (its includer's layout).
    pub contrib_addr: [u32; 2],
    /// (first row, rows) of the labels it adds; others wait for another pass.
    pub rows: (u32, u32),
    pub center_only: bool,
    pub per_view: bool,
    /// Per pixel, the median and opaque depths the kernel writes (only
    /// fuse/region_footprint.comp).
    pub depths: Option<OcclusionDepths<'a>>,
}

/// Records `walk` over every window of the binned view's tile lists, band by band of the
/// per-pixel buffers.
pub(crate) fn record_contrib_walk(
    rec: &mut Recorder,
    tiles: &TileLists,
    n: u32,
    walk: &ContribWalk,
) -> Result<()> {
    let f = &tiles.frame;
    let bands = f.bands(CONTRIB_CARRY_BYTES)?;
    let projected = tiles.projected_addrs()?;
    let windows = tiles.pass_windows(rec, &bands)?;
    for (window, start) in f.window_starts() {
        for (band_index, band) in bands.iter().enumerate() {
            let params = ContribParams {
                xy_depth_opacity_addr: projected.xy_depth_opacity,
                xy_frac_addr: projected.xy_frac,
                conics_addr: projected.conics,
                contrib_addr: walk.contrib_addr,
                width: f.cam.width,
                height: f.cam.height,
                tiles_x: f.tiles_x,
                n,
                window_start: start,
                window_len: f.window_len,
                row_begin: walk.rows.0,
                rows: walk.rows.1,
                center_only: u32::from(walk.center_only),
                per_view: u32::from(walk.per_view),
                tile_row_base: band.first_tile_row,
            };
            let mut bindings = vec![
                ("tile_ranges", BufferRange::whole(tiles.ranges())),
                ("isect_ids", BufferRange::whole(tiles.isect_ids())),
                ("labels", band.range(walk.labels, 4)),
                ("carry", band.range(walk.carry, CONTRIB_CARRY_BYTES)),
                ("status", tiles.status()),
            ];
            if let Some(depths) = &walk.depths {
                bindings.push(("out_depth", band.range(depths.median, 4)));
                bindings.push(("out_opaque_depth", band.range(depths.opaque, 4)));
            }
            windows.dispatch(rec, walk.kernel, &bindings, &params, (window, band_index))?;
        }
        rec.barrier();
    }
    Ok(())
}

/// Rows `rows` of the pass (relative to its first), widened to f64 into `dst`.
fn download_rows(
    gpu: &Gpu,
    pass: &EvidencePass,
    cfg: &FuseConfig,
    rows: std::ops::Range<usize>,
    dst: &mut [f64],
) -> Result<()> {
    let entry = bytes_per_entry(cfg.method, cfg.accumulation);
    let widen: fn(&[u8]) -> f64 = match (cfg.method, cfg.accumulation) {
        (Method::Vote | Method::VoteOcclusion, _) => |b| f64::from(u32::from_le_bytes(le(b))),
        (_, Accumulation::FixedPoint) => |b| fixed_to_f64(u64::from_le_bytes(le(b))),
        (_, Accumulation::Float) => |b| f64::from(f32::from_le_bytes(le(b))),
    };
    let row_bytes = entry * (dst.len() / rows.len().max(1)) as u64;
    let (offset, len) = (rows.start as u64 * row_bytes, rows.len() as u64 * row_bytes);
    gpu.download_with(&pass.evidence, offset, len, |bytes| {
        widen_in_parallel(bytes, entry as usize, dst, widen)
    })?;
    Ok(())
}

/// The first N bytes of `b` as an array (`b` is one evidence entry).
fn le<const N: usize>(b: &[u8]) -> [u8; N] {
    b[..N].try_into().expect("one entry")
}

/// `dst[i] = widen(entry i of bytes)` on every core: the evidence of millions of
/// Gaussians times the classes is hundreds of MB (6M x 16 fixed-point entries: 768 MB).
fn widen_in_parallel(bytes: &[u8], entry: usize, dst: &mut [f64], widen: fn(&[u8]) -> f64) {
    let threads = crate::util::cores();
    let per_thread = dst.len().div_ceil(threads).max(1);
    std::thread::scope(|scope| {
        for (out, raw) in dst
            .chunks_mut(per_thread)
            .zip(bytes.chunks(per_thread * entry))
        {
            scope.spawn(move || {
                for (o, b) in out.iter_mut().zip(raw.chunks_exact(entry)) {
                    *o = widen(b);
                }
            });
        }
    });
}

/// The vote of one view (only where `depth` shows the center, when given) in a submission
/// of its own; returns its GPU work (the label upload not counted in its time).
fn run_vote(
    ctx: &PassContext,
    cam: &Camera,
    labels: &ViewLabels,
    depth: Option<&Buffer>,
) -> Result<ViewGpu> {
    let mut rec = Recorder::new(ctx.gpu)?;
    labels.record_upload(&mut rec);
    let m0 = rec.mark();
    dispatch_vote(
        &mut rec,
        ctx.scene,
        cam,
        labels.device,
        depth,
        ctx.pass,
        ctx.cfg,
    )?;
    let m1 = rec.mark();
    let t = rec.submit_and_wait()?;
    Ok(ViewGpu {
        ms: t.between(m0, m1).unwrap_or(0.0) * 1e-6,
        kernels: t.by_kernel(),
    })
}

/// Push constants of the kernels that look up each Gaussian's center pixel (the vote and
/// the consensus's observations): the camera, clip range and occlusion test of `cfg`, and
/// the class rows `(row_begin, rows)` a vote pass holds, and the addresses of the scene's
/// means and of the output (a vote pass's rows, or the observations' center pixels).
pub(crate) fn center_params(
    cam: &Camera,
    scene: &GpuScene,
    cfg: &FuseConfig,
    occlusion: bool,
    (row_begin, rows): (u32, u32),
    out_addr: [u32; 2],
) -> Result<CenterParams> {
    Ok(CenterParams {
        world_to_camera: camera_rows_f32(&scene.local_camera(cam)),
        means_addr: scene.params.means.address_words(12)?,
        out_addr,
        spatial_addr: [0, 0], // at each Gaussian's own index
        fx: cam.fx as f32,
        fy: cam.fy as f32,
        cx: cam.cx as f32,
        cy: cam.cy as f32,
        near: cfg.near,
        far: cfg.far,
        depth_tolerance: cfg.depth_tolerance,
        behind_tolerance: cfg.behind_tolerance,
        occlusion: u32::from(occlusion),
        width: cam.width,
        height: cam.height,
        n: scene.n,
        row_begin,
        rows,
    })
}

/// Records the vote of every projected center into the pass's rows; with `depth`, only
/// centers within the tolerance of the rendered depth vote.
fn dispatch_vote(
    rec: &mut Recorder,
    scene: &GpuScene,
    cam: &Camera,
    labels: &Buffer,
    depth: Option<&Buffer>,
    pass: &EvidencePass,
    cfg: &FuseConfig,
) -> Result<()> {
    let rows = (pass.row_begin as u32, pass.rows as u32);
    let votes = pass.evidence.address_words(4)?;
    let params = center_params(cam, scene, cfg, depth.is_some(), rows, votes)?;
    rec.dispatch(
        ids::FUSE_VOTE,
        &[("labels", labels), ("depth", depth.unwrap_or(labels))],
        &params,
        ids::FUSE_VOTE.groups_for(scene.n),
    )?;
    rec.barrier();
    Ok(())
}
