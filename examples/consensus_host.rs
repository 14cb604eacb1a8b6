//! The segment consensus's host passes (clustering and decision) run again and again on one
//! run's observations, for profiling them (`perf record`, `perf stat`, `taskset`) without
//! the views between: the office at 1080p spends about a minute on lavapipe's views and
//! a second in these passes.
//!
//! ```sh
//! cargo build --release --example consensus_host
//! target/release/examples/consensus_host --scene OFFICE --labels OFFICE/labels_noisy \
//!     --cache /tmp/office.observations --repeats 5 --profile
//! ```
//!
//! The first call runs the views (as `semsplat fuse --method segment-consensus` does) and
//! writes the observations and neighbours to `--cache`; later calls read them from there.
//! Each repetition prints the clustering's and the decision's seconds and a hash of the
//! segments, classes, confidences and entropies, which must not change between
//! repetitions, and changes between builds only when their outputs do. The process's
//! allocator is set as the CLI's (one arena, fixed thresholds) unless `--glibc-defaults`.
//! Beside them, the allocations the clustering and the decision made on other threads than
//! the caller's, and the process's page faults: under the one arena those threads wait on
//! each other's allocations, and pages touched for the first time are zeroed and mapped
//! one by one, neither of which a model of their items (`--model-threads`) sees (the
//! rounds' candidates listed anew for every Gaussian made two cores slower than one:
//! docs/robustness-log.md, "The rounds' allocations").

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::hash::{Hash, Hasher};
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{ensure, Context, Result};
use clap::Parser;
use semsplat::dataset::{Dataset, DatasetPaths};
use semsplat::fuse::consensus::{consensus_run, ConsensusInput, Kept};
use semsplat::fuse::consensus_cluster::cluster_segments_timed;
use semsplat::fuse::consensus_decide::{decide_timed, Consensus};
use semsplat::fuse::consensus_order::SpatialOrder;
use semsplat::fuse::consensus_segments::Observations;
use semsplat::fuse::consensus_split::split_near_ties;
use semsplat::fuse::consensus_surface::SurfaceNormals;
use semsplat::fuse::{Clustering, ConsensusParams, FuseConfig, GaussianShapes, Method};
use semsplat::scene::labels::LabelFormat;
use semsplat::scene::Gaussians;
use semsplat::util::scaling::{estimate_scaling, Scaling, THREADS};

/// The system allocator, counting the allocations made on threads other than `main`'s.
struct CountingAllocator;

/// Allocations and reallocations on other threads than `main`'s, since the process began.
static OTHER_THREADS_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    /// Set on `main`'s thread: its allocations are not counted.
    static CALLER: Cell<bool> = const { Cell::new(false) };
}

fn count_allocation() {
    if !CALLER.with(Cell::get) {
        OTHER_THREADS_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: every call is passed on to `System` unchanged; the count touches no allocation.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_allocation();
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count_allocation();
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_allocation();
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// What a stretch of work cost beside its time, in ways a model of its items on one core
/// does not see.
#[derive(Clone, Copy)]
struct Costs {
    /// Allocations other threads made (under one arena they wait on each other's).
    worker_allocations: u64,
    /// The process's minor page faults: pages touched for the first time, each zeroed by
    /// the kernel (many threads faulting at once share the process's memory map).
    page_faults: u64,
}

/// `work`'s output and what it cost meanwhile ([`Costs`]).
fn costs<T>(work: impl FnOnce() -> T) -> (T, Costs) {
    let (allocations, faults) = (
        OTHER_THREADS_ALLOCATIONS.load(Ordering::Relaxed),
        minor_faults(),
    );
    let out = work();
    let costs = Costs {
        worker_allocations: OTHER_THREADS_ALLOCATIONS.load(Ordering::Relaxed) - allocations,
        page_faults: minor_faults().saturating_sub(faults),
    };
    (out, costs)
}

/// The process's minor page faults so far (`minflt` of /proc/self/stat; 0 without it).
fn minor_faults() -> u64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // The fields after the command's name, which ends at the last ')': minflt is the
    // eighth of them (the tenth of the line).
    let after_name = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    after_name
        .split_whitespace()
        .nth(7)
        .and_then(|f| f.parse().ok())
        .unwrap_or(0)
}

#[derive(Parser)]
struct Args {
    /// Scene folder (scene.ply, cameras.json).
    #[arg(long)]
    scene: PathBuf,
    /// Label maps of the scene's cameras (read only when the cache does not exist).
    #[arg(long)]
    labels: PathBuf,
    /// Observations and neighbours of one run: read if the file exists, else written.
    #[arg(long)]
    cache: PathBuf,
    /// Clusterings and decisions to run.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Print each repetition's step times (the clustering's and decision's profiles).
    #[arg(long)]
    profile: bool,
    /// Leave glibc's allocator as it starts (the CLI sets one arena and fixed thresholds).
    #[arg(long)]
    glibc_defaults: bool,
    /// Also print each repetition's clustering and decision modeled on 1, 2, 4, ... 32
    /// threads, from each parallel item's time (semsplat::util::scaling; run on one core,
    /// `taskset -c 0`, for items timed alone).
    #[arg(long)]
    model_threads: bool,
    /// The clustering's joins after the outright joins (the observations' cache does not
    /// depend on it).
    #[arg(long, value_enum, default_value_t = Clustering::Order)]
    clustering: Clustering,
}

fn main() -> Result<()> {
    CALLER.with(|caller| caller.set(true));
    let args = Args::parse();
    if !args.glibc_defaults {
        semsplat::util::memory::configure_malloc();
    }
    let (g, _) = semsplat::bench::read_scene_folder(&args.scene)?;
    let shapes = GaussianShapes::of(&g);
    let params = ConsensusParams {
        clustering: args.clustering,
        ..ConsensusParams::default()
    };
    let run = match args.cache.exists() {
        true => read_cache(&args.cache)?,
        false => {
            let run = observe_views(&args, &g, &params)?;
            write_cache(&args.cache, &run)?;
            run
        }
    };
    ensure!(
        run.observations.n == g.len(),
        "{} holds {} Gaussians' observations, the scene {}",
        args.cache.display(),
        run.observations.n,
        g.len()
    );
    let order = SpatialOrder::of(shapes.means);
    let surfaces = SurfaceNormals::of(&shapes, &order, &params);
    for _ in 0..args.repeats {
        let (((segment, clustering), cluster_model), cluster_costs) = costs(|| {
            timed(args.model_threads, || {
                let (clustered, mut done) =
                    cluster_segments_timed(&run.observations, &run.knn, &surfaces, &params);
                let segment = split_near_ties(
                    &run.observations,
                    clustered,
                    run.classes,
                    &params,
                    &mut done,
                );
                (segment, done)
            })
        });
        let (((consensus, decision), decide_model), decide_costs) = costs(|| {
            timed(args.model_threads, || {
                decide_timed(&run.observations, &run.knn, segment, run.classes, &params)
            })
        });
        println!(
            "clustering {:.3} s, decision {:.3} s, outputs {:016x}",
            cluster_model.measured_s,
            decide_model.measured_s,
            outputs_hash(&consensus)
        );
        let [c, d] = [cluster_costs, decide_costs];
        println!(
            "  allocations on the worker threads: clustering {}, decision {}; page faults: \
             clustering {}, decision {}",
            c.worker_allocations, d.worker_allocations, c.page_faults, d.page_faults
        );
        if args.profile {
            println!("  {clustering:?}\n  {decision:?}");
        }
        if args.model_threads {
            print_models(cluster_model, decide_model);
        }
    }
    Ok(())
}

/// The clustering's and the decision's times modeled on 1 to 32 threads (`--model-threads`),
/// and per place in the source that makes parallel calls its time and longest item.
fn print_models(cluster_model: Scaling, decide_model: Scaling) {
    for (step, model) in [("clustering", cluster_model), ("decision", decide_model)] {
        let modeled = THREADS.iter().zip(model.modeled_s);
        let each = modeled.map(|(t, s)| format!("{t}: {s:.3}"));
        println!(
            "  {step} modeled (threads: s) {}; {} parallel calls, {:.3} s of it",
            each.collect::<Vec<_>>().join(", "),
            model.calls,
            model.calls_s
        );
        for place in &model.by_place {
            let [one, _, _, eight, sixteen, _] = place.scheduled_s;
            println!(
                "    {} ({} calls): {:.4} s measured; modeled 1: {one:.4}, 8: {eight:.4}, 16: {sixteen:.4}; longest item {:.4}",
                place.place, place.calls, place.calls_s, place.longest_item_s
            );
        }
    }
}

/// `work`'s output and wall time; with `model`, every parallel item timed too
/// ([`estimate_scaling`]). Only then: the runs on more cores (the device script's) time the
/// passes as the CLI runs them.
fn timed<T>(model: bool, work: impl FnOnce() -> T) -> (T, Scaling) {
    if model {
        return estimate_scaling(work);
    }
    let start = std::time::Instant::now();
    let out = work();
    let measured_s = start.elapsed().as_secs_f64();
    let scaling = Scaling {
        measured_s,
        ..Default::default()
    };
    (out, scaling)
}

/// What the host passes read: the observations and neighbours (both numbered in space) and
/// the classes the labels hold.
struct Observed {
    observations: Observations,
    knn: Vec<u32>,
    classes: usize,
}

/// The views of one segment consensus run, as `fuse` runs them.
fn observe_views(args: &Args, g: &Gaussians, params: &ConsensusParams) -> Result<Observed> {
    let dataset = Dataset::open(&DatasetPaths {
        cameras: &args.scene.join("cameras.json"),
        labels: &args.labels,
        class_table: None,
        train_only: false,
        format: LabelFormat::default(),
    })?;
    let gpu = semsplat::gpu::Gpu::new()?;
    let scene = semsplat::render::GpuScene::upload(&gpu, g)?;
    let input = ConsensusInput {
        gpu: &gpu,
        scene: &scene,
        shapes: GaussianShapes::of(g),
        cams: &dataset.cameras,
        labels: &dataset,
        classes: dataset.classes.len(),
    };
    let cfg = FuseConfig {
        method: Method::SegmentConsensus,
        ..Default::default()
    };
    let run = consensus_run(&input, &cfg, params, Kept::Observations, &mut |_, _| {})?;
    Ok(Observed {
        observations: run.observations,
        knn: run.knn,
        classes: dataset.classes.len(),
    })
}

/// A hash of what the decision gives every Gaussian (and its segments).
fn outputs_hash(consensus: &Consensus) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    consensus.segment.hash(&mut h);
    consensus.assignment.class.hash(&mut h);
    let floats = consensus
        .assignment
        .confidence
        .iter()
        .chain(&consensus.entropy);
    floats.for_each(|x| x.to_bits().hash(&mut h));
    h.finish()
}

fn write_cache(path: &Path, run: &Observed) -> Result<()> {
    let o = &run.observations;
    let mut f = BufWriter::new(std::fs::File::create(path).context("cannot create the cache")?);
    write_words(&mut f, &[o.n as u64, run.classes as u64])?;
    write_words(
        &mut f,
        &o.offsets.iter().map(|&x| x as u64).collect::<Vec<_>>(),
    )?;
    write_words(&mut f, &o.view)?;
    write_words(&mut f, &o.label)?;
    write_words(&mut f, &o.region)?;
    write_words(&mut f, &o.edge.iter().map(|&e| e as u8).collect::<Vec<_>>())?;
    write_words(&mut f, &run.knn)?;
    f.flush().context("cannot write the cache")
}

fn read_cache(path: &Path) -> Result<Observed> {
    let file = std::fs::File::open(path).context("cannot open the cache")?;
    let bytes = file.metadata()?.len();
    let mut f = BufReader::new(file);
    let sizes: Vec<u64> = read_words(&mut f, bytes)?;
    ensure!(
        sizes.len() == 2,
        "{} is not a cache of observations",
        path.display()
    );
    let offsets: Vec<u64> = read_words(&mut f, bytes)?;
    let observations = Observations {
        n: sizes[0] as usize,
        offsets: offsets.into_iter().map(|x| x as usize).collect(),
        view: read_words(&mut f, bytes)?,
        label: read_words(&mut f, bytes)?,
        region: read_words(&mut f, bytes)?,
        edge: read_words::<u8>(&mut f, bytes)?
            .into_iter()
            .map(|e| e != 0)
            .collect(),
    };
    let knn = read_words(&mut f, bytes)?;
    let classes = sizes[1] as usize;
    Ok(Observed {
        observations,
        knn,
        classes,
    })
}

/// A list as its length and its bytes (this machine's byte order: a cache is local).
fn write_words<T: bytemuck::Pod>(f: &mut impl Write, items: &[T]) -> Result<()> {
    f.write_all(&(items.len() as u64).to_le_bytes())?;
    Ok(f.write_all(bytemuck::cast_slice(items))?)
}

/// A list [`write_words`] wrote, in a file of `bytes` bytes.
fn read_words<T: bytemuck::Pod>(f: &mut impl Read, bytes: u64) -> Result<Vec<T>> {
    let mut len = [0u8; 8];
    f.read_exact(&mut len).context("the cache ends early")?;
    let len = u64::from_le_bytes(len);
    ensure!(
        len.saturating_mul(std::mem::size_of::<T>() as u64) <= bytes,
        "the cache is not one this program wrote"
    );
    let mut items = vec![T::zeroed(); len as usize];
    f.read_exact(bytemuck::cast_slice_mut(&mut items))
        .context("the cache ends early")?;
    Ok(items)
}
