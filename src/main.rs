//! The `semsplat` command line. Each subcommand lives in `src/cli/<name>.rs`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use semsplat::util::interrupt;

mod cli;

#[derive(Parser)]
#[command(
    name = "semsplat",
    version,
    about = "Lift 2D semantic labels into 3D Gaussian Splatting scenes (Vulkan compute)",
    long_about = "Lift 2D semantic labels into 3D Gaussian Splatting scenes on a Vulkan compute \
                  backend. Runs on any Vulkan 1.3 device; without a GPU, install lavapipe with \
                  tools/setup.sh. Select a device with SEMSPLAT_DEVICE=<index or name substring>. \
                  Ctrl-C stops a run cleanly: no half-written file, exit status 130 \
                  (143 for SIGTERM)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build the default benchmark room, lift its labels with every method, and compare
    /// speed and accuracy (table, report.json, speed_vs_accuracy.png, strip.png).
    Demo(cli::demo::DemoArgs),
    /// Generate a procedural benchmark room with exact ground truth and label noise.
    // Negative numbers are values (`--levels -0.1` reaches its range check).
    #[command(allow_negative_numbers = true)]
    Synth(cli::synth::SynthArgs),
    /// Lift per-view label maps onto the Gaussians (vote, FlashSplat or segment consensus; no
    /// training).
    // Negative numbers are values (`--depth-tol -1` reaches its range check), not flags.
    #[command(allow_negative_numbers = true)]
    Fuse(Box<cli::fuse::FuseArgs>),
    /// Sum the partial evidence of `fuse --shard K/N` runs (every shard once) and write what
    /// a single `fuse` of every view writes, bit for bit.
    Merge(Box<cli::merge::MergeArgs>),
    /// Train semantic logits jointly with geometry and appearance (Gaussian Semantics), or the
    /// logits alone with --semantics-only.
    #[command(allow_negative_numbers = true)]
    Train(Box<cli::train::TrainArgs>),
    /// Render views of a scene on the GPU (RGB, and semantic labels with --semantics).
    #[command(allow_negative_numbers = true)]
    Render(cli::render::RenderArgs),
    /// Score a classified scene against label maps (mIoU, pixel and 3D accuracy).
    ///
    /// mIoU is the mean IoU over the classes the label maps hold on the scored views: a class
    /// the scene draws where the maps hold none is not averaged in (its pixels lower the IoU
    /// of the classes they cover). Pixels without a label are not scored.
    Eval(cli::eval::EvalArgs),
    /// Robustness: every method's mIoU as one kind of label noise grows (chart + JSON).
    // Negative numbers are values (`--levels -0.1` reaches its range check).
    #[command(allow_negative_numbers = true)]
    Sweep(cli::sweep::SweepArgs),
    /// Summarize a PLY scene, a camera model or a label folder, and report problems.
    Inspect(cli::inspect::InspectArgs),
    /// Show the Vulkan device semsplat would use and what it supports.
    Info(cli::info::InfoArgs),
    /// Measure GPU kernels (throughput from GPU timestamps) against CPU baselines.
    #[command(subcommand)]
    Bench(cli::bench::BenchCommand),
}

impl Command {
    /// Whether the command polls for Ctrl-C in its long loops (train per iteration, fuse,
    /// render and eval per view, sweep per level) and so stops cleanly with an error; the
    /// others exit at the first signal, after removing their temp files.
    fn polls_for_interrupt(&self) -> bool {
        matches!(
            self,
            Command::Train(_)
                | Command::Fuse(_)
                | Command::Render(_)
                | Command::Eval(_)
                | Command::Sweep(_)
        )
    }
}

impl Command {
    /// Whether the command's results are the files it writes, its standard output a
    /// summary: a closed or full standard output must not stop it before the files
    /// (`sweep ... | head`); the others end quietly on a closed pipe, as shell tools do.
    fn results_are_files(&self) -> bool {
        matches!(self, Command::Sweep(_) | Command::Demo(_))
    }
}

/// A standard output that cannot be written (`info --json > /dev/full`) ends the run with
/// an error, not a panic's backtrace: `println!` panics with this message, which the hook
/// turns into `error: ...` and exit status 1.
fn report_stdout_failures_as_errors() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = (info.payload().downcast_ref::<String>())
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if let Some(cause) = message.strip_prefix("failed printing to stdout: ") {
            interrupt::exit_removing_temp_files(&format!("writing standard output: {cause}"), 1);
        }
        default(info);
    }));
}

fn main() -> ExitCode {
    semsplat::util::memory::configure_malloc();
    let cli = Cli::parse();
    if !cli.command.results_are_files() {
        interrupt::end_quietly_on_closed_stdout();
    }
    report_stdout_failures_as_errors();
    if let Err(e) = interrupt::install_handler(cli.command.polls_for_interrupt()) {
        eprintln!("warning: {e:#}; Ctrl-C may leave temp files behind");
    }
    let result = match cli.command {
        Command::Demo(args) => cli::demo::run(args),
        Command::Eval(args) => cli::eval::run(args),
        Command::Info(args) => cli::info::run(args),
        Command::Sweep(args) => cli::sweep::run(args),
        Command::Bench(cmd) => cli::bench::run(cmd),
        Command::Inspect(args) => cli::inspect::run(args),
        Command::Synth(args) => cli::synth::run(args),
        Command::Render(args) => cli::render::run(args),
        Command::Fuse(args) => cli::fuse::run(*args),
        Command::Merge(args) => cli::merge::run(*args),
        Command::Train(args) => cli::train::run(*args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if interrupt::is_interruption(&e) => {
            eprintln!("error: {}", interrupt::Interrupted);
            ExitCode::from(interrupt::exit_code())
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
