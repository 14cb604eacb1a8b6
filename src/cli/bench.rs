//! `semsplat bench`: GPU kernel throughput from timestamps, against a CPU baseline measured
//! in the same run on the same data.

use anyhow::Result;
use clap::{Args, Subcommand};
use serde::Serialize;

use semsplat::bench::{render::bench_render, scan::bench_scan, sort::bench_sort};
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
}

#[derive(Args)]
pub struct RenderArgs {
    /// Number of Gaussians.
    #[arg(long, default_value_t = 100_000)]
    n: usize,
    #[arg(long, default_value_t = 640)]
    width: u32,
    #[arg(long, default_value_t = 480)]
    height: u32,
    /// Semantic channels blended with RGB (0: RGB only).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u16).range(0..=256))]
    channels: u16,
    #[command(flatten)]
    common: CommonArgs,
}

#[derive(Args)]
pub struct CommonArgs {
    /// Timed repetitions (after one warm-up); the median is reported.
    #[arg(long, default_value_t = 5)]
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
    #[arg(long, default_value_t = 1 << 22)]
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
    #[arg(long, default_value_t = 1 << 22)]
    n: u64,
    #[command(flatten)]
    common: CommonArgs,
}

fn print_kernels(kernels: &[KernelTotal]) {
    for k in kernels {
        println!(
            "  {:<16} {:>4} dispatches {:>10.3} ms",
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

pub fn run(cmd: BenchCommand) -> Result<()> {
    let gpu = Gpu::new()?;
    match cmd {
        BenchCommand::Sort(a) => {
            let r = bench_sort(&gpu, a.n, a.bits, a.common.iters, a.common.seed)?;
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
        BenchCommand::Scan(a) => {
            let r = bench_scan(&gpu, a.n, a.common.iters, a.common.seed)?;
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
        BenchCommand::Render(a) => {
            let r = bench_render(
                &gpu,
                a.n,
                a.width,
                a.height,
                a.channels as usize,
                a.common.iters,
                a.common.seed,
            )?;
            emit(a.common.json, &r, || {
                println!(
                    "render: {} Gaussians, {}x{}, C = {} on {} (median of {})",
                    r.n, r.width, r.height, r.channels, r.device, r.iters
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
            })
        }
    }
}
