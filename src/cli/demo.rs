//! `semsplat demo`: builds the default benchmark room, lifts its labels with every method,
//! and reports speed and accuracy side by side.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde::Serialize;

use super::joint_args::{room_config, MethodArgs};
use super::{args, check_outputs};
use semsplat::eval::image_quality::ImageQuality;
use semsplat::experiment::{held_out_quality, score_methods, MethodScore, TrainLabels};
use semsplat::gpu::Gpu;
use semsplat::synth::{generate, NoiseSpec, SynthScene};
use semsplat::util::write_bytes_atomic;
#[cfg(feature = "charts")]
use {
    anyhow::Context,
    semsplat::eval::chart::{speed_vs_accuracy, SpeedPoint},
    semsplat::eval::label_render::LabelRenderer,
    semsplat::eval::strip::write_strip,
    semsplat::scene::labels::LabelMap,
    semsplat::scene::{ClassTable, Split},
};

#[derive(Args)]
pub struct DemoArgs {
    /// Room preset (office, living, tiny) or a room JSON file.
    #[arg(long, default_value = "office")]
    preset: String,
    /// Output folder: report.json, speed_vs_accuracy.png, strip.png.
    #[arg(long, default_value = "demo_out")]
    out: PathBuf,
    #[arg(long, default_value_t = 20, value_parser = args::at_least_one::<usize>)]
    views: usize,
    /// Held-out views the 2D metrics are computed on.
    #[arg(long, default_value_t = 6, value_parser = args::at_least_one::<usize>)]
    test_views: usize,
    #[arg(long, default_value_t = 320, value_parser = args::at_least_one::<u32>)]
    width: u32,
    #[arg(long, default_value_t = 240, value_parser = args::at_least_one::<u32>)]
    height: u32,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Label noise on the train views (e.g. flicker=0.2,boundary=2); default: true labels.
    #[arg(long)]
    noise: Option<NoiseSpec>,
    #[command(flatten)]
    methods: MethodArgs,
}

#[derive(Serialize)]
struct DemoReport<'a> {
    preset: &'a str,
    gaussians: usize,
    classes: usize,
    train_views: usize,
    test_views: usize,
    width: u32,
    height: u32,
    noise: String,
    device: String,
    methods: &'a [MethodScore],
    /// Held-out PSNR and SSIM of the input scene, the baseline for methods that change
    /// appearance.
    input_image_quality: ImageQuality,
}

#[cfg(feature = "charts")]
fn palette(labels: &[u16], table: &ClassTable) -> Vec<u8> {
    labels
        .iter()
        .flat_map(|&l| {
            if l == LabelMap::IGNORE {
                [0, 0, 0]
            } else {
                table.color_of(l as u32)
            }
        })
        .collect()
}

/// The files demo writes in --out.
const REPORT_FILE: &str = "report.json";
const CHART_FILE: &str = "speed_vs_accuracy.png";
const STRIP_FILE: &str = "strip.png";

pub fn run(args: DemoArgs) -> Result<()> {
    let file = |name: &str| Some(args.out.join(name));
    let (report, chart, strip) = (file(REPORT_FILE), file(CHART_FILE), file(STRIP_FILE));
    check_outputs(
        &[
            ("--out's report", report.as_deref()),
            ("--out's chart", chart.as_deref()),
            ("--out's strip", strip.as_deref()),
        ],
        &[("--out", Some(&args.out))],
        &[],
    )?;
    let methods = args.methods.methods()?;
    let s = build_room(&args)?;
    let gpu = Gpu::new()?;
    let which = if args.noise.is_some() {
        TrainLabels::Noisy
    } else {
        TrainLabels::True
    };
    let scores = score_methods(
        &gpu,
        &s,
        which,
        &methods,
        &args.methods.schedule(),
        args.methods.clustering(),
        |m| eprintln!("lifting with {m}"),
    )?;
    print_scores(&scores);

    let input_image_quality = held_out_quality(&gpu, &s, &s.gaussians)?;
    outln!(
        "input scene, held out: PSNR {:.2} dB, SSIM {:.4}",
        input_image_quality.psnr,
        input_image_quality.ssim
    );
    let report = DemoReport {
        preset: &args.preset,
        gaussians: s.gaussians.len(),
        classes: s.room.classes.len(),
        train_views: args.views,
        test_views: args.test_views,
        width: args.width,
        height: args.height,
        noise: args.noise.as_ref().map_or("none".into(), |n| n.to_string()),
        device: gpu.caps().name.clone(),
        methods: &scores,
        input_image_quality,
    };
    write_bytes_atomic(
        &args.out.join(REPORT_FILE),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    write_charts(&args, &gpu, &s, &scores)
}

/// The benchmark room the flags describe, generated in memory.
fn build_room(args: &DemoArgs) -> Result<SynthScene> {
    let mut cfg = room_config(
        &args.preset,
        args.views,
        args.test_views,
        (args.width, args.height),
        args.seed,
    )?;
    cfg.noise = args.noise.clone();
    eprintln!(
        "building the {} room ({} + {} views at {}x{})",
        args.preset, args.views, args.test_views, args.width, args.height
    );
    generate(&cfg)
}

fn print_scores(scores: &[MethodScore]) {
    // The method column fits the longest name ("segment-consensus --relabel").
    let name = scores
        .iter()
        .map(|r| r.method.len())
        .max()
        .unwrap_or(0)
        .max(24);
    outln!(
        "{:<name$} {:>9} {:>8} {:>10} {:>10} {:>10} {:>10}",
        "method",
        "seconds",
        "mIoU",
        "pixel acc",
        "3D acc",
        "memory",
        "PSNR"
    );
    for r in scores {
        outln!(
            "{:<name$} {:>9.2} {:>8.3} {:>10.3} {:>10.3} {:>7.0} MiB {:>10}",
            r.method,
            r.seconds,
            r.miou,
            r.pixel_accuracy,
            r.gaussian_accuracy,
            r.peak_device_bytes as f64 / (1 << 20) as f64,
            r.image_quality
                .map_or("-".to_string(), |q| format!("{:.2} dB", q.psnr))
        );
    }
}

/// speed_vs_accuracy.png and strip.png.
#[cfg(feature = "charts")]
fn write_charts(args: &DemoArgs, gpu: &Gpu, s: &SynthScene, scores: &[MethodScore]) -> Result<()> {
    let out = &args.out;
    let points: Vec<SpeedPoint> = scores
        .iter()
        .map(|r| SpeedPoint {
            label: r.method,
            seconds: r.seconds,
            score: r.miou,
        })
        .collect();
    let title = format!(
        "{}: {} Gaussians, {} train views",
        args.preset,
        s.gaussians.len(),
        args.views
    );
    speed_vs_accuracy(
        &out.join(CHART_FILE),
        &title,
        "mIoU on held-out views",
        &points,
    )?;
    write_view_strip(gpu, s, scores, &out.join(STRIP_FILE))?;
    eprintln!(
        "wrote {}/report.json, speed_vs_accuracy.png, strip.png",
        out.display()
    );
    Ok(())
}

#[cfg(not(feature = "charts"))]
fn write_charts(args: &DemoArgs, _: &Gpu, _: &SynthScene, _: &[MethodScore]) -> Result<()> {
    eprintln!(
        "wrote {}/report.json (built without the charts feature: no PNGs)",
        args.out.display()
    );
    Ok(())
}

/// One held-out view: RGB, true labels, each method's rendered labels.
#[cfg(feature = "charts")]
fn write_view_strip(
    gpu: &Gpu,
    s: &SynthScene,
    scores: &[MethodScore],
    path: &std::path::Path,
) -> Result<()> {
    let (i, cam) = s
        .cameras
        .iter()
        .enumerate()
        .find(|(_, c)| c.split == Split::Test)
        .context("no test view")?;
    let table = &s.room.classes;
    let mut panels = vec![
        ("RGB".to_string(), s.views[i].rgb.clone()),
        ("true labels".into(), palette(&s.views[i].labels, table)),
    ];
    for r in scores {
        let labels: Vec<u16> = LabelRenderer::new(gpu, r.scene(&s.gaussians), &r.classes)?
            .render(cam)?
            .into_iter()
            .map(|l| l.unwrap_or(LabelMap::IGNORE))
            .collect();
        panels.push((r.method.to_string(), palette(&labels, table)));
    }
    let refs: Vec<(&str, Vec<u8>)> = panels
        .iter()
        .map(|(t, p)| (t.as_str(), p.clone()))
        .collect();
    write_strip(path, cam.width, cam.height, &refs)
}
