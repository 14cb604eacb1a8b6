//! `semsplat bench`: GPU kernel throughput from timestamps, against a CPU baseline measured
//! in the same run on the same data; fusion against a forward render of the same views.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::{Args, Subcommand};
use serde::Serialize;

use super::args;
use super::joint_args::{methods_help, parse_methods};
use super::progress::{follow, views_bar};
use super::{check_outputs, Input};
use semsplat::bench::export::EXPORT_FILES;
use semsplat::bench::fuse::{bench_fuse, FuseBench, FuseBenchSpec};
use semsplat::bench::render::{bench_render, BenchInput};
use semsplat::bench::train::{bench_train, TrainBench};
use semsplat::bench::{scan::bench_scan, sort::bench_sort};
use semsplat::experiment::{Lifter, ALL_METHODS};
use semsplat::gpu::timings::KernelTotal;
use semsplat::gpu::Gpu;

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Radix sort of u32 key/value pairs vs Rust's stable sort_by_key.
    Sort(SortArgs),
    /// Exclusive prefix sum of u32 vs a sequential CPU scan.
    Scan(ScanArgs),
    /// Forward rendering of a random scene (SH degree 3): frames/s and per-stage GPU time.
    Render(RenderArgs),
    /// Every fusion method over many views of a random scene, against a plain forward render
    /// (RGB only) of the same views: seconds, GPU time, views/s and the ratio to the render.
    Fuse(FuseArgs),
    /// Training iterations (forward, losses, backward, Adam) on one view of a random scene:
    /// wall time per iteration and GPU time per stage; the backward stage is the backward
    /// pass's benchmark.
    Train(TrainArgs),
}

/// Scene sizes of trained 3DGS scenes at full HD, for `bench fuse --preset`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum FusePreset {
    /// 1,000,000 Gaussians (SH degree 3) at 1920x1080.
    #[value(name = "1m")]
    OneMillion,
    /// 6,000,000 Gaussians (SH degree 3, about Mip-NeRF 360 garden) at 1920x1080.
    #[value(name = "6m")]
    SixMillion,
}

#[derive(Args)]
pub struct FuseArgs {
    /// A real-size scene: sets --n, --width and --height (given values are overridden).
    #[arg(long)]
    preset: Option<FusePreset>,
    /// Number of Gaussians (a random scene, SH degree 3).
    #[arg(long, default_value_t = 200_000)]
    n: usize,
    /// A scene with a `cameras.json` in its folder (a `synth` room or its scene.ply, an INRIA
    /// run) instead of the random scene: its first --views cameras, scaled to --width x
    /// --height.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["preset", "n"])]
    scene: Option<PathBuf>,
    /// Views: cameras on a ring in front of the scene, each seeing most of it (or the
    /// --scene folder's first ones), with a label map of blocks of random classes each
    /// (seeded, streamed view by view), or the --labels folder's maps.
    #[arg(long, default_value_t = 100)]
    views: usize,
    /// With --scene: the folder's own label maps (PNGs named like its cameras, such as a
    /// `synth` room's labels_noisy) instead of random blocks. Random blocks are drawn
    /// independently in every view, so their edges cut every surface somewhere: the worst
    /// case for segment consensus's clustering, where a segmenter's regions follow the
    /// objects. The views take the maps' size (--width and --height are not used) and the
    /// classes are those the maps hold (--classes is not used).
    // Conflicting with --n and --preset too: clap does not hold `requires` to an option
    // that conflicts with one given (`--n 2000 --labels DIR` passed, its labels unread).
    #[arg(long, value_name = "DIR", requires = "scene", conflicts_with_all = ["preset", "n"])]
    labels: Option<PathBuf>,
    /// Image size of every view.
    #[arg(long, default_value_t = 640)]
    width: u32,
    #[arg(long, default_value_t = 480)]
    height: u32,
    /// Label classes (rows of the evidence matrix), 1..=65535.
    #[arg(long, default_value_t = 16)]
    classes: usize,
    #[arg(long, value_delimiter = ',', num_args = 1.., help = methods_help(&fusion_methods()))]
    methods: Vec<String>,
    /// Timed runs over all views of the forward render and of every method (after a
    /// one-view warm-up); the median is reported. One run already times every view.
    #[arg(long, default_value_t = 1)]
    iters: usize,
    /// Seed of the scene and the label maps.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Views each tiled method keeps in flight at most, each on its own lane (rasterizer
    /// buffers, and for segment consensus its own region finder): more hide more of each
    /// view's host work behind the GPU's. Fewer are kept where the device has no room.
    #[arg(long, default_value_t = semsplat::fuse::LANES,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new()
              .range(1..=semsplat::fuse::MAX_LANES as u64))]
    views_in_flight: usize,
    /// Segment consensus's clustering (`fuse --clustering`).
    #[arg(long, value_enum, default_value_t = semsplat::fuse::Clustering::Order)]
    clustering: semsplat::fuse::Clustering,
    /// Also write the scene (PLY), the cameras (JSON), every view's label map (one uint16
    /// `labels.npy`, 65535 where unlabeled) and a `bench.json` into DIR, so other tools can
    /// be timed on the same bytes.
    #[arg(long, value_name = "DIR")]
    export: Option<PathBuf>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct RenderArgs {
    #[command(flatten)]
    input: InputArgs,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Args)]
pub struct TrainArgs {
    #[command(flatten)]
    input: InputArgs,
    /// Train only the semantic logits (geometry and colours fixed), as `train
    /// --semantics-only`.
    #[arg(long)]
    semantics_only: bool,
    /// With --semantics-only: no target image, the loss records the semantic term alone,
    /// as `train --semantics-only` without --images (without this flag it times the
    /// photometric loss too, as with --images).
    #[arg(long, requires = "semantics_only")]
    without_images: bool,
    #[command(flatten)]
    common: CommonArgs,
}

/// The scene and view of `bench render` and `bench train`.
#[derive(Args)]
pub struct InputArgs {
    /// Number of Gaussians of the random scene (SH degree 3).
    #[arg(long, default_value_t = 100_000, value_parser = args::at_least_one::<usize>)]
    n: usize,
    #[arg(long, default_value_t = 640, value_parser = args::at_least_one::<u32>)]
    width: u32,
    #[arg(long, default_value_t = 480, value_parser = args::at_least_one::<u32>)]
    height: u32,
    /// Semantic channels blended with RGB (0: RGB only), with random logits.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u16).range(0..=256))]
    channels: u16,
    /// A scene with a `cameras.json` in its folder (a `synth` room or its scene.ply, an INRIA
    /// run) to use instead of the random scene; its first camera is the view, at its own
    /// size.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["n", "width", "height"])]
    scene: Option<PathBuf>,
    /// Also write the scene (PLY, with the semantic channels), the camera (JSON) and a
    /// `bench.json` into DIR, so other renderers can be timed on the same bytes.
    #[arg(long, value_name = "DIR")]
    export: Option<PathBuf>,
}

impl InputArgs {
    fn input(&self, seed: u64) -> BenchInput {
        BenchInput {
            n: self.scene.is_none().then_some(self.n),
            width: self.width,
            height: self.height,
            channels: self.channels as usize,
            seed,
            scene: self.scene.clone(),
            export: self.export.clone(),
        }
    }
}

#[derive(Args)]
pub struct CommonArgs {
    /// Timed repetitions (after a warm-up); the median is reported (`bench train`: the
    /// iteration's wall time; its stages' GPU times are means over the iterations).
    #[arg(long, default_value_t = 5, value_parser = args::at_least_one::<usize>)]
    iters: usize,
    /// Seed of the random input.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
pub struct SortArgs {
    /// Number of key/value pairs.
    #[arg(long, default_value_t = 1 << 22, value_parser = args::at_least_one::<u64>)]
    n: u64,
    /// Sort by the low BITS bits of each key (1..=32).
    #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u32).range(1..=32))]
    bits: u32,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Args)]
pub struct ScanArgs {
    /// Number of u32 elements.
    #[arg(long, default_value_t = 1 << 22, value_parser = args::at_least_one::<u64>)]
    n: u64,
    #[command(flatten)]
    common: CommonArgs,
}

fn print_kernels(kernels: &[KernelTotal]) {
    for k in kernels {
        println!(
            "  {:<26} {:>4} dispatches {:>10.3} ms",
            k.kernel,
            k.dispatches,
            k.ns * 1e-6
        );
    }
}

fn emit<T: Serialize>(json: bool, value: &T, table: impl FnOnce()) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(value)?);
    } else {
        table();
    }
    Ok(())
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 20) as f64
}

/// A ratio to the forward render, with whether it meets the goal.
fn against_goal(ratio: f64, goal: f64) -> String {
    let verdict = if ratio <= goal { "met" } else { "missed" };
    format!("{ratio:>7.2}x {verdict:<6}")
}

fn print_fuse(r: &FuseBench) {
    let s = &r.spec;
    let labels = match &s.labels {
        Some(dir) => format!("labels of {}", dir.display()),
        None => "random block labels".to_string(),
    };
    println!(
        "fuse: {} Gaussians, {} views at {}x{}, {} classes ({labels}), on {} (median of {} run{})",
        s.n,
        s.views,
        s.width,
        s.height,
        s.classes,
        r.device,
        s.iters,
        if s.iters == 1 { "" } else { "s" }
    );
    let f = &r.forward;
    println!(
        "{:<22} {:>8} {:>10} {:>8} {:>6} {:>8} {:>8}        {:>8}",
        "", "wall s", "GPU ms", "views/s", "passes", "memory", "GPU/fwd", "wall/fwd"
    );
    println!(
        "{:<22} {:>8.2} {:>10.1} {:>8.2} {:>6} {:>4.0} MiB",
        "forward render (RGB)",
        f.wall_s,
        f.gpu_ms,
        f.views_per_s,
        1,
        mib(f.peak_device_bytes)
    );
    for m in &r.methods {
        let row = format!(
            "{:<22} {:>8.2} {:>10.1} {:>8.2} {:>6} {:>4.0} MiB {} {}",
            m.method,
            m.wall_s,
            m.gpu_ms,
            m.views_per_s,
            m.passes,
            mib(m.peak_device_bytes),
            against_goal(m.gpu_ratio, r.goal_ratio),
            against_goal(m.wall_ratio, r.goal_ratio)
        );
        println!("{}", row.trim_end());
    }
    println!(
        "goal: accumulation <= {:.1}x the forward render (GPU time and wall time)",
        r.goal_ratio
    );
    println!(
        "forward render: {:.0} visible Gaussians, {:.0} tile intersections per view",
        f.visible_per_view, f.intersections_per_view
    );
    let scenes: Vec<String> = r
        .methods
        .iter()
        .map(|m| format!("{} {:.0} MiB", m.key, mib(m.scene_device_bytes)))
        .collect();
    println!("scene on the device per method: {}", scenes.join(", "));
    if let Some(peak) = r.peak_host_bytes {
        println!("host memory peak: {:.0} MiB", mib(peak));
    }
}

pub fn run(cmd: BenchCommand) -> Result<()> {
    let gpu = Gpu::new()?;
    match &cmd {
        BenchCommand::Render(a) => check_export(&a.input.export, &a.input.scene, &None)?,
        BenchCommand::Train(a) => check_export(&a.input.export, &a.input.scene, &None)?,
        BenchCommand::Fuse(a) => check_export(&a.export, &a.scene, &a.labels)?,
        BenchCommand::Sort(_) | BenchCommand::Scan(_) => {}
    }
    match cmd {
        BenchCommand::Sort(a) => run_sort(&gpu, a),
        BenchCommand::Scan(a) => run_scan(&gpu, a),
        BenchCommand::Render(a) => run_render(&gpu, a),
        BenchCommand::Fuse(a) => run_fuse(&gpu, a),
        BenchCommand::Train(a) => run_train(&gpu, a),
    }
}

/// `--export DIR` writes a scene folder's files: not over the `--scene` folder it reads (its
/// cameras would be cut to the benchmark's, its scene given random logits), nor into the
/// label folder.
fn check_export(
    export: &Option<PathBuf>,
    scene: &Option<PathBuf>,
    labels: &Option<PathBuf>,
) -> Result<()> {
    let Some(dir) = export else {
        return Ok(());
    };
    let files = EXPORT_FILES.map(|f| dir.join(f));
    let named: Vec<(&str, Option<&Path>)> = files
        .iter()
        .map(|f| ("--export", Some(f.as_path())))
        .collect();
    check_outputs(
        &named,
        &[],
        &[
            Input::Scene("--scene", scene.as_deref()),
            Input::Labels("--labels", labels.as_deref()),
        ],
    )
}

fn run_sort(gpu: &Gpu, a: SortArgs) -> Result<()> {
    let r = bench_sort(gpu, a.n, a.bits, a.common.iters, a.common.seed)?;
    emit(a.common.json, &r, || {
        println!(
            "radix sort: {} pairs, {} bits, on {} (median of {})",
            r.n, r.bits, r.device, r.iters
        );
        println!(
            "  GPU  {:>10.3} ms  {:>8.3} G pairs/s",
            r.gpu_ms,
            r.gpu_pairs_per_s * 1e-9
        );
        println!(
            "  CPU  {:>10.3} ms  {:>8.3} G pairs/s  (Rust stable sort_by_key)",
            r.cpu_ms,
            r.cpu_pairs_per_s * 1e-9
        );
        println!(
            "  ratio GPU/CPU: {:.2}x   (result verified against the CPU sort)",
            r.ratio
        );
        print_kernels(&r.kernels);
    })
}

fn run_scan(gpu: &Gpu, a: ScanArgs) -> Result<()> {
    let r = bench_scan(gpu, a.n, a.common.iters, a.common.seed)?;
    emit(a.common.json, &r, || {
        println!(
            "prefix scan: {} elements on {} (median of {})",
            r.n, r.device, r.iters
        );
        println!(
            "  GPU  {:>10.3} ms  {:>8.3} G elems/s",
            r.gpu_ms,
            r.gpu_elems_per_s * 1e-9
        );
        println!(
            "  CPU  {:>10.3} ms  {:>8.3} G elems/s",
            r.cpu_ms,
            r.cpu_elems_per_s * 1e-9
        );
        println!(
            "  ratio GPU/CPU: {:.2}x   (result verified against the CPU scan)",
            r.ratio
        );
        print_kernels(&r.kernels);
    })
}

fn run_render(gpu: &Gpu, a: RenderArgs) -> Result<()> {
    let r = bench_render(gpu, &a.input.input(a.common.seed), a.common.iters)?;
    emit(a.common.json, &r, || {
        let i = &r.input;
        println!(
            "render: {} Gaussians, {}x{}, C = {} on {} (median of {})",
            r.gaussians, i.width, i.height, i.channels, r.device, r.iters
        );
        println!(
            "  frame      {:>10.3} ms  {:>8.1} frames/s",
            r.frame_ms, r.frames_per_s
        );
        let s = &r.stages;
        println!("  project    {:>10.3} ms", s.project_ms);
        println!("  depth sort {:>10.3} ms", s.depth_sort_ms);
        println!("  bin        {:>10.3} ms", s.bin_ms);
        println!("  blend      {:>10.3} ms", s.blend_ms);
        println!(
            "  visible {} Gaussians, {} tile intersections",
            r.visible, r.intersections
        );
        print_kernels(&r.kernels);
    })
}

/// The training-free methods, which `bench fuse` times.
fn fusion_methods() -> Vec<Lifter> {
    ALL_METHODS
        .into_iter()
        .filter(|l| matches!(l, Lifter::Fuse(_)))
        .collect()
}

fn run_fuse(gpu: &Gpu, a: FuseArgs) -> Result<()> {
    let methods = parse_methods(&a.methods, &fusion_methods())?
        .into_iter()
        .filter_map(|l| match l {
            Lifter::Fuse(m) => Some(m),
            _ => None,
        })
        .collect::<Vec<_>>();
    let (n, width, height) = match a.preset {
        Some(FusePreset::OneMillion) => (1_000_000, 1920, 1080),
        Some(FusePreset::SixMillion) => (6_000_000, 1920, 1080),
        None => (a.n, a.width, a.height),
    };
    let spec = FuseBenchSpec {
        n,
        views: a.views,
        width,
        height,
        classes: a.classes,
        iters: a.iters,
        seed: a.seed,
        scene: a.scene,
        labels: a.labels,
        export: a.export,
        views_in_flight: a.views_in_flight,
        clustering: a.clustering,
    };
    let bar = views_bar(0);
    let r = bench_fuse(gpu, &spec, &methods, |phase, done, total| {
        if bar.message() != phase {
            bar.set_message(phase.to_string());
        }
        follow(&bar)(done, total);
    })?;
    bar.finish_and_clear();
    emit(a.json, &r, || print_fuse(&r))
}

fn run_train(gpu: &Gpu, a: TrainArgs) -> Result<()> {
    let input = a.input.input(a.common.seed);
    let iters = u32::try_from(a.common.iters).unwrap_or(u32::MAX);
    let r = bench_train(gpu, &input, iters, a.semantics_only, !a.without_images)?;
    emit(a.common.json, &r, || print_train(&r))
}

fn print_train(r: &TrainBench) {
    let i = &r.input;
    let what = match (r.semantics_only, r.images) {
        (false, _) => "full",
        (true, true) => "semantics only",
        (true, false) => "semantics only, no target image",
    };
    println!(
        "train ({what}): {} Gaussians, {}x{}, C = {} on {} ({} iterations)",
        r.gaussians, i.width, i.height, i.channels, r.device, r.iters
    );
    println!("  iteration  {:>10.3} ms (wall, median)", r.iter_ms);
    println!("  forward    {:>10.3} ms (GPU, mean)", r.forward_ms);
    println!("  losses     {:>10.3} ms", r.loss_ms);
    println!("  backward   {:>10.3} ms", r.backward_ms);
    println!("  optimizer  {:>10.3} ms", r.optimizer_ms);
    print_kernels(&r.kernels);
}
