//! Fusion speed (issue #5): every fusion method over many views of a random scene, against
//! a plain forward render (RGB only, the same render options) of the same views.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{ensure, Result};
use glam::DVec3;
use serde::Serialize;

use super::export::{export_inputs, ExportLabels};
use super::median;
use crate::dataset::{Dataset, DatasetPaths};
use crate::fuse::{
    accumulate_assigned, nearest_neighbours, AssignOnGpu, ClusterProfile, Clustering,
    DecideProfile, FuseConfig, LabelSource, Method, ObserveTimes, TieNeighbours, NO_LABEL,
    TIE_NEIGHBOURS,
};
use crate::gpu::timings::KernelTotal;
use crate::gpu::Gpu;
use crate::render::{BandWork, GpuScene, Rasterizer, RenderOptions};
use crate::scene::labels::LabelFormat;
use crate::scene::random_scene::{random_scene, RandomSceneSpec};
use crate::scene::scene_file::CAMERAS_FILE;
use crate::scene::{Camera, Gaussians};
use crate::util::Rng;

/// Issue #5's goal: accumulation takes at most this multiple of the forward render's time.
pub const GOAL_RATIO: f64 = 1.3;

/// Label classes a label map can hold (16-bit label PNGs).
pub const MAX_CLASSES: usize = 65_535;

/// Share of the label blocks left unlabeled, as a segmenter leaves some pixels.
const UNLABELED: f64 = 0.05;

/// What to measure.
#[derive(Clone, Debug, Serialize)]
pub struct FuseBenchSpec {
    /// Gaussians.
    pub n: usize,
    pub views: usize,
    pub width: u32,
    pub height: u32,
    pub classes: usize,
    /// Timed runs of every method and of the forward render; medians are reported.
    pub iters: usize,
    pub seed: u64,
    /// A folder with `scene.ply` and `cameras.json` to fuse instead of the random scene
    /// (its first `views` cameras, scaled to `width` x `height`); `n` becomes its size.
    pub scene: Option<PathBuf>,
    /// With `scene`: its own label maps instead of random blocks (matched to its cameras by name); the
    /// views take the maps' size and `classes` becomes the classes they hold.
    pub labels: Option<PathBuf>,
    /// Write the scene, cameras and label maps here first (see [`super::export`]).
    #[serde(skip)]
    pub export: Option<PathBuf>,
    /// Views each method keeps in flight at most ([`FuseConfig::views_in_flight`]; what it
    /// kept is each method's `views_in_flight`).
    pub views_in_flight: usize,
    /// Segment consensus's clustering ([`FuseConfig::clustering`]).
    pub clustering: Clustering,
}

/// The forward render of every view.
#[derive(Debug, Serialize)]
pub struct ForwardBench {
    /// GPU time of all views (binning + RGB blending), from timestamps.
    pub gpu_ms: f64,
    pub wall_s: f64,
    pub views_per_s: f64,
    /// Mean over the views.
    pub visible_per_view: f64,
    pub intersections_per_view: f64,
    pub peak_device_bytes: u64,
    /// GPU time per kernel over all views (the last run's).
    pub kernels: Vec<KernelTotal>,
}

/// One fusion method over every view.
#[derive(Debug, Serialize)]
pub struct MethodBench {
    /// As `fuse` spells it ("vote --occlusion").
    pub method: &'static str,
    /// As `--methods` takes it ("vote-occlusion").
    pub key: &'static str,
    /// Accumulation over all views and the assignment, as `fuse` runs them
    /// (`fuse::accumulate_assigned`): label upload, GPU work, and the assignment on the GPU
    /// (or the evidence download and host assignment where the method needs it). The
    /// neighbour search for its tie-breaks, once per scene, is `neighbours_s`.
    pub wall_s: f64,
    /// GPU time of all views (binning + accumulation), from timestamps.
    pub gpu_ms: f64,
    /// Views (times passes) per wall second.
    pub views_per_s: f64,
    /// Host time of the accumulation: waiting for label maps, running the views, and
    /// setting up and assigning the evidence matrix (see `FuseStats`); the rest of `wall_s`
    /// is setup.
    pub label_wait_s: f64,
    pub view_s: f64,
    pub evidence_s: f64,
    /// The label maps' readers' busy time, summed over their threads
    /// (`FuseStats::label_read_s`, `label_stage_s`).
    pub label_read_s: f64,
    pub label_stage_s: f64,
    /// Consensus methods: the host's neighbour search and clustering, and the decision.
    pub segments_s: f64,
    pub decide_s: f64,
    /// Consensus methods: their observation pass split (`FuseStats::observe`).
    pub observe: ObserveTimes,
    /// Consensus methods: `segments_s` split, with what the clustering did
    /// (`FuseStats::clustering`).
    pub clustering: ClusterProfile,
    /// Consensus methods: `decide_s` split (`FuseStats::decision`).
    pub decision: DecideProfile,
    /// Passes over the views (the evidence matrix split into class-row batches).
    pub passes: usize,
    pub rows_per_pass: usize,
    /// Views in flight at once (`FuseStats::views_in_flight`): the tiled methods' and the
    /// consensus's observation pass's lanes (whose `observe` parts are summed over them).
    pub views_in_flight: usize,
    /// Device memory the allocator held at most (every method's scene is resident).
    pub peak_device_bytes: u64,
    /// Device memory of the scene as this method uploads it (only what it reads).
    pub scene_device_bytes: u64,
    /// gpu_ms / forward gpu_ms.
    pub gpu_ratio: f64,
    /// GPU time per kernel over all views (the last run's).
    pub kernels: Vec<KernelTotal>,
    /// wall_s / forward wall_s.
    pub wall_ratio: f64,
}

#[derive(Debug, Serialize)]
pub struct FuseBench {
    #[serde(flatten)]
    pub spec: FuseBenchSpec,
    pub device: String,
    /// The ratio to the forward render the issue asks accumulation to stay within.
    pub goal_ratio: f64,
    pub forward: ForwardBench,
    pub methods: Vec<MethodBench>,
    /// Peak resident memory of the whole benchmark process (scene generation included).
    pub peak_host_bytes: Option<u64>,
    /// Threads the host's parallel passes run on (the cores this process may use).
    pub host_threads: usize,
    /// The host's search for every Gaussian's nearest neighbours (the assignment's
    /// tie-break), once per scene.
    pub neighbours_s: f64,
}

/// Label maps like a segmenter's: square blocks of about a twelfth of the image, one class
/// each (a few unlabeled), so neighbouring pixels share labels, as the subgroup combining of
/// contributions expects of real maps. Blocks are not tile-aligned (random offset, size not
/// a multiple of 16). Fresh per view and the same in every run: drawn from (seed, view).
pub(super) struct BlockLabels {
    classes: u64,
    rng: Rng,
}

impl BlockLabels {
    pub(super) fn new(classes: usize, seed: u64) -> BlockLabels {
        BlockLabels {
            classes: classes as u64,
            rng: Rng::new(seed).fork(0x1abe1),
        }
    }
}

impl LabelSource for BlockLabels {
    fn labels(&self, view: usize, cam: &Camera) -> Result<Option<Vec<u32>>> {
        let (w, h) = (cam.width as usize, cam.height as usize);
        let block = (w.max(h) / 12).max(3) | 1;
        let mut rng = self.rng.fork(view as u64);
        let (ox, oy) = (
            rng.below(block as u64) as usize,
            rng.below(block as u64) as usize,
        );
        let bw = (w + ox).div_ceil(block);
        let ids: Vec<u32> = (0..bw * (h + oy).div_ceil(block))
            .map(|_| {
                if rng.bool(UNLABELED) {
                    NO_LABEL
                } else {
                    rng.below(self.classes) as u32
                }
            })
            .collect();
        let mut map = Vec::with_capacity(w * h);
        for y in 0..h {
            let row = &ids[(y + oy) / block * bw..];
            map.extend((0..w).map(|x| row[(x + ox) / block]));
        }
        Ok(Some(map))
    }
}

/// `views` cameras on a ring in front of the random scene (which fills the view cone of a
/// camera at the origin looking down +z), each aimed at its middle, so every view sees
/// most of it from a slightly different side.
fn ring_cameras(views: usize, width: u32, height: u32) -> Vec<Camera> {
    let target = DVec3::new(0.0, 0.0, 4.5);
    (0..views)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / views as f64;
            let eye = DVec3::new(a.cos(), a.sin(), -0.5);
            Camera::look_at(
                &format!("view{i:04}"),
                eye,
                target,
                -DVec3::Y,
                width,
                height,
                70.0,
            )
        })
        .collect()
}

/// One timed forward render of `cams`: binning and RGB blending, as `Rasterizer::render`
/// records them, without downloading the images (accumulation downloads nothing per view
/// either). A fresh rasterizer, as `accumulate` starts with, so buffer growth counts alike.
fn forward_run(
    gpu: &Gpu,
    scene: &GpuScene,
    cams: &[Camera],
    opts: &RenderOptions,
    mut progress: impl FnMut(usize),
) -> Result<RunTotal> {
    let start = Instant::now();
    let mut raster = Rasterizer::new(gpu);
    let mut total = RunTotal::default();
    for (i, cam) in cams.iter().enumerate() {
        progress(i);
        let run =
            raster.run_tiled_in_bands(scene, cam, opts, BandWork::Overwrite, |rec, tiles| {
                tiles.record_blend(rec)
            })?;
        total.add(run.timings.total_ns() * 1e-6, 0.0, gpu.memory_reserved());
        run.timings.add_to(&mut total.kernels);
        total.visible += f64::from(run.visible);
        total.intersections += f64::from(run.intersections);
    }
    progress(cams.len());
    total.wall_s = start.elapsed().as_secs_f64();
    Ok(total)
}

/// Times the forward render and each of `methods` over `spec.views` views of a random
/// scene, taking turns on each timed run. `progress(phase, done, total)` counts views over
/// all phases ("forward render" or the method's name).
pub fn bench_fuse(
    gpu: &Gpu,
    spec: &FuseBenchSpec,
    methods: &[Method],
    progress: impl FnMut(&str, usize, usize),
) -> Result<FuseBench> {
    check_spec(gpu, spec, methods)?;
    let (g, cams, labels) = scene_and_cameras(spec)?;
    let spec = &FuseBenchSpec {
        n: g.len(),
        views: cams.len(),
        width: cams[0].width,
        height: cams[0].height,
        classes: labels.classes(),
        ..spec.clone()
    };
    let opts = FuseConfig::default().render_options();
    let neighbours_start = Instant::now();
    let knn = nearest_neighbours(&g.means, TIE_NEIGHBOURS);
    let neighbours_s = neighbours_start.elapsed().as_secs_f64();
    if let Some(dir) = &spec.export {
        let source = labels.source();
        let classes = spec.classes;
        export_inputs(
            dir,
            &g,
            &cams,
            &opts,
            Some(ExportLabels { source, classes }),
        )?;
    }
    // Each method reads only its attributes (no SH colour, or only the centers), as `fuse`
    // uploads them; the forward render reads all.
    let scene = GpuScene::upload(gpu, &g)?;
    let method_scenes = methods
        .iter()
        .map(|m| GpuScene::upload_for(gpu, &g, m.scene_attributes()))
        .collect::<Result<Vec<_>, _>>()?;
    drop(g);
    let setup = Setup {
        gpu,
        scene: &scene,
        method_scenes: &method_scenes,
        cams,
        labels,
        classes: spec.classes,
        knn,
        opts,
        cfgs: methods
            .iter()
            .map(|&method| FuseConfig {
                method,
                views_in_flight: spec.views_in_flight,
                clustering: spec.clustering,
                ..Default::default()
            })
            .collect(),
    };
    setup.warm_up()?;
    let (forward_runs, method_runs) = setup.timed_runs(spec.iters, progress)?;
    let forward = forward_bench(&forward_runs, spec.views);
    let results = methods
        .iter()
        .zip(&method_runs)
        .zip(&method_scenes)
        .map(|((&method, runs), scene)| {
            method_bench(method, runs, &forward, spec.views, scene.device_bytes())
        })
        .collect();
    Ok(FuseBench {
        spec: spec.clone(),
        device: gpu.caps().name.clone(),
        goal_ratio: GOAL_RATIO,
        forward,
        methods: results,
        peak_host_bytes: crate::util::memory::peak_host_bytes(),
        host_threads: crate::util::cores(),
        neighbours_s,
    })
}

/// The random scene (SH degree 3 as a trained 3DGS scene, and `bench render`: projection
/// evaluates it) on its ring of cameras, or the folder's scene and first cameras; their
/// label maps.
fn scene_and_cameras(spec: &FuseBenchSpec) -> Result<(Gaussians, Vec<Camera>, BenchLabels)> {
    let blocks = || BenchLabels::Blocks(BlockLabels::new(spec.classes, spec.seed));
    let Some(dir) = &spec.scene else {
        let g = random_scene(&RandomSceneSpec {
            n: spec.n,
            sh_degree: 3,
            seed: spec.seed,
            ..Default::default()
        });
        let cams = ring_cameras(spec.views, spec.width, spec.height);
        return Ok((g, cams, blocks()));
    };
    let (g, cams) = super::read_scene_folder(dir)?;
    let Some(labels) = &spec.labels else {
        let cams = cams.iter().take(spec.views);
        let cams = cams.map(|c| c.scaled_to(spec.width, spec.height)).collect();
        return Ok((g, cams, blocks()));
    };
    // The cameras again, matched to the maps (and scaled to them where they are resized).
    let mut dataset = Dataset::open(&DatasetPaths {
        cameras: &dir.join(CAMERAS_FILE),
        labels,
        class_table: None,
        train_only: false,
        format: LabelFormat::default(),
    })?;
    dataset.cameras.truncate(spec.views);
    let cams = dataset.cameras.clone();
    ensure!(
        cams.iter()
            .all(|c| (c.width, c.height) == (cams[0].width, cams[0].height)),
        "the label maps of {} differ in size; the benchmark's views share one",
        labels.display()
    );
    Ok((g, cams, BenchLabels::Scene(Box::new(dataset))))
}

/// The label maps a benchmark fuses.
enum BenchLabels {
    /// Random blocks, drawn for each view ([`BlockLabels`]).
    Blocks(BlockLabels),
    /// The scene folder's own maps, matched to its cameras by name.
    Scene(Box<Dataset>),
}

impl BenchLabels {
    fn source(&self) -> &dyn LabelSource {
        match self {
            BenchLabels::Blocks(blocks) => blocks,
            BenchLabels::Scene(dataset) => dataset.as_ref(),
        }
    }

    /// Rows of the evidence matrix: the spec's classes, or those the maps hold.
    fn classes(&self) -> usize {
        match self {
            BenchLabels::Blocks(blocks) => blocks.classes as usize,
            BenchLabels::Scene(dataset) => dataset.classes.len(),
        }
    }
}

/// Refuses specs the benchmark cannot run or measure.
fn check_spec(gpu: &Gpu, spec: &FuseBenchSpec, methods: &[Method]) -> Result<()> {
    ensure!(spec.n > 0, "--n must be at least 1 Gaussian");
    ensure!(
        spec.n <= u32::MAX as usize,
        "--n must be below 2^32 Gaussians"
    );
    ensure!(spec.views > 0, "--views must be at least 1");
    ensure!(
        spec.width > 0 && spec.height > 0,
        "--width and --height must be at least 1 pixel"
    );
    ensure!(
        (1..=MAX_CLASSES).contains(&spec.classes),
        "--classes must lie in 1..={MAX_CLASSES}, got {}",
        spec.classes
    );
    ensure!(spec.iters > 0, "--iters must be at least 1");
    ensure!(!methods.is_empty(), "no fusion method to run");
    ensure!(
        gpu.caps().timestamps,
        "the device has no timestamp queries; GPU time cannot be measured"
    );
    Ok(())
}

/// What every timed run works on.
struct Setup<'a> {
    gpu: &'a Gpu,
    /// The whole scene, for the forward render.
    scene: &'a GpuScene,
    /// Per method, what of the scene it reads.
    method_scenes: &'a [GpuScene],
    cams: Vec<Camera>,
    labels: BenchLabels,
    classes: usize,
    /// [n][TIE_NEIGHBOURS] nearest neighbours, for the assignment's tie-breaks.
    knn: Vec<u32>,
    opts: RenderOptions,
    /// One per method.
    cfgs: Vec<FuseConfig>,
}

impl Setup<'_> {
    /// Runs everything on the first view once, compiling the pipelines, so no timed run
    /// pays for them.
    fn warm_up(&self) -> Result<()> {
        forward_run(self.gpu, self.scene, &self.cams[..1], &self.opts, |_| {})?;
        for (cfg, scene) in self.cfgs.iter().zip(self.method_scenes) {
            self.fuse(cfg, scene, &self.cams[..1], |_| {})?;
        }
        Ok(())
    }

    /// One method over `cams`, accumulated and assigned as `fuse` does it.
    fn fuse(
        &self,
        cfg: &FuseConfig,
        scene: &GpuScene,
        cams: &[Camera],
        mut progress: impl FnMut(usize),
    ) -> Result<crate::fuse::FuseStats> {
        let with = AssignOnGpu {
            knn: Some(TieNeighbours::Found(&self.knn, TIE_NEIGHBOURS)),
            rows: None,
        };
        let (_, stats) = accumulate_assigned(
            self.gpu,
            scene,
            cams,
            self.labels.source(),
            self.classes,
            cfg,
            with,
            |d, _| progress(d),
        )?;
        Ok(stats)
    }

    /// `iters` timed runs of the forward render and of every method, each over all views
    /// at once as `fuse` does it (one rasterizer, one evidence matrix). They take turns on
    /// each iteration, so a slow spell of a shared machine slows them alike.
    fn timed_runs(
        &self,
        iters: usize,
        mut progress: impl FnMut(&str, usize, usize),
    ) -> Result<(Vec<RunTotal>, Vec<Vec<RunTotal>>)> {
        let methods = self.cfgs.len();
        let views = self.cams.len();
        let total = iters * views * (1 + methods);
        let mut done = 0;
        let mut forward_runs = Vec::with_capacity(iters);
        let mut method_runs: Vec<Vec<RunTotal>> = vec![Vec::with_capacity(iters); methods];
        for _ in 0..iters {
            let forward = forward_run(self.gpu, self.scene, &self.cams, &self.opts, |d| {
                progress("forward render", done + d, total)
            })?;
            done += views;
            forward_runs.push(forward);
            let runs = self.cfgs.iter().zip(self.method_scenes);
            for ((cfg, scene), method) in runs.zip(&mut method_runs) {
                let stats = self.fuse(cfg, scene, &self.cams, |d| {
                    progress(cfg.method.name(), done + d, total)
                })?;
                done += views;
                method.push(RunTotal {
                    gpu_ms: stats.gpu_ms,
                    wall_s: stats.wall_s,
                    label_wait_s: stats.label_wait_s,
                    label_read_s: stats.label_read_s,
                    label_stage_s: stats.label_stage_s,
                    view_s: stats.view_s,
                    evidence_s: stats.evidence_s,
                    segments_s: stats.segments_s,
                    decide_s: stats.decide_s,
                    observe: stats.observe,
                    clustering: stats.clustering,
                    decision: stats.decision,
                    kernels: stats.kernels,
                    peak_device_bytes: stats.peak_device_bytes,
                    passes: stats.passes,
                    rows_per_pass: stats.rows_per_pass,
                    views_in_flight: stats.views_in_flight,
                    ..Default::default()
                });
            }
        }
        Ok((forward_runs, method_runs))
    }
}

/// The forward render's medians over `runs` of `views` views.
fn forward_bench(runs: &[RunTotal], views: usize) -> ForwardBench {
    let forward = RunTotal::median(runs);
    let n_views = views as f64;
    let last = runs.last().expect("at least one run");
    ForwardBench {
        gpu_ms: forward.gpu_ms,
        wall_s: forward.wall_s,
        views_per_s: n_views / forward.wall_s,
        visible_per_view: last.visible / n_views,
        intersections_per_view: last.intersections / n_views,
        peak_device_bytes: forward.peak_device_bytes,
        kernels: forward.kernels,
    }
}

/// A method's medians over `runs`, and their ratios to the forward render's.
fn method_bench(
    method: Method,
    runs: &[RunTotal],
    forward: &ForwardBench,
    views: usize,
    scene_device_bytes: u64,
) -> MethodBench {
    let m = RunTotal::median(runs);
    MethodBench {
        method: method.name(),
        key: method.key(),
        wall_s: m.wall_s,
        gpu_ms: m.gpu_ms,
        label_wait_s: m.label_wait_s,
        label_read_s: m.label_read_s,
        label_stage_s: m.label_stage_s,
        view_s: m.view_s,
        evidence_s: m.evidence_s,
        segments_s: m.segments_s,
        decide_s: m.decide_s,
        observe: m.observe,
        clustering: m.clustering,
        decision: m.decision,
        views_per_s: (views * m.passes) as f64 / m.wall_s,
        passes: m.passes,
        rows_per_pass: m.rows_per_pass,
        views_in_flight: m.views_in_flight,
        peak_device_bytes: m.peak_device_bytes,
        scene_device_bytes,
        gpu_ratio: m.gpu_ms / forward.gpu_ms,
        kernels: m.kernels,
        wall_ratio: m.wall_s / forward.wall_s,
    }
}

/// Time and memory of one run over all views; for the forward render also the visible
/// Gaussians and tile intersections.
#[derive(Clone, Debug, Default)]
struct RunTotal {
    gpu_ms: f64,
    wall_s: f64,
    /// Host seconds waiting for label maps and running the views (methods only; the last
    /// run's).
    label_wait_s: f64,
    label_read_s: f64,
    label_stage_s: f64,
    view_s: f64,
    evidence_s: f64,
    segments_s: f64,
    decide_s: f64,
    observe: ObserveTimes,
    clustering: ClusterProfile,
    decision: DecideProfile,
    kernels: Vec<KernelTotal>,
    peak_device_bytes: u64,
    passes: usize,
    rows_per_pass: usize,
    views_in_flight: usize,
    visible: f64,
    intersections: f64,
}

impl RunTotal {
    fn add(&mut self, gpu_ms: f64, wall_s: f64, peak: u64) {
        self.gpu_ms += gpu_ms;
        self.wall_s += wall_s;
        self.peak_device_bytes = self.peak_device_bytes.max(peak);
    }

    /// GPU and wall time each the median over the runs; the largest memory peak.
    fn median(runs: &[RunTotal]) -> RunTotal {
        RunTotal {
            gpu_ms: median(&mut runs.iter().map(|r| r.gpu_ms).collect::<Vec<_>>()),
            wall_s: median(&mut runs.iter().map(|r| r.wall_s).collect::<Vec<_>>()),
            peak_device_bytes: runs.iter().map(|r| r.peak_device_bytes).max().unwrap_or(0),
            ..runs.last().cloned().unwrap_or_default()
        }
    }
}
