//! Sharded fusion: `fuse --shard K/N` writes one shard's exact partial evidence, and
//! `semsplat merge` sums the parts of every shard, in chunks of Gaussians, into what a single
//! `fuse` of every view gives, then assigns and writes exactly as `fuse` does
//! (docs/sharded-fusion.md).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{ensure, Context, Result};
use clap::Args;

use super::fuse::{selected_class, write_fused, Evidence, OutputArgs, Provenance};
use super::progress::{follow, views_bar};
use super::{Input, Interruptible};
use semsplat::dataset::{load_split_cameras, Dataset};
use semsplat::fuse::partial::{
    cameras_digest, check_parts, manifest_path, FileDigest, Fnv64, FusionKey, PartReader,
    MANIFEST_FORMAT, MANIFEST_VERSION,
};
use semsplat::fuse::{
    accumulate_raw, Accumulation, ClassScores, EvidenceKind, FuseConfig, LabelSource, Method,
    PartManifest, RawEvidence, Shard,
};
use semsplat::gpu::Gpu;
use semsplat::render::GpuScene;
use semsplat::scene::scene_file::{cameras_for_scene, read_scene, resolve_scene_path};
use semsplat::scene::{Camera, Gaussians};

/// Gaussians summed at a time by default: 1M columns of every part (8 MB per class and part
/// for fixed point).
const CHUNK_GAUSSIANS: usize = 1 << 20;

/// `merge`'s own help for the output options it shares with `fuse`, whose text speaks of
/// what only `fuse` does (segment consensus, shards, a fused scene's class): the parts are
/// always vote counts or FlashSplat's evidence.
const OUT_HELP: &str = "Output PLY: the input Gaussians with `class` (label id, -1 for \
    Gaussians no view saw, or whose evidence tied and neither their neighbours' evidence nor \
    the whole scene's broke the tie) and `class_conf` (the winning class's share of the \
    evidence); semantics the input scene held (a trained scene's logits) are replaced. The \
    class table goes beside it, its `.ply` replaced (fused.ply: fused.classes.json)";
const REPORT_HELP: &str = "Write a JSON report: the method and accumulation the parts were \
    fused with, per-class counts (class -1: no class, as in --out) and the assignment's time";
const SAVE_CONTRIB_HELP: &str = "Write the merged evidence matrix A as float64 NumPy \
    [classes, Gaussians], rows in the order of FILE.classes.json written beside it (what \
    `fuse --save-contrib` of every view writes; `fuse --contrib` reads it). Each Gaussian's \
    class is its column's argmax";
const EXTRACT_HELP: &str = "Keep only the Gaussians of this class (name, any case, or id) in \
    --out, by FlashSplat's one-vs-rest assignment with --gamma (which may keep Gaussians whose \
    own class is another)";
const REMOVE_HELP: &str = "Drop the Gaussians of this class (name, any case, or id) from \
    --out (as --extract selects them)";

#[derive(Args)]
#[command(
    mut_arg("out", |a| a.help(OUT_HELP)),
    mut_arg("report", |a| a.help(REPORT_HELP)),
    mut_arg("save_contrib", |a| a.help(SAVE_CONTRIB_HELP)),
    mut_arg("extract", |a| a.help(EXTRACT_HELP)),
    mut_arg("remove", |a| a.help(REMOVE_HELP)),
)]
pub struct MergeArgs {
    /// Partial evidence of `fuse --shard K/N`, one per shard 0..N-1 in any order, each with
    /// its <part>.manifest.json beside it.
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// The scene PLY the parts were fused from (checked against their manifests' digest).
    #[arg(long)]
    scene: PathBuf,
    /// The cameras the parts were fused from: only needed by --render-views (checked
    /// against the manifests). Default there: the cameras.json of the scene's folder.
    #[arg(long)]
    cameras: Option<PathBuf>,
    /// Gaussians summed per chunk: memory is about parts x classes x this x 8 bytes.
    #[arg(long, default_value_t = CHUNK_GAUSSIANS, hide = true)]
    chunk_gaussians: usize,
    #[command(flatten)]
    output: OutputArgs,
}

/// One shard of `fuse`: what it fuses, and where the part goes.
pub struct ShardJob<'a> {
    pub scene_path: &'a Path,
    /// The cameras file, as given (its views may since be scaled to their label maps).
    pub cameras_path: &'a Path,
    pub gaussians: &'a Gaussians,
    pub data: &'a Dataset,
    pub cfg: FuseConfig,
    pub train_only: bool,
    pub shard: Shard,
    pub out: &'a Path,
}

/// The labels of a shard's views, by their position in the shard's camera list.
struct ShardLabels<'a> {
    data: &'a Dataset,
    views: &'a [usize],
}

impl LabelSource for ShardLabels<'_> {
    fn labels(&self, view: usize, _cam: &Camera) -> Result<Option<Vec<u32>>> {
        self.data.compact_labels(self.views[view])
    }
}

/// Fuses the shard's views and writes the part and its manifest.
pub fn fuse_shard(job: &ShardJob) -> Result<()> {
    let data = job.data;
    let labeled: Vec<usize> = (0..data.labels.len())
        .filter_map(|i| data.labels.camera_index(i))
        .collect();
    let views = job.shard.select(&labeled);
    let cams: Vec<Camera> = views.iter().map(|&v| data.cameras[v].clone()).collect();
    let key = fusion_key(job)?;
    let gpu = Gpu::new()?;
    let scene = GpuScene::upload_for(&gpu, job.gaussians, job.cfg.method.scene_attributes())?;
    let bar = views_bar(cams.len());
    let shard_labels = ShardLabels {
        data,
        views: &views,
    };
    let labels = Interruptible(&shard_labels);
    let (raw, stats) = accumulate_raw(
        &gpu,
        &scene,
        &cams,
        &labels,
        data.classes.len(),
        &job.cfg,
        follow(&bar),
    )?;
    bar.finish_and_clear();
    raw.save_npy(job.out, data.classes.len())?;
    let manifest = PartManifest {
        format: MANIFEST_FORMAT.into(),
        version: MANIFEST_VERSION,
        key,
        shard: job.shard,
        views: cams.iter().map(|c| c.name.clone()).collect(),
        data: FileDigest::of_file(job.out)?,
    };
    manifest.write(job.out)?;
    eprintln!(
        "shard {}: {} of {} labeled views in {:.2} s ({:.1} views/s, peak device memory \
         {:.1} MiB) -> {} (+ {})",
        job.shard,
        cams.len(),
        labeled.len(),
        stats.wall_s,
        stats.views_per_s,
        stats.peak_device_bytes as f64 / (1u64 << 20) as f64,
        job.out.display(),
        manifest_path(job.out).display()
    );
    Ok(())
}

/// What the shard was fused from, as its manifest names it.
fn fusion_key(job: &ShardJob) -> Result<FusionKey> {
    let data = job.data;
    let evidence = EvidenceKind::of(job.cfg.method, job.cfg.accumulation)
        .context("--shard needs exact (fixed-point) evidence; drop --float-atomics")?;
    let mut labels = Fnv64::default();
    for i in 0..data.labels.len() {
        let path = data.labels.path(i).context("label entry without a path")?;
        // The contents, not the size: a frame segmented again between two shards' runs
        // often keeps its size (a few hundred KB a map, read once more per shard).
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let name = data
            .labels
            .camera_index(i)
            .map_or("", |c| data.cameras[c].name.as_str());
        labels.update(name.as_bytes());
        labels.update(&[0]);
        labels.update(&(bytes.len() as u64).to_le_bytes());
        labels.update(&bytes);
    }
    Ok(FusionKey {
        scene: FileDigest::of_file(&resolve_scene_path(job.scene_path)?)?,
        gaussians: job.gaussians.len(),
        // The cameras as the file holds them, which `merge --cameras` is checked against:
        // `data`'s are scaled to label maps of another resolution.
        cameras: cameras_digest(&load_split_cameras(job.cameras_path, job.train_only)?),
        camera_count: data.cameras.len(),
        labels: labels.hex(),
        label_files: data.labels.len(),
        classes: data.table.clone(),
        method: job.cfg.method.key().into(),
        depth_tolerance: (job.cfg.method.reads_depth_tolerance())
            .then_some(job.cfg.depth_tolerance),
        train_only: job.train_only,
        evidence,
    })
}

pub fn run(mut args: MergeArgs) -> Result<()> {
    let start = Instant::now();
    if args.cameras.is_none() && args.output.render_views.is_some() {
        args.cameras = Some(cameras_for_scene(None, &args.scene)?);
    }
    let manifests: Vec<PathBuf> = args.parts.iter().map(|p| manifest_path(p)).collect();
    let inputs: Vec<Input> = (args.parts.iter().map(|p| Input::File("part", Some(p))))
        .chain(
            manifests
                .iter()
                .map(|m| Input::File("part's manifest", Some(m))),
        )
        .chain([
            Input::Scene("--scene", Some(&args.scene)),
            Input::Cameras("--cameras", args.cameras.as_deref()),
        ])
        .collect();
    super::fuse::check_output_args(&args.output, &[], &inputs, true)?;
    ensure!(
        args.chunk_gaussians > 0,
        "--chunk-gaussians must be positive"
    );
    let parts = args
        .parts
        .iter()
        .map(|p| Ok((p.clone(), PartManifest::read(p)?)))
        .collect::<Result<Vec<_>>>()?;
    let key = check_parts(&parts)?;
    let scene_file = resolve_scene_path(&args.scene)?;
    let scene_digest = FileDigest::of_file(&scene_file)?;
    ensure!(
        scene_digest == key.scene,
        "{} is not the scene the parts were fused from ({} bytes, FNV-1a {} vs {} bytes, {})",
        args.scene.display(),
        scene_digest.bytes,
        scene_digest.fnv1a64,
        key.scene.bytes,
        key.scene.fnv1a64
    );
    if let Some(cameras) = &args.cameras {
        let cams = load_split_cameras(cameras, key.train_only)?;
        ensure!(
            cameras_digest(&cams) == key.cameras,
            "{} are not the cameras the parts were fused from",
            cameras.display()
        );
    }
    // Before the parts are summed: a name no part's classes hold would fail at the end.
    selected_class(&args.output, &key.classes)?;
    let g = read_scene(&scene_file)?;
    let method = Method::from_key(&key.method)
        .with_context(|| format!("the parts name an unknown method '{}'", key.method))?;
    let scores = sum_parts(&parts, &key, args.chunk_gaussians)?;
    let evidence = Evidence::from_matrix(scores, &g, key.classes.clone());
    let provenance = Provenance {
        method: method.name(),
        // The parts' sums are exact: fixed point, or vote counts.
        accumulation: method
            .reads_accumulation()
            .then_some(Accumulation::FixedPoint),
        start,
    };
    write_fused(
        &args.output,
        args.cameras.as_deref(),
        g,
        evidence,
        &provenance,
    )
}

/// Sums the parts' integers chunk of Gaussians by chunk and converts each sum as `fuse`
/// converts its download: only one chunk of every part is in memory at a time.
fn sum_parts(
    parts: &[(PathBuf, PartManifest)],
    key: &FusionKey,
    chunk: usize,
) -> Result<ClassScores> {
    let (classes, n) = (key.classes.len(), key.gaussians);
    let mut readers = parts
        .iter()
        .map(|(p, _)| PartReader::open(p))
        .collect::<Result<Vec<_>>>()?;
    for (r, (path, manifest)) in readers.iter().zip(parts) {
        ensure!(
            (r.classes, r.n, r.kind) == (classes, n, key.evidence),
            "{} holds {:?} [{}, {}] but its manifest names {:?} [{classes}, {n}]",
            path.display(),
            r.kind,
            r.classes,
            r.n,
            key.evidence
        );
        // After the shape's checks, which name a part cut short as such.
        manifest.check_data(path)?;
    }
    let mut scores = ClassScores::zeros(classes, n);
    for begin in (0..n).step_by(chunk) {
        let len = chunk.min(n - begin);
        let mut sum = RawEvidence::zeros(key.evidence, classes * len);
        for r in &mut readers {
            sum.add(&r.read_columns(begin, len)?)?;
        }
        let values = sum.to_f64();
        for (row, chunk_row) in values.chunks_exact(len).enumerate() {
            scores.data[row * n + begin..row * n + begin + len].copy_from_slice(chunk_row);
        }
    }
    Ok(scores)
}
