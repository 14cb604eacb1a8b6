//! `semsplat sweep`: how each method holds up as one kind of label noise grows, and where
//! it breaks (mIoU below half of its clean value), over several rooms and seeds, read against
//! the instance-oracle bound (the per-object majority of the same noisy labels).

use std::path::PathBuf;

use anyhow::{bail, ensure, Context, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;

use super::joint_args::{room_config, MethodArgs};
use super::{args, check_outputs};
#[cfg(feature = "charts")]
use semsplat::eval::chart::{lines, Line, Reference};
use semsplat::eval::metrics::ClassIou;
use semsplat::experiment::{
    mislabel_follow, score_instance_oracle, score_methods, Lifter, MislabelFollow, TrainLabels,
    ORACLE_NAME,
};
use semsplat::gpu::Gpu;
use semsplat::synth::{generate, NoiseSpec, RoomSource};
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

    /// The label noise of one level: `base` with this kind at `level` (boundary: whole
    /// pixels). Checked as `--noise` would check it (a rate in [0, 1]), so every level is
    /// refused before any runs rather than when the sweep reaches it.
    fn at(self, base: &NoiseSpec, level: f64) -> Result<NoiseSpec> {
        let item = if self == NoiseKind::Boundary {
            ensure!(
                level >= 0.0 && level.fract() == 0.0,
                "--levels '{level}' for --noise boundary: a boundary warp is a whole number of \
                 pixels (0, 1, 2, 4, ...)"
            );
            format!("boundary={}", level as u32)
        } else {
            format!("{}={level}", self.key())
        };
        let alone: NoiseSpec = item
            .parse()
            .with_context(|| format!("--levels '{level}' for --noise {}", self.key()))?;
        let mut spec = base.clone();
        match self {
            NoiseKind::Flicker => spec.flicker = alone.flicker,
            NoiseKind::Consistent => spec.consistent = alone.consistent,
            NoiseKind::Boundary => spec.boundary = alone.boundary,
            NoiseKind::Salt => spec.salt = alone.salt,
            NoiseKind::Missing => spec.missing = alone.missing,
        }
        Ok(spec)
    }
}

/// The levels in ascending order (the chart's line runs through them in that order); a
/// level given twice would run the same work twice and be drawn twice.
fn sorted_levels(levels: Vec<f64>) -> Result<Vec<f64>> {
    // -0 is level 0 (adding +0 turns it so): compared as text it was another level, run twice.
    let mut levels: Vec<f64> = levels.into_iter().map(|l| l + 0.0).collect();
    levels.sort_by(f64::total_cmp);
    let items: Vec<String> = levels.iter().map(f64::to_string).collect();
    refuse_repeats("--levels", &items)?;
    Ok(levels)
}

/// A list option naming one item twice would run the same work twice.
fn refuse_repeats(list: &str, items: &[String]) -> Result<()> {
    for (i, item) in items.iter().enumerate() {
        ensure!(!items[..i].contains(item), "{list} names '{item}' twice");
    }
    Ok(())
}

#[derive(Args)]
pub struct SweepArgs {
    #[arg(long, value_enum)]
    noise: NoiseKind,
    /// Other label noise at every level, beside the kind swept: a segmenter's errors come
    /// together (e.g. --noise flicker --base-noise boundary=2,salt=0.01,missing=0.05). The
    /// `--noise` grammar of `semsplat synth`; it may not set the swept kind. Level 0 is then
    /// this noise alone, the reference the chart and `breaks_at` measure against.
    #[arg(long, value_name = "SPEC")]
    base_noise: Option<NoiseSpec>,
    /// Noise levels (default per kind, starting at 0: the clean reference).
    #[arg(long, value_delimiter = ',', num_args = 1.., value_parser = args::non_negative::<f64>)]
    levels: Vec<f64>,
    /// The room (one of `--presets`' names, or a room spec file).
    #[arg(long, default_value = "office", conflicts_with = "presets")]
    preset: String,
    /// Several rooms, e.g. office,living: every (room, seed) is one run; the JSON and chart
    /// give mean, min and max over the runs.
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    presets: Vec<String>,
    /// Output folder: robustness_<noise>.png and robustness_<noise>.json.
    #[arg(long, default_value = "demo_out")]
    out: PathBuf,
    /// Train views of each room: as many as a real capture has (each Gaussian is seen in
    /// only some of them, which is where label noise bites).
    #[arg(long, default_value_t = 60, value_parser = args::at_least_one::<usize>)]
    views: usize,
    /// Held-out views the mIoU is measured on.
    #[arg(long, default_value_t = 8, value_parser = args::at_least_one::<usize>)]
    test_views: usize,
    #[arg(long, default_value_t = 320, value_parser = args::at_least_one::<u32>)]
    width: u32,
    #[arg(long, default_value_t = 240, value_parser = args::at_least_one::<u32>)]
    height: u32,
    #[arg(long, default_value_t = 0, conflicts_with = "seeds")]
    seed: u64,
    /// Several seeds, e.g. 1,2,3 (cameras, Gaussians and noise all follow the seed).
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    seeds: Vec<u64>,
    #[command(flatten)]
    methods: MethodArgs,
}

impl SweepArgs {
    /// `--base-noise` as written in the report and chart; None without it (or with `none`).
    fn base_text(&self) -> Option<String> {
        let base = self.base_noise.as_ref()?;
        (*base != NoiseSpec::default()).then(|| base.to_string())
    }
}

/// One method's (or the oracle's) figures at one level of one run.
#[derive(Serialize)]
struct MethodLevel {
    method: String,
    /// The name `--methods` takes ("oracle" for the oracle).
    key: &'static str,
    /// Held-out views.
    miou: f64,
    gaussian_accuracy: f64,
    /// Held-out IoU per class present there, with the room's class names.
    per_class: Vec<ClassIou>,
}

#[derive(Serialize)]
struct LevelResult {
    level: f64,
    methods: Vec<MethodLevel>,
    /// The instance-oracle bound on the same labels.
    oracle: MethodLevel,
    /// Consistent noise only: per mislabeled object and method.
    mislabeled: Vec<(String, Vec<MislabelFollow>)>,
}

/// One room and seed: every level.
#[derive(Serialize)]
struct RunResult {
    preset: String,
    seed: u64,
    levels: Vec<LevelResult>,
}

/// Mean, min and max of one figure over the runs.
#[derive(Clone, Copy, Serialize)]
struct Spread {
    mean: f64,
    min: f64,
    max: f64,
}

impl Spread {
    fn of(values: impl Iterator<Item = f64> + Clone) -> Spread {
        let n = values.clone().count().max(1) as f64;
        Spread {
            mean: values.clone().sum::<f64>() / n,
            min: values.clone().fold(f64::INFINITY, f64::min),
            max: values.fold(f64::NEG_INFINITY, f64::max),
        }
    }
}

/// One method's spread over the runs at one level.
#[derive(Serialize)]
struct MethodSpread {
    method: String,
    /// The name `--methods` takes ("oracle" for the oracle).
    key: &'static str,
    miou: Spread,
    gaussian_accuracy: Spread,
}

#[derive(Serialize)]
struct LevelSummary {
    level: f64,
    /// Methods, then the oracle last.
    methods: Vec<MethodSpread>,
}

/// The reference line: the method with the best mean mIoU at level 0 (clean labels, or the
/// base noise alone).
#[derive(Serialize)]
struct CleanReference {
    method: String,
    miou: f64,
}

#[derive(Serialize)]
struct SweepReport {
    noise: &'static str,
    /// `--base-noise`, at every level (None: the swept kind alone).
    base_noise: Option<String>,
    presets: Vec<String>,
    seeds: Vec<u64>,
    /// Segment consensus's clustering (`--clustering`).
    clustering: semsplat::fuse::Clustering,
    /// Mean, min and max over the runs (every preset and seed).
    levels: Vec<LevelSummary>,
    /// None when the levels do not include 0. With `base_noise`, level 0 is that noise alone
    /// rather than clean labels.
    clean_reference: Option<CleanReference>,
    /// method -> the lowest level where its mean mIoU fell below half of its mean at level 0
    /// ([`breaks_at`]); None when the levels do not include 0.
    breaks_at: Option<Vec<(String, Option<f64>)>>,
    runs: Vec<RunResult>,
}

/// The sweep's levels (sorted), rooms and seeds, each list's default where it was not
/// given; repeats and unknown rooms refused before the first run.
fn sweep_lists(args: &SweepArgs) -> Result<(Vec<f64>, Vec<String>, Vec<u64>)> {
    let levels = if args.levels.is_empty() {
        args.noise.default_levels()
    } else {
        args.levels.clone()
    };
    let presets = if args.presets.is_empty() {
        vec![args.preset.clone()]
    } else {
        args.presets.clone()
    };
    let seeds = if args.seeds.is_empty() {
        vec![args.seed]
    } else {
        args.seeds.clone()
    };
    let levels = sorted_levels(levels)?;
    refuse_repeats("--presets", &presets)?;
    refuse_repeats(
        "--seeds",
        &seeds.iter().map(u64::to_string).collect::<Vec<_>>(),
    )?;
    for preset in &presets {
        RoomSource::from_arg(preset)?;
    }
    Ok((levels, presets, seeds))
}

pub fn run(args: SweepArgs) -> Result<()> {
    let (levels, presets, seeds) = sweep_lists(&args)?;
    let base = base_noise(&args)?;
    let specs = (levels.iter())
        .map(|&level| Ok((level, args.noise.at(&base, level)?)))
        .collect::<Result<Vec<_>>>()?;
    let (report_file, chart_file) = (sweep_file(&args, "json"), sweep_file(&args, "png"));
    check_outputs(
        &[
            ("--out's report", Some(&report_file)),
            ("--out's chart", Some(&chart_file)),
        ],
        &[("--out", Some(&args.out))],
        &[],
    )?;
    let methods = args.methods.methods()?;
    let gpu = Gpu::new()?;
    let mut runs = Vec::new();
    for preset in &presets {
        for &seed in &seeds {
            eprintln!("{preset}, seed {seed}");
            let levels = (specs.iter())
                .map(|level| {
                    interrupt::check()?;
                    run_level(&args, &gpu, &methods, (preset, seed), level)
                })
                .collect::<Result<Vec<_>>>()?;
            runs.push(RunResult {
                preset: preset.clone(),
                seed,
                levels,
            });
        }
    }
    let summary = summarize(&runs);
    let clean_reference = clean_reference(&summary);
    let key = args.noise.key();
    write_chart(
        &args,
        &presets,
        &summary,
        clean_reference.as_ref(),
        runs.len(),
    )?;
    let report = SweepReport {
        noise: key,
        base_noise: args.base_text(),
        presets,
        seeds,
        clustering: args.methods.clustering(),
        breaks_at: breaks_at(&summary),
        levels: summary,
        clean_reference,
        runs,
    };
    print_summary(&report);
    write_bytes_atomic(
        &report_file,
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    Ok(())
}

/// `robustness_<noise>.<extension>` in --out: the sweep's report and chart.
fn sweep_file(args: &SweepArgs, extension: &str) -> PathBuf {
    let key = args.noise.key();
    args.out.join(format!("robustness_{key}.{extension}"))
}

/// `--base-noise`, refused where it sets the kind the levels sweep (the levels would
/// silently replace it).
fn base_noise(args: &SweepArgs) -> Result<NoiseSpec> {
    let base = args.base_noise.clone().unwrap_or_default();
    let key = args.noise.key();
    if args.noise.at(&base, 0.0)? != base {
        bail!("--base-noise {base} sets {key}, the noise --noise {key} sweeps: leave it out of --base-noise (--levels sets it)");
    }
    Ok(base)
}

fn print_summary(report: &SweepReport) {
    let key = report.noise;
    if report.runs.len() > 1 {
        outln!("mean (min-max) over {} runs:", report.runs.len());
        for l in &report.levels {
            for m in &l.methods {
                let (a, g) = (m.miou, m.gaussian_accuracy);
                outln!(
                    "{key}={:<6} {:<28} mIoU {:.4} ({:.4}-{:.4})  3D acc {:.4} ({:.4}-{:.4})",
                    l.level,
                    m.method,
                    a.mean,
                    a.min,
                    a.max,
                    g.mean,
                    g.min,
                    g.max
                );
            }
        }
    }
    let Some(breaks) = &report.breaks_at else {
        outln!("no level 0 among the levels: add 0 to --levels to see where each method falls below half of its mIoU there");
        return;
    };
    let reference = match &report.base_noise {
        Some(base) => format!("its mIoU with {base} alone"),
        None => "its clean mIoU".to_string(),
    };
    let clean = report.levels.iter().find(|l| l.level == 0.0);
    let clean_miou = |m: &str| {
        let of_method = clean.and_then(|l| l.methods.iter().find(|s| s.method == m));
        of_method.map_or(0.0, |s| s.miou.mean)
    };
    for (m, b) in breaks {
        match b {
            // Half of nothing is nothing: a method whose held-out views matched nothing
            // there (no labeled pixel right, or no class rendered) has no break to find.
            _ if clean_miou(m) == 0.0 => {
                outln!("{m}: {reference} is 0 (no labeled pixel of the held-out views right): no break to find")
            }
            Some(l) => outln!("{m}: below half of {reference} at {key}={l}"),
            None => outln!("{m}: never below half of {reference} in this range"),
        }
    }
}

/// Generates the room with `level` of the swept noise (`noise`: it and the base noise) and
/// scores every method and the oracle on it.
fn run_level(
    args: &SweepArgs,
    gpu: &Gpu,
    methods: &[Lifter],
    (preset, seed): (&str, u64),
    (level, noise): &(f64, NoiseSpec),
) -> Result<LevelResult> {
    let mut cfg = room_config(
        preset,
        args.views,
        args.test_views,
        (args.width, args.height),
        seed,
    )?;
    let spec = noise.to_string();
    cfg.noise = Some(noise.clone());
    eprintln!("{spec}");
    let s = generate(&cfg)?;
    let scores = score_methods(
        gpu,
        &s,
        TrainLabels::Noisy,
        methods,
        &args.methods.schedule(),
        args.methods.clustering(),
        |m| eprintln!("  {m}"),
    )?;
    let oracle = score_instance_oracle(gpu, &s)?;
    for r in scores.iter().chain([&oracle]) {
        outln!(
            "{preset:<8} seed {seed:<4} {spec:<16} {:<28} mIoU {:.4}  3D acc {:.4}",
            r.method,
            r.miou,
            r.gaussian_accuracy
        );
    }
    let figures = |r: &semsplat::experiment::MethodScore| MethodLevel {
        method: r.method.to_string(),
        key: r.key,
        miou: r.miou,
        gaussian_accuracy: r.gaussian_accuracy,
        per_class: r.per_class.clone(),
    };
    Ok(LevelResult {
        level: *level,
        methods: scores.iter().map(figures).collect(),
        oracle: figures(&oracle),
        mislabeled: scores
            .iter()
            .map(|r| (r.method.to_string(), mislabel_follow(&s, r)))
            .collect(),
    })
}

/// Per level, every method's (then the oracle's) mean, min and max over the runs. Every run
/// has the same levels and methods in the same order.
fn summarize(runs: &[RunResult]) -> Vec<LevelSummary> {
    let first = &runs[0].levels;
    (0..first.len())
        .map(|l| {
            let at = |k: usize| {
                runs.iter().map(move |r| {
                    let level = &r.levels[l];
                    level.methods.get(k).unwrap_or(&level.oracle)
                })
            };
            let methods = (0..=first[l].methods.len())
                .map(|k| MethodSpread {
                    method: at(k).next().map(|m| m.method.clone()).unwrap_or_default(),
                    key: at(k).next().map_or("", |m| m.key),
                    miou: Spread::of(at(k).map(|m| m.miou)),
                    gaussian_accuracy: Spread::of(at(k).map(|m| m.gaussian_accuracy)),
                })
                .collect();
            LevelSummary {
                level: first[l].level,
                methods,
            }
        })
        .collect()
}

/// The best mean mIoU at level 0 among the methods (not the oracle); None without level 0,
/// or where every method scored 0 there.
fn clean_reference(summary: &[LevelSummary]) -> Option<CleanReference> {
    let clean = summary.iter().find(|l| l.level == 0.0)?;
    clean
        .methods
        .iter()
        .filter(|m| m.method != ORACLE_NAME && m.miou.mean > 0.0)
        .max_by(|a, b| a.miou.mean.total_cmp(&b.miou.mean))
        .map(|m| CleanReference {
            method: m.method.clone(),
            miou: m.miou.mean,
        })
}

/// Per method (and the oracle): the lowest noise level at which its mean mIoU fell below
/// half of its mean on clean labels (level 0), None where it never did; None for all when
/// the levels do not include 0 (a first noisy level is no clean value to halve).
fn breaks_at(summary: &[LevelSummary]) -> Option<Vec<(String, Option<f64>)>> {
    let clean = summary.iter().find(|l| l.level == 0.0)?;
    let mut noisy: Vec<&LevelSummary> = summary.iter().filter(|l| l.level > 0.0).collect();
    noisy.sort_by(|a, b| a.level.total_cmp(&b.level));
    let first_below = |k: usize, half: f64| {
        noisy
            .iter()
            .find(|l| l.methods[k].miou.mean < half)
            .map(|l| l.level)
    };
    let methods = clean.methods.iter().enumerate();
    Some(
        methods
            .map(|(k, m)| (m.method.clone(), first_below(k, 0.5 * m.miou.mean)))
            .collect(),
    )
}

/// robustness_<noise>.png: every method's mean mIoU against the noise level, with its
/// min-max band over the runs, the oracle bound and the clean-label reference dashed.
#[cfg(feature = "charts")]
fn write_chart(
    args: &SweepArgs,
    presets: &[String],
    summary: &[LevelSummary],
    clean: Option<&CleanReference>,
    runs: usize,
) -> Result<()> {
    let oracle = summary[0].methods.len() - 1;
    let curve = |k: usize| -> Vec<(f64, f64)> {
        summary
            .iter()
            .map(|l| (l.level, l.methods[k].miou.mean))
            .collect()
    };
    let series: Vec<Line> = summary[0].methods[..oracle]
        .iter()
        .enumerate()
        .map(|(k, m)| Line {
            label: &m.method,
            points: curve(k),
            band: if runs > 1 {
                summary
                    .iter()
                    .map(|l| (l.methods[k].miou.min, l.methods[k].miou.max))
                    .collect()
            } else {
                Vec::new()
            },
        })
        .collect();
    let clean_label = clean.map(|c| match args.base_text() {
        Some(base) => format!("{base} alone: {} at level 0", c.method),
        None => format!("clean labels: {} at level 0", c.method),
    });
    let mut references = vec![Reference {
        label: "oracle bound (instance majority of the noisy labels)",
        points: curve(oracle),
    }];
    if let (Some(c), Some(label)) = (clean, &clean_label) {
        let xs = summary.iter().map(|l| l.level);
        references.push(Reference {
            label,
            points: vec![
                (xs.clone().fold(f64::INFINITY, f64::min), c.miou),
                (xs.fold(f64::NEG_INFINITY, f64::max), c.miou),
            ],
        });
    }
    let key = args.noise.key();
    let mut details = if runs > 1 {
        format!(", mean and min-max of {runs} runs")
    } else {
        String::new()
    };
    if let Some(base) = args.base_text() {
        details += &format!(", with {base}");
    }
    lines(
        &sweep_file(args, "png"),
        &format!("{}: mIoU as {key} noise grows{details}", presets.join("+")),
        &format!("{key} level"),
        "mIoU on held-out views",
        &series,
        &references,
    )
}

#[cfg(not(feature = "charts"))]
fn write_chart(
    _: &SweepArgs,
    _: &[String],
    _: &[LevelSummary],
    _: Option<&CleanReference>,
    _: usize,
) -> Result<()> {
    eprintln!("built without the charts feature: no robustness chart");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(level: f64, mious: &[f64]) -> LevelSummary {
        let spread = |v: f64| Spread {
            mean: v,
            min: v,
            max: v,
        };
        let methods = mious.iter().enumerate().map(|(k, &v)| MethodSpread {
            method: format!("m{k}"),
            key: "",
            miou: spread(v),
            gaussian_accuracy: spread(v),
        });
        LevelSummary {
            level,
            methods: methods.collect(),
        }
    }

    /// Against the clean level wherever it is listed, the noisy levels searched from the
    /// lowest; without a clean level there is nothing to halve.
    #[test]
    fn breaks_at_halves_the_clean_miou_only() {
        let noisy_only = [level(0.4, &[0.8, 0.6]), level(0.5, &[0.3, 0.5])];
        assert!(
            breaks_at(&noisy_only).is_none(),
            "0.3 is not half of a clean value"
        );
        let listed = [
            level(0.5, &[0.2, 0.5]),
            level(0.0, &[0.9, 0.9]),
            level(0.3, &[0.4, 0.8]),
        ];
        let breaks = breaks_at(&listed).unwrap();
        assert_eq!(
            breaks,
            [("m0".to_string(), Some(0.3)), ("m1".to_string(), None)]
        );
    }
}
