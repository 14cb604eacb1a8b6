//! `semsplat train`: joint optimization of geometry, appearance and semantic logits
//! (Gaussian Semantics, docs/papers.md), or of the logits alone (`--semantics-only`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;

use super::args;
use super::progress::iterations_bar;
use super::run_paths::identity;
use super::{check_outputs, open_dataset, write_scene_with_table, Input, FRAME_HINT};
use semsplat::dataset::{user_classes, CompactClasses, Dataset, DatasetPaths};
use semsplat::gpu::Gpu;
use semsplat::render::SemanticMode;
use semsplat::scene::images::ImageDir;
use semsplat::scene::ply::{classes_sidecar_path, every_scenes_vertex_bytes};
use semsplat::scene::scene_file::{
    cameras_for_scene, read_scene, read_scene_or_point_cloud, resolve_scene_path,
};
use semsplat::scene::Gaussians;
use semsplat::train::config::TrainConfig;
use semsplat::train::trainer::{
    classes_from_logits, with_initial_logits, with_logits_from_classes, DensifyEvent, LogitInit,
    StageTotals, Trainer, FUSED_DEFAULT_CONF,
};
use semsplat::train::views::TrainView;
use semsplat::util::free_space::short_of_room;
use semsplat::util::{
    check_output_file, interrupt, parallel_map_on, resolve_output_file, write_bytes_atomic,
};

#[derive(Args)]
pub struct TrainArgs {
    /// Folder of RGB images (PNG or JPEG, the extension in any case) named like the cameras
    /// (<image name>.png); an image with alpha is composited over black, 3DGS's default.
    /// Optional with --semantics-only, whose frozen colours learn nothing from them: given,
    /// the log's L1, SSIM and PSNR compare the scene's renders with them (a check of the
    /// cameras); left out, those read null and no image is read.
    #[arg(long, required_unless_present = "semantics_only")]
    images: Option<PathBuf>,
    /// Folder of label PNGs (gray or palette class ids, or colour-coded through the class
    /// table; see --ignore-id and docs/label-maps.md) named like the cameras. Views without
    /// a label map train appearance only.
    #[arg(long)]
    labels: PathBuf,
    /// Cameras: COLMAP model folder, INRIA cameras.json, nerfstudio transforms.json or semsplat cameras.json. Default:
    /// the cameras.json of --init's folder (a `synth` room, an INRIA run).
    #[arg(long)]
    cameras: Option<PathBuf>,
    /// Initial scene: a 3DGS PLY (a trained scene, or a synth room's init.ply), compressed PLY,
    /// .splat, .spz, INRIA run folder or scene folder (its scene.ply), or a plain point-cloud PLY such as an SfM input.ply
    /// (x y z [red green blue]), seeded into Gaussians as INRIA 3DGS does. Its logits, if any, are replaced by
    /// new ones over the classes present in the labels (--logit-init).
    #[arg(long)]
    init: PathBuf,
    /// How the logits start (without --init-semantics-from): `uniform` (zeros) or `random`
    /// (Gaussian Semantics' small random values). Default: uniform with --semantics-only,
    /// random otherwise. Random logits, with the entropy term under Adam, leave Gaussians
    /// the cross-entropy reaches late at their random first choice (--semantics-only on the
    /// demo room: held-out mIoU 0.932 -> 0.943 uniform); with the geometry trained too, those
    /// wrong, sharpened logits drive its densification early (uniform there: higher mIoU,
    /// lower PSNR, mostly lower per-Gaussian accuracy, measured; docs/joint-training.md)
    #[arg(long, value_enum, conflicts_with = "init_semantics_from")]
    logit_init: Option<LogitStart>,
    /// Iterations (one view each). The densification schedule (500..15000 every 100, the
    /// interval at least 10) and the entropy warm-up follow 3DGS's 30k schedule scaled to
    /// this; the opacity reset stays every 3000 iterations.
    #[arg(long, default_value_t = 30_000, value_parser = args::at_least_one::<u32>)]
    iters: u32,
    /// Output PLY: the trained Gaussians with their logits (sem_0..sem_{C-1}), `class` (label id,
    /// -1 for Gaussians no view sees or whose top logits training left tied) and `class_conf`
    /// (softmax probability of the class).
    #[arg(long)]
    out: PathBuf,
    /// Train the semantic logits only: geometry and colors stay as in --init (fast; a
    /// middle point between fusion and full training). Views without a label map are left
    /// out (they would teach nothing).
    #[arg(long)]
    semantics_only: bool,
    /// Blend softmax(logits) instead of the raw logits (Gaussian Semantics' ablation).
    #[arg(long)]
    softmax: bool,
    /// Weight of the semantic cross-entropy (Gaussian Semantics: 1; >= 0).
    #[arg(long, default_value_t = 1.0, value_parser = args::non_negative::<f32>)]
    lambda_sem: f32,
    /// Weight of the per-Gaussian entropy regularizer (Gaussian Semantics: 0.01; 0 turns it off).
    #[arg(long, default_value_t = 0.01, value_parser = args::non_negative::<f32>)]
    lambda_entropy: f32,
    /// Iterations over which the entropy weight grows from 0 (default: 5000 of 30000,
    /// scaled to --iters).
    #[arg(long)]
    entropy_warmup: Option<u32>,
    /// Learning rate of the semantic logits (Adam; > 0).
    #[arg(long, default_value_t = 0.05, value_parser = args::positive::<f64>)]
    lr_logits: f64,
    /// Never grow the model past this many Gaussians.
    #[arg(long, default_value_t = 3_000_000, value_parser = args::at_least_one::<u32>)]
    max_gaussians: u32,
    /// No densification or pruning.
    #[arg(long)]
    no_densify: bool,
    /// Start the semantic logits where a fusion of --init ended: a PLY that `semsplat fuse`
    /// wrote for the same scene (its `class` and `class_conf` per Gaussian; any method; a
    /// PLY with `class` alone, such as a synth scene.ply, starts each class at one fixed
    /// confidence, which a note gives).
    /// Each Gaussian's logits then give its fused class its fused confidence; unseen ones
    /// start uniform, and a class at confidence 0 (segment consensus's Gaussians no view
    /// saw, which took their neighbours' class) with a slight lean to it (twice each other
    /// class's probability). With --semantics-only, training refines the fused labels.
    #[arg(long, value_name = "PLY")]
    init_semantics_from: Option<PathBuf>,
    /// Class table (JSON: id, name, color). Default: classes.json beside or inside the
    /// label folder.
    #[arg(long)]
    classes: Option<PathBuf>,
    #[command(flatten)]
    label_format: super::LabelFormatArgs,
    /// Train on the cameras marked "train" only (semsplat cameras.json).
    #[arg(long)]
    train_only: bool,
    /// Write the model every this many iterations beside --out, its name's stem followed by
    /// .iter<N>.ply (--out trained.ply: trained.iter5000.ply).
    #[arg(long, value_parser = args::at_least_one::<u32>)]
    checkpoint_every: Option<u32>,
    /// JSON report: configuration, losses over time, stage times, densification.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Seed of every random choice (initial logits, view order, densification). The same
    /// inputs and seed give the same bytes only with --deterministic (the default float
    /// atomics add gradients in the order the GPU runs them)
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Sum gradients as order-independent 64-bit fixed point, so the same inputs and seed
    /// give the same bytes on the same device and driver (off by default: the backward
    /// costs about 3x on lavapipe; the default float atomics let runs differ slightly)
    #[arg(long)]
    deterministic: bool,
}

/// `--logit-init`'s values.
#[derive(Clone, Copy, ValueEnum)]
enum LogitStart {
    Uniform,
    Random,
}

/// The logits' start: `--logit-init`, else the mode's default.
fn logit_init(args: &TrainArgs) -> LogitInit {
    match args.logit_init {
        Some(LogitStart::Uniform) => LogitInit::Uniform,
        Some(LogitStart::Random) => LogitInit::SmallRandom,
        None => LogitInit::default_for(args.semantics_only),
    }
}

#[derive(Serialize)]
struct LogLine {
    iteration: u32,
    gaussians: u32,
    /// The photometric values: None (null) without --images.
    l1: Option<f32>,
    ssim: Option<f32>,
    psnr: Option<f32>,
    /// None (null) on a view without labels: it has no cross-entropy, and a 0 would read
    /// as a perfect one.
    ce: Option<f32>,
    entropy: f32,
}

impl LogLine {
    /// The progress bar's message: "-" for a value the line lacks.
    fn summary(&self) -> String {
        let shown =
            |v: Option<f32>, digits: usize| v.map_or("-".into(), |v| format!("{v:.digits$}"));
        let ce = shown(self.ce, 3);
        let h = self.entropy;
        match self.l1 {
            Some(l1) => format!(
                "L1 {l1:.4} SSIM {} CE {ce} H {h:.3} PSNR {} dB, {} Gaussians",
                shown(self.ssim, 3),
                shown(self.psnr, 2),
                self.gaussians
            ),
            None => format!("CE {ce} H {h:.3}, {} Gaussians", self.gaussians),
        }
    }
}

#[derive(Serialize)]
struct TrainReport<'a> {
    config: &'a TrainConfig,
    /// How the logits started: "uniform", "random" or "fusion" (--init-semantics-from).
    logits_start: &'static str,
    views: usize,
    classes: usize,
    initial_gaussians: usize,
    final_gaussians: usize,
    seconds: f64,
    iterations_per_second: f64,
    /// GPU milliseconds per iteration, by stage.
    stage_ms_per_iteration: StageTotals,
    log: Vec<LogLine>,
    densify: Vec<DensifyEvent>,
}

pub fn run(args: TrainArgs) -> Result<()> {
    let start = Instant::now();
    check_paths(&args)?;
    // The logits learn from the cross-entropy alone there (the entropy term sharpens what
    // it gives them): without it the run would write the scene it started from.
    ensure!(
        !(args.semantics_only && args.lambda_sem == 0.0),
        "--semantics-only with --lambda-sem 0 trains nothing (the logits learn from the label \
         maps' cross-entropy): give --lambda-sem > 0, or leave out --semantics-only"
    );
    let data = load_dataset(&args)?;
    let views = train_views(&args, &data)?;
    let init = read_scene_or_point_cloud(&args.init)?;
    let logits_start = logit_init(&args);
    let init = match &args.init_semantics_from {
        Some(fused) => logits_from_fusion(&init, fused, &data.classes)?,
        None => with_initial_logits(&init, data.classes.len(), logits_start, args.seed),
    };
    let cfg = train_config(&args, init.len())?;
    warn_if_short_of_room(&args, &init);

    let gpu = Gpu::new()?;
    let mut trainer = Trainer::new(&gpu, &init, &views, cfg.clone(), &[])?;
    // Training on views that see nothing would run to the end and write an untouched scene.
    ensure!(
        trainer.some_view_sees_a_gaussian()?,
        "no training view sees any of --init's {} Gaussians. {FRAME_HINT}",
        init.len()
    );
    eprintln!(
        "training {} iterations on {} views from {} Gaussians (Ctrl-C stops without writing --out)",
        args.iters,
        views.len(),
        init.len()
    );
    let log = train_loop(&args, &data, &mut trainer)?;
    let out = trainer.finish()?;
    let per_iter = per_iteration(&out.times);
    let g = write_trained(&args.out, out.gaussians, &out.seen, &args, &data)?;

    let seconds = start.elapsed().as_secs_f64();
    eprintln!(
        "trained {} iterations in {seconds:.1} s: {} -> {} Gaussians; GPU ms per iteration: forward {:.1}, loss {:.1}, backward {:.1}, optimizer {:.1}, densify {:.1}",
        out.times.iterations,
        init.len(),
        g.len(),
        per_iter.forward_ms,
        per_iter.loss_ms,
        per_iter.backward_ms,
        per_iter.optimizer_ms,
        per_iter.densify_ms
    );
    if let Some(path) = &args.report {
        let report = TrainReport {
            config: &cfg,
            logits_start: match (&args.init_semantics_from, logits_start) {
                (Some(_), _) => "fusion",
                (None, LogitInit::Uniform) => "uniform",
                (None, LogitInit::SmallRandom) => "random",
            },
            views: views.len(),
            classes: data.classes.len(),
            initial_gaussians: init.len(),
            final_gaussians: g.len(),
            seconds,
            iterations_per_second: out.times.iterations.max(1) as f64 / seconds.max(1e-9),
            stage_ms_per_iteration: per_iter,
            log,
            densify: out.densify_events,
        };
        write_bytes_atomic(path, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(())
}

/// `init` with logits from the fused classes of `fused` (see --init-semantics-from), which
/// must hold the same Gaussians.
fn logits_from_fusion(
    init: &Gaussians,
    fused: &Path,
    classes: &CompactClasses,
) -> Result<Gaussians> {
    let f = read_scene(fused)?;
    ensure!(
        f.len() == init.len(),
        "--init-semantics-from {}: its {} Gaussians are not --init's {} (fuse the scene you \
         train from, and train from that scene)",
        fused.display(),
        f.len(),
        init.len()
    );
    if let Some(i) = (0..f.len()).find(|&i| f.means[i] != init.means[i]) {
        bail!(
            "--init-semantics-from {}: its Gaussian {i} lies at {:?}, --init's at {:?}: not the \
             scene --init holds (fuse the scene you train from, and train from that scene)",
            fused.display(),
            f.means[i],
            init.means[i]
        );
    }
    let Some(ids) = &f.class_ids else {
        bail!(
            "--init-semantics-from {} has no `class` property (write it with `semsplat fuse`)",
            fused.display()
        );
    };
    let compact: Vec<Option<u32>> = ids
        .iter()
        .map(|&id| {
            u32::try_from(id)
                .ok()
                .and_then(|id| classes.compact_of(id))
                .map(u32::from)
        })
        .collect();
    // A fused class the training labels lack has no logit: its Gaussians start uniform.
    let lost = (ids.iter().zip(&compact))
        .filter(|(&id, c)| id >= 0 && c.is_none())
        .count();
    if lost > 0 {
        eprintln!(
            "note: {lost} Gaussians of --init-semantics-from {} hold classes the training \
             labels lack (another class table?): they start uniform",
            fused.display()
        );
    }
    let conf = f.class_conf.as_deref();
    if conf.is_none() {
        eprintln!(
            "note: --init-semantics-from {} has no `class_conf` (not a `semsplat fuse` \
             output?): each Gaussian's class starts at confidence {FUSED_DEFAULT_CONF}",
            fused.display()
        );
    }
    Ok(with_logits_from_classes(
        init,
        &compact,
        conf,
        classes.len(),
    ))
}

/// The cameras, their label maps and the classes present (at least one).
fn load_dataset(args: &TrainArgs) -> Result<Dataset> {
    let paths = DatasetPaths {
        cameras: &cameras_for_scene(args.cameras.as_deref(), &args.init)?,
        labels: &args.labels,
        class_table: args.classes.as_deref(),
        train_only: args.train_only,
        format: args.label_format.format(),
    };
    // Appearance is frozen with --semantics-only: a view without labels would teach nothing
    // and take iterations.
    let skipped = match args.semantics_only {
        true => "are left out (--semantics-only learns from label maps alone)",
        false => "train appearance only",
    };
    let data = open_dataset(&paths, skipped)?;
    if data.classes.is_empty() {
        bail!("the label maps hold no class (every pixel is ignore)");
    }
    Ok(data)
}

/// Every camera with its image and, where it has a label map, its compact labels (with
/// --semantics-only the cameras with a label map alone), decoded on every core (hundreds of
/// 1080p images and maps take seconds on one); an error is the first failing view's.
fn train_views(args: &TrainArgs, data: &Dataset) -> Result<Vec<TrainView>> {
    let images = (args.images.as_deref()).map(|dir| {
        ImageDir::new(dir).with_scaled_cameras(data.labels.scaled_cameras(&data.cameras))
    });
    let trained: Vec<usize> = (0..data.cameras.len())
        .filter(|&i| !args.semantics_only || data.has_label_map(i))
        .collect();
    let view = |v: usize| -> Result<TrainView> {
        let i = trained[v];
        let camera = &data.cameras[i];
        Ok(TrainView {
            camera: camera.clone(),
            rgb: match &images {
                Some(images) => images.load(camera)?,
                None => Vec::new(),
            },
            labels: data.compact_labels(i)?.unwrap_or_default(),
        })
    };
    // On threads of the call's own: each keeps its decoder's buffer of samples until it ends.
    parallel_map_on(usize::MAX, trained.len(), view)
        .into_iter()
        .collect()
}

/// The schedule and weights the flags ask for, checked against the initial scene's size.
fn train_config(args: &TrainArgs, init_gaussians: usize) -> Result<TrainConfig> {
    let mut cfg = if args.semantics_only {
        TrainConfig::semantics_only(args.iters)
    } else {
        TrainConfig::new(args.iters)
    };
    cfg.semantic_mode = if args.softmax {
        SemanticMode::Softmax
    } else {
        SemanticMode::RawLogits
    };
    cfg.lambda_sem = args.lambda_sem;
    cfg.lambda_entropy = args.lambda_entropy;
    if let Some(w) = args.entropy_warmup {
        cfg.entropy_warmup = w;
    }
    cfg.lr.logits = args.lr_logits;
    cfg.seed = args.seed;
    cfg.deterministic = args.deterministic;
    if args.no_densify {
        cfg.densify = None;
    }
    if let Some(d) = &mut cfg.densify {
        d.max_gaussians = args.max_gaussians;
    }
    if init_gaussians > args.max_gaussians as usize {
        bail!(
            "--init has {} Gaussians, more than --max-gaussians {}",
            init_gaussians,
            args.max_gaussians
        );
    }
    Ok(cfg)
}

/// Warns where --out's file system has less room than the trained scene would take with
/// as many Gaussians as --init (a guess: densification adds and prunes): a full disk is
/// otherwise found at the write, after the whole run.
fn warn_if_short_of_room(args: &TrainArgs, init: &Gaussians) {
    let channels = init.semantics.as_ref().map_or(0, |s| s.channels);
    let vertex = every_scenes_vertex_bytes(init.sh_coeffs()) + 4 * channels;
    let about = (init.len() * vertex) as u64;
    let needs = "a trained scene of --init's Gaussians needs about";
    if let Some(short) = short_of_room("--out", &args.out, about, needs) {
        eprintln!("warning: {short}; the run may fail at its write");
    }
}

/// Runs every iteration with a progress bar, writing checkpoints; returns the loss log.
fn train_loop(args: &TrainArgs, data: &Dataset, trainer: &mut Trainer) -> Result<Vec<LogLine>> {
    let bar = iterations_bar(args.iters);
    let mut log = Vec::new();
    let photometric = args.images.is_some();
    for _ in 0..args.iters {
        interrupt::check()?;
        if let Some(l) = trainer.step()? {
            let line = LogLine {
                iteration: trainer.iteration(),
                gaussians: trainer.gaussian_count(),
                l1: photometric.then_some(l.l1),
                ssim: photometric.then_some(l.ssim),
                psnr: photometric.then_some(l.psnr()),
                ce: (l.labeled_pixels > 0).then_some(l.ce),
                entropy: l.entropy,
            };
            bar.set_message(line.summary());
            log.push(line);
        }
        bar.inc(1);
        if let Some(k) = args.checkpoint_every {
            let it = trainer.iteration();
            if it.is_multiple_of(k) && it < args.iters {
                let seen = trainer.seen_by_views()?;
                let path = checkpoint_path(&args.out, it);
                write_trained(&path, trainer.gaussians()?, &seen, args, data)?;
            }
        }
    }
    bar.finish();
    Ok(log)
}

/// Writes a trained model, as `--out` and its checkpoints are written: each Gaussian's class
/// from its logits and the class table beside it, so `render --semantics` and `eval` read a
/// checkpoint as they read the final scene. A Gaussian no view sees has no class, except
/// with --init-semantics-from: its logits are then the fusion's (or a clone's of one), not
/// a random start, and its fused class stands (segment consensus gives its hidden Gaussians
/// their neighbours' class: 657 of a tiny room's 24k lost theirs).
fn write_trained(
    path: &Path,
    mut g: Gaussians,
    seen: &[bool],
    args: &TrainArgs,
    data: &Dataset,
) -> Result<Gaussians> {
    let every = vec![true; g.len()];
    let classed = match args.init_semantics_from {
        Some(_) => &every,
        None => seen,
    };
    let (classes, conf) = classes_from_logits(&g, classed);
    g.class_ids = Some(user_classes(
        data.classes.user_ids(),
        classes.iter().map(|c| c.map(|c| c as usize)),
    ));
    g.class_conf = Some(conf);
    g.validate().with_context(|| {
        format!(
            "training diverged (nothing written to {}): lower the learning rates or the loss \
             weights, and look for extreme values in --init (`semsplat inspect` lists each \
             attribute's range)",
            path.display()
        )
    })?;
    write_scene_with_table(path, &g, &data.table)?;
    Ok(g)
}

/// GPU milliseconds per iteration, by stage.
fn per_iteration(t: &StageTotals) -> StageTotals {
    let iters = t.iterations.max(1) as f64;
    StageTotals {
        forward_ms: t.forward_ms / iters,
        loss_ms: t.loss_ms / iters,
        backward_ms: t.backward_ms / iters,
        optimizer_ms: t.optimizer_ms / iters,
        densify_ms: t.densify_ms / iters,
        iterations: t.iterations,
    }
}

/// Every output, checkpoints included, against the inputs and each other (before any work).
fn check_paths(args: &TrainArgs) -> Result<()> {
    let table = classes_sidecar_path(&args.out);
    check_outputs(
        &[
            ("--out", Some(&args.out)),
            ("--out's class table", Some(&table)),
            ("--report", args.report.as_deref()),
        ],
        &[],
        &[
            Input::Tree("--images", args.images.as_deref()),
            Input::Labels("--labels", Some(&args.labels)),
            Input::Cameras("--cameras", args.cameras.as_deref()),
            Input::Scene("--init", Some(&args.init)),
            Input::Scene("--init-semantics-from", args.init_semantics_from.as_deref()),
            Input::File("--classes", args.classes.as_deref()),
        ],
    )?;
    check_checkpoints(args)
}

/// No checkpoint (`<out>.iter<N>.ply` and its class table) may land on an input or the
/// report: resuming from a checkpoint under the same --out is the likely way.
fn check_checkpoints(args: &TrainArgs) -> Result<()> {
    let Some(every) = args.checkpoint_every else {
        return Ok(());
    };
    let init = resolve_scene_path(&args.init).unwrap_or_else(|_| args.init.clone());
    let others = [
        ("--init", Some(&init)),
        ("--init-semantics-from", args.init_semantics_from.as_ref()),
        ("--report", args.report.as_ref()),
        ("--classes", args.classes.as_ref()),
    ];
    for (option, path) in others.iter().filter_map(|(o, p)| Some((o, (*p)?))) {
        let written = (checkpoint_iteration(&args.out, path))
            .filter(|&n| n > 0 && n % every == 0 && n < args.iters);
        if let Some(n) = written {
            bail!(
                "{option} {} would be replaced by the checkpoint of iteration {n} \
                 (--checkpoint-every {every}): give --out another name",
                path.display()
            );
        }
    }
    // Each checkpoint a file that can be written (not a folder in its place), the last,
    // longest name short enough: found here, not at its iteration.
    let iterations: Vec<u32> = (every..args.iters).step_by(every as usize).collect();
    for &n in &iterations {
        let checkpoint = checkpoint_path(&args.out, n);
        for file in [classes_sidecar_path(&checkpoint), checkpoint] {
            resolve_output_file(&file).context("--checkpoint-every")?;
        }
    }
    if let Some(&last) = iterations.last() {
        check_output_file("--checkpoint-every", &checkpoint_path(&args.out, last))?;
    }
    Ok(())
}

/// A checkpoint of `out`: `<out's stem>.iter<N>.ply` beside it, its class table beside that.
fn checkpoint_path(out: &Path, iteration: u32) -> PathBuf {
    let stem = out.file_stem().unwrap_or_default().to_string_lossy();
    out.with_file_name(format!("{stem}.iter{iteration}.ply"))
}

/// The iteration whose checkpoint of `out` (or its class table) `path` is, if any.
fn checkpoint_iteration(out: &Path, path: &Path) -> Option<u32> {
    let name = path.file_name()?.to_str()?;
    let stem = out.file_stem()?.to_str()?;
    let number = (name.strip_prefix(stem)?.strip_prefix(".iter")?)
        .strip_suffix(".ply")
        .or_else(|| {
            name.strip_prefix(stem)?
                .strip_prefix(".iter")?
                .strip_suffix(".classes.json")
        })?;
    let n: u32 = number.parse().ok()?;
    let checkpoint = checkpoint_path(out, n);
    let same = |file: &Path| identity(file) == identity(path);
    (same(&checkpoint) || same(&classes_sidecar_path(&checkpoint))).then_some(n)
}
