//! `semsplat train`: joint optimization of geometry, appearance and semantic logits
//! (Gaussian Semantics, docs/papers.md), or of the logits alone (`--semantics-only`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use super::label_classes::{classes_in_labels, default_class_table};
use semsplat::gpu::Gpu;
use semsplat::render::SemanticMode;
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::classes::{read_class_table, CompactClasses};
use semsplat::scene::images::load_view_image;
use semsplat::scene::labels::{LabelDir, LabelMap, MissingLabels};
use semsplat::scene::ply::{read_ply, write_classes_sidecar, write_ply};
use semsplat::scene::Gaussians;
use semsplat::train::config::TrainConfig;
use semsplat::train::loss::IGNORE_LABEL;
use semsplat::train::trainer::{
    classes_from_logits, with_initial_logits, DensifyEvent, StageTotals, Trainer,
};
use semsplat::train::views::TrainView;
use semsplat::util::write_bytes_atomic;

#[derive(Args)]
pub struct TrainArgs {
    /// Folder of RGB images (PNG or JPEG) named like the cameras (<image name>.png).
    #[arg(long)]
    images: PathBuf,
    /// Folder of label PNGs (8/16-bit class ids, 255/65535 = no label) named like the
    /// cameras. Views without a label map train appearance only.
    #[arg(long)]
    labels: PathBuf,
    /// Cameras: COLMAP model folder, INRIA cameras.json or semsplat cameras.json.
    #[arg(long)]
    cameras: PathBuf,
    /// Initial scene (any 3DGS PLY: a trained scene, or an SfM point cloud converted to
    /// Gaussians such as a synth room's init.ply). Its logits, if any, are replaced by
    /// small random values over the classes present in the labels.
    #[arg(long)]
    init: PathBuf,
    /// Iterations (one view each). The densification schedule and the entropy warm-up
    /// follow 3DGS's 30k schedule scaled to this.
    #[arg(long, default_value_t = 30_000)]
    iters: u32,
    /// Output PLY: the trained Gaussians with their logits (f_sem_*), `class` (label id,
    /// -1 for Gaussians no view sees) and `class_conf` (softmax probability of the class).
    #[arg(long)]
    out: PathBuf,
    /// Train the semantic logits only: geometry and colors stay as in --init (fast; a
    /// middle point between fusion and full training).
    #[arg(long)]
    semantics_only: bool,
    /// Blend softmax(logits) instead of the raw logits (Gaussian Semantics' ablation).
    #[arg(long)]
    softmax: bool,
    /// Weight of the semantic cross-entropy (Gaussian Semantics: 1).
    #[arg(long, default_value_t = 1.0)]
    lambda_sem: f32,
    /// Weight of the per-Gaussian entropy regularizer (Gaussian Semantics: 0.01; 0 turns it off).
    #[arg(long, default_value_t = 0.01)]
    lambda_entropy: f32,
    /// Iterations over which the entropy weight grows from 0 (default: 5000 of 30000,
    /// scaled to --iters).
    #[arg(long)]
    entropy_warmup: Option<u32>,
    /// Learning rate of the semantic logits (Adam).
    #[arg(long, default_value_t = 0.05)]
    lr_logits: f64,
    /// Never grow the model past this many Gaussians.
    #[arg(long, default_value_t = 3_000_000)]
    max_gaussians: u32,
    /// No densification or pruning.
    #[arg(long)]
    no_densify: bool,
    /// Class table (JSON: id, name, color). Default: classes.json beside or inside the
    /// label folder.
    #[arg(long)]
    classes: Option<PathBuf>,
    /// Train on the cameras marked "train" only (semsplat cameras.json).
    #[arg(long)]
    train_only: bool,
    /// Write the model every this many iterations to <out>.iter<N>.ply.
    #[arg(long)]
    checkpoint_every: Option<u32>,
    /// JSON report: configuration, losses over time, stage times, densification.
    #[arg(long)]
    report: Option<PathBuf>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(Serialize)]
struct LogLine {
    iteration: u32,
    gaussians: u32,
    l1: f32,
    ssim: f32,
    psnr: f32,
    ce: f32,
    entropy: f32,
}

#[derive(Serialize)]
struct TrainReport<'a> {
    config: &'a TrainConfig,
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

fn compact_labels(map: &LabelMap, compact: &CompactClasses) -> Vec<u32> {
    map.labels
        .iter()
        .map(|&l| {
            if l == LabelMap::IGNORE {
                IGNORE_LABEL
            } else {
                compact.compact_of(l as u32).map_or(IGNORE_LABEL, u32::from)
            }
        })
        .collect()
}

pub fn run(args: TrainArgs) -> Result<()> {
    let start = Instant::now();
    let mut cams = load_cameras(&args.cameras)?;
    if args.train_only {
        cams.retain(|c| c.split == semsplat::scene::Split::Train);
        if cams.is_empty() {
            bail!("{} has no train cameras", args.cameras.display());
        }
    }
    let table_path = args
        .classes
        .clone()
        .or_else(|| default_class_table(&args.labels));
    let given = table_path.as_deref().map(read_class_table).transpose()?;
    let dir = LabelDir::open(&args.labels, &cams, given.as_ref(), MissingLabels::Skip)?;
    if dir.is_empty() {
        bail!(
            "no label map in {} matches a camera name",
            args.labels.display()
        );
    }
    if !dir.skipped().is_empty() {
        eprintln!(
            "note: {} views have no label map and train appearance only",
            dir.skipped().len()
        );
    }
    let (compact, table) = classes_in_labels(&dir, given.as_ref())?;
    if compact.is_empty() {
        bail!("the label maps hold no class (every pixel is ignore)");
    }
    let mut label_of_camera = vec![None; cams.len()];
    for i in 0..dir.len() {
        if let Some(c) = dir.camera_index(i) {
            label_of_camera[c] = Some(i);
        }
    }
    let views = cams
        .iter()
        .zip(&label_of_camera)
        .map(|(cam, entry)| {
            Ok(TrainView {
                camera: cam.clone(),
                rgb: load_view_image(&args.images, cam)?,
                labels: match entry {
                    Some(i) => compact_labels(&dir.load(*i)?, &compact),
                    None => Vec::new(),
                },
            })
        })
        .collect::<Result<Vec<_>>>()?;

    let init = read_ply(&args.init)?;
    let init = with_initial_logits(&init, compact.len(), args.seed);
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
    if args.no_densify {
        cfg.densify = None;
    }
    if let Some(d) = &mut cfg.densify {
        d.max_gaussians = args.max_gaussians;
    }
    if init.len() > args.max_gaussians as usize {
        bail!(
            "--init has {} Gaussians, more than --max-gaussians {}",
            init.len(),
            args.max_gaussians
        );
    }

    let gpu = Gpu::new()?;
    let mut trainer = Trainer::new(&gpu, &init, &views, cfg.clone(), &[])?;
    let bar = ProgressBar::new(args.iters as u64).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} it {per_sec} eta {eta} {msg}")
            .expect("valid template"),
    );
    let mut log = Vec::new();
    for _ in 0..args.iters {
        if let Some(l) = trainer.step()? {
            let line = LogLine {
                iteration: trainer.iteration(),
                gaussians: trainer.gaussian_count(),
                l1: l.l1,
                ssim: l.ssim,
                psnr: l.psnr(),
                ce: l.ce,
                entropy: l.entropy,
            };
            bar.set_message(format!(
                "L1 {:.4} SSIM {:.3} CE {:.3} H {:.3} PSNR {:.2} dB, {} Gaussians",
                line.l1, line.ssim, line.ce, line.entropy, line.psnr, line.gaussians
            ));
            log.push(line);
        }
        bar.inc(1);
        if let Some(k) = args.checkpoint_every {
            let it = trainer.iteration();
            if k > 0 && it % k == 0 && it < args.iters {
                let path = checkpoint_path(&args.out, it);
                write_ply(&path, &trainer.gaussians()?)?;
            }
        }
    }
    bar.finish();
    let out = trainer.finish()?;
    let mut g: Gaussians = out.gaussians;
    let (classes, conf) = classes_from_logits(&g, &out.seen);
    g.class_ids = Some(
        classes
            .iter()
            .map(|c| {
                c.and_then(|c| compact.user_of(c as usize))
                    .map_or(-1, |u| u as i32)
            })
            .collect(),
    );
    g.class_conf = Some(conf);
    write_ply(&args.out, &g)?;
    write_classes_sidecar(&args.out, &table)?;
    let seconds = start.elapsed().as_secs_f64();
    let iters = out.times.iterations.max(1) as f64;
    let t = out.times;
    let per_iter = StageTotals {
        forward_ms: t.forward_ms / iters,
        loss_ms: t.loss_ms / iters,
        backward_ms: t.backward_ms / iters,
        optimizer_ms: t.optimizer_ms / iters,
        densify_ms: t.densify_ms / iters,
        iterations: t.iterations,
    };
    eprintln!(
        "trained {} iterations in {seconds:.1} s: {} -> {} Gaussians; GPU ms per iteration: forward {:.1}, loss {:.1}, backward {:.1}, optimizer {:.1}, densify {:.1}",
        t.iterations,
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
            views: views.len(),
            classes: compact.len(),
            initial_gaussians: init.len(),
            final_gaussians: g.len(),
            seconds,
            iterations_per_second: iters / seconds.max(1e-9),
            stage_ms_per_iteration: per_iter,
            log,
            densify: out.densify_events,
        };
        write_bytes_atomic(path, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(())
}

fn checkpoint_path(out: &Path, iteration: u32) -> PathBuf {
    let stem = out.file_stem().unwrap_or_default().to_string_lossy();
    out.with_file_name(format!("{stem}.iter{iteration}.ply"))
}
