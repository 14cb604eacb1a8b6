//! `semsplat sweep`: how each method holds up as one kind of label noise grows, and where
//! it breaks (mIoU below half of its clean value).

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde::Serialize;

use super::joint_args::{room_config, MethodArgs};
use super::{args, check_outputs};
#[cfg(feature = "charts")]
use semsplat::eval::chart::{lines, Line};
use semsplat::experiment::{mislabel_follow, score_methods, Lifter, MislabelFollow, TrainLabels};
use semsplat::gpu::Gpu;
use semsplat::synth::{generate, NoiseSpec};
use semsplat::util::{interrupt, write_bytes_atomic};

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug)]
enum NoiseKind {
    /// Each object relabeled in a view with probability p (to a look-alike class).
    Flicker,
    /// One object gets the same wrong class in a fraction q of the views.
    Consistent,
    /// Labels shifted across object edges by up to k pixels.
    Boundary,
    /// A fraction s of pixels set to random classes.
    Salt,
    /// A fraction m of pixels unlabeled (in blobs).
    Missing,
}

impl NoiseKind {
    fn key(self) -> &'static str {
        match self {
            NoiseKind::Flicker => "flicker",
            NoiseKind::Consistent => "consistent",
            NoiseKind::Boundary => "boundary",
            NoiseKind::Salt => "salt",
            NoiseKind::Missing => "missing",
        }
    }

    fn default_levels(self) -> Vec<f64> {
        match self {
            NoiseKind::Flicker => vec![0.0, 0.1, 0.2, 0.3, 0.4, 0.5],
            NoiseKind::Consistent => vec![0.0, 0.25, 0.5, 0.75, 1.0],
            NoiseKind::Boundary => vec![0.0, 1.0, 2.0, 4.0, 8.0],
            NoiseKind::Salt => vec![0.0, 0.05, 0.1, 0.2, 0.4],
            NoiseKind::Missing => vec![0.0, 0.1, 0.3, 0.5],
        }
    }
}

#[derive(Args)]
pub struct SweepArgs {
    #[arg(long, value_enum)]
    noise: NoiseKind,
    /// Noise levels (default per kind, starting at 0: the clean reference).
    #[arg(long, value_delimiter = ',', num_args = 1.., value_parser = args::non_negative::<f64>)]
    levels: Vec<f64>,
    #[arg(long, default_value = "office")]
    preset: String,
    /// Output folder: robustness_<noise>.png and robustness_<noise>.json.
    #[arg(long, default_value = "demo_out")]
    out: PathBuf,
    #[arg(long, default_value_t = 12, value_parser = args::at_least_one::<usize>)]
    views: usize,
    #[arg(long, default_value_t = 4, value_parser = args::at_least_one::<usize>)]
    test_views: usize,
    #[arg(long, default_value_t = 320, value_parser = args::at_least_one::<u32>)]
    width: u32,
    #[arg(long, default_value_t = 240, value_parser = args::at_least_one::<u32>)]
    height: u32,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    methods: MethodArgs,
}

#[derive(Serialize)]
struct LevelResult {
    level: f64,
    /// method -> mIoU on held-out views
    miou: Vec<(String, f64)>,
    gaussian_accuracy: Vec<(String, f64)>,
    /// Consistent noise only: per mislabeled object and method.
    mislabeled: Vec<(String, Vec<MislabelFollow>)>,
}

#[derive(Serialize)]
struct SweepReport {
    noise: &'static str,
    preset: String,
    levels: Vec<LevelResult>,
    /// method -> first level where mIoU fell below half of its value at the first level.
    breaks_at: Vec<(String, Option<f64>)>,
}

pub fn run(args: SweepArgs) -> Result<()> {
    let levels = if args.levels.is_empty() {
        args.noise.default_levels()
    } else {
        args.levels.clone()
    };
    check_outputs(&[], &[("--out", Some(&args.out))])?;
    let methods = args.methods.methods()?;
    let gpu = Gpu::new()?;
    let results = levels
        .iter()
        .map(|&level| {
            interrupt::check()?;
            run_level(&args, &gpu, &methods, level)
        })
        .collect::<Result<Vec<_>>>()?;
    let key = args.noise.key();
    write_chart(&args, &results)?;
    let report = SweepReport {
        noise: key,
        preset: args.preset.clone(),
        breaks_at: breaks_at(&results),
        levels: results,
    };
    for (m, b) in &report.breaks_at {
        match b {
            Some(l) => println!("{m}: below half of its clean mIoU at {key}={l}"),
            None => println!("{m}: never below half of its clean mIoU in this range"),
        }
    }
    write_bytes_atomic(
        &args.out.join(format!("robustness_{key}.json")),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    Ok(())
}

/// Generates the room with `level` of the noise and scores every method on it.
fn run_level(args: &SweepArgs, gpu: &Gpu, methods: &[Lifter], level: f64) -> Result<LevelResult> {
    let mut cfg = room_config(
        &args.preset,
        args.views,
        args.test_views,
        (args.width, args.height),
        args.seed,
    )?;
    let spec = if args.noise == NoiseKind::Boundary {
        format!("boundary={}", level.round() as u32)
    } else {
        format!("{}={level}", args.noise.key())
    };
    cfg.noise = Some(spec.parse::<NoiseSpec>()?);
    eprintln!("{spec}");
    let s = generate(&cfg)?;
    let scores = score_methods(
        gpu,
        &s,
        TrainLabels::Noisy,
        methods,
        &args.methods.schedule(),
        |m| eprintln!("  {m}"),
    )?;
    for r in &scores {
        println!(
            "{spec:<16} {:<18} mIoU {:.4}  3D acc {:.4}",
            r.method, r.miou, r.gaussian_accuracy
        );
    }
    Ok(LevelResult {
        level,
        miou: scores
            .iter()
            .map(|r| (r.method.to_string(), r.miou))
            .collect(),
        gaussian_accuracy: scores
            .iter()
            .map(|r| (r.method.to_string(), r.gaussian_accuracy))
            .collect(),
        mislabeled: scores
            .iter()
            .map(|r| (r.method.to_string(), mislabel_follow(&s, r)))
            .collect(),
    })
}

/// The methods, in the order of every level's results.
fn method_names(results: &[LevelResult]) -> Vec<String> {
    results[0].miou.iter().map(|(m, _)| m.clone()).collect()
}

/// Per method: the first level where mIoU fell below half of its value at the first level.
fn breaks_at(results: &[LevelResult]) -> Vec<(String, Option<f64>)> {
    method_names(results)
        .into_iter()
        .enumerate()
        .map(|(k, m)| {
            let clean = results[0].miou[k].1;
            (
                m,
                results
                    .iter()
                    .find(|r| r.miou[k].1 < 0.5 * clean)
                    .map(|r| r.level),
            )
        })
        .collect()
}

/// robustness_<noise>.png: every method's mIoU against the noise level.
#[cfg(feature = "charts")]
fn write_chart(args: &SweepArgs, results: &[LevelResult]) -> Result<()> {
    let methods = method_names(results);
    let series: Vec<Line> = methods
        .iter()
        .enumerate()
        .map(|(k, m)| Line {
            label: m,
            points: results.iter().map(|r| (r.level, r.miou[k].1)).collect(),
        })
        .collect();
    let key = args.noise.key();
    lines(
        &args.out.join(format!("robustness_{key}.png")),
        &format!("{}: mIoU as {key} noise grows", args.preset),
        &format!("{key} level"),
        "mIoU on held-out views",
        &series,
    )
}

#[cfg(not(feature = "charts"))]
fn write_chart(_: &SweepArgs, _: &[LevelResult]) -> Result<()> {
    eprintln!("built without the charts feature: no robustness chart");
    Ok(())
}
