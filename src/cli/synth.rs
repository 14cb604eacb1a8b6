//! `semsplat synth`: generate a procedural benchmark room (the logic lives in
//! `semsplat::synth`; this file parses arguments, guards the output folder and reports).

use std::path::{Path, PathBuf};
use std::sync::LazyLock;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;

use super::args;
use super::progress::{follow, phase_bar};
use semsplat::scene::ply::every_scenes_vertex_bytes;
use semsplat::synth::writer::{OUTPUT_LAYOUT, ROOM_FILE, SUMMARY_FILE};
use semsplat::synth::{
    self, NoiseReport, NoiseSpec, RoomSource, SynthConfig, DEFAULT_HEIGHT, DEFAULT_HFOV_DEG,
    DEFAULT_INIT_JITTER, DEFAULT_INIT_SPACING, DEFAULT_SPACING, DEFAULT_TEST_VIEWS,
    DEFAULT_TRAIN_VIEWS, DEFAULT_WIDTH, HFOV_RANGE, INIT_JITTER_RANGE, INIT_SPACING_RANGE,
    MAX_SIDE, NOISE_KEYS_HELP, PRESETS, SPACING_RANGE,
};
use semsplat::util::free_space::check_free_space;

static AFTER_HELP: LazyLock<String> = LazyLock::new(|| {
    let presets: String = PRESETS
        .iter()
        .map(|(name, about)| format!("  {name:<8} {about}\n"))
        .collect();
    format!(
        "Presets (--preset):\n{presets}  FILE.json  a room description: the room.json any run writes, e.g.\n             \
         {{\"size\": [4, 3, 2.5], \"objects\": [{{\"name\": \"box_0\", \"class\": \"box\", \"parts\": [\n               \
         {{\"shape\": {{\"box\": {{\"center\": [1, 1, 0.25], \"size\": [0.5, 0.5, 0.5], \"yaw_deg\": 0}}}},\n                \
         \"material\": {{\"color\": [200, 80, 40], \"pattern\": \"wood\", \"scale\": 0.1}}}}]}}]}}\n             \
         shapes: box {{center, size, yaw_deg}}, cylinder {{center, radius, height, axis}},\n             \
         sphere {{center, radius}}, quad {{center, half_u, half_v}}; patterns: plain, noise,\n             \
         checker, stripes, wood. World: z up, floor at z = 0, room spans [0, size] meters\n             \
         (each part centered inside it). DIR  a synth output folder: its room.json.\n\n\
         Ground truth: RGB, class and instance maps are exact ray casts of the analytic primitives\n\
         (one ray per pixel center, Lambertian shading with a fixed light, so SH degree 0 suffices).\n\
         Cameras: --views train and --test-views held-out views at 0.8-1.8 m, looking at objects.\n\n\
         Noise (--noise key=value,...):\n{NOISE_KEYS_HELP}\n\n\
         Output (--out DIR):\n{OUTPUT_LAYOUT}\n\n\
         Example:\n  semsplat synth --preset living --out rooms/living --seed 3 \\\n    \
         --noise flicker=0.2,boundary=2,consistent=0.6,salt=0.01,missing=0.05"
    )
});

#[derive(Args)]
#[command(after_long_help = AFTER_HELP.as_str())]
pub struct SynthArgs {
    /// Room: a preset (office, living, tiny) or a room JSON file (see --help).
    #[arg(long, value_name = "NAME|FILE", default_value = "office")]
    preset: String,
    /// Output folder (created; an existing non-empty folder needs --force unless it holds an
    /// earlier synth output).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Seed of the layout jitter, cameras and noise: same seed, same bytes.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Number of train views.
    #[arg(long, default_value_t = DEFAULT_TRAIN_VIEWS)]
    views: usize,
    /// Number of held-out test views.
    #[arg(long, default_value_t = DEFAULT_TEST_VIEWS)]
    test_views: usize,
    /// Image width in pixels.
    #[arg(long, default_value_t = DEFAULT_WIDTH, value_parser = image_side)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = DEFAULT_HEIGHT, value_parser = image_side)]
    height: u32,
    /// Horizontal field of view in degrees (20..=120).
    #[arg(long, default_value_t = DEFAULT_HFOV_DEG,
          value_parser = |s: &str| in_range(s, HFOV_RANGE, "degrees"))]
    fov: f64,
    /// Gaussian spacing on surfaces in meters, 0.002..=1 (density ~ 1/spacing^2; only
    /// surfaces some view sees get Gaussians, held-out views included: office ~150k at 0.03
    /// with the default views, 41k at 0.03 and ~1M at 0.0053 with one view and
    /// --test-views 0).
    #[arg(long, default_value_t = DEFAULT_SPACING,
          value_parser = |s: &str| in_range(s, SPACING_RANGE, "m"))]
    spacing: f64,
    /// Point spacing of init.ply in meters.
    #[arg(long, default_value_t = DEFAULT_INIT_SPACING,
          value_parser = |s: &str| in_range(s, INIT_SPACING_RANGE, "m"))]
    init_spacing: f64,
    /// Standard deviation of init.ply's offsets off the surface, meters.
    #[arg(long, default_value_t = DEFAULT_INIT_JITTER,
          value_parser = |s: &str| in_range(s, INIT_JITTER_RANGE, "m"))]
    init_jitter: f64,
    /// Label noise, e.g. flicker=0.3,boundary=2,consistent=0.6,salt=0.01,missing=0.05 (keys in
    /// --help); writes labels_noisy/.
    #[arg(long, value_name = "SPEC")]
    noise: Option<String>,
    /// Write into a non-empty folder that is not an earlier synth output (files there keep
    /// their place unless synth writes the same name: train_NNNN.png, test_NNNN.png in
    /// images/, labels/, instances/, labels_noisy/, vis/, and the room's files).
    #[arg(long)]
    force: bool,
    /// Skip the palette previews under vis/.
    #[arg(long)]
    no_previews: bool,
    /// Keep Gaussians on surfaces no camera sees (by default they are left out, as 3DGS
    /// training would prune them; a surface only held-out views see keeps its Gaussians, so
    /// that those views show a room, not holes).
    #[arg(long)]
    keep_hidden: bool,
}

/// An image side of 1..=MAX_SIDE pixels.
fn image_side(s: &str) -> Result<u32, String> {
    let range = format!("1..={MAX_SIDE} pixels");
    args::within::<u32>(s, 1.0, MAX_SIDE as f64, &range)
}

/// A finite number in `range`, of `unit`.
fn in_range(s: &str, range: std::ops::RangeInclusive<f64>, unit: &str) -> Result<f64, String> {
    let spelled = format!("{range:?} {unit}");
    args::within::<f64>(s, *range.start(), *range.end(), &spelled)
}

pub fn run(args: SynthArgs) -> Result<()> {
    let noise = match &args.noise {
        Some(spec) => Some(spec.parse::<NoiseSpec>().context("--noise")?),
        None => None,
    };
    let config = SynthConfig {
        room: RoomSource::from_arg(&args.preset)?,
        seed: args.seed,
        train_views: args.views,
        test_views: args.test_views,
        width: args.width,
        height: args.height,
        hfov_deg: args.fov,
        spacing: args.spacing,
        init_spacing: args.init_spacing,
        init_jitter: args.init_jitter,
        noise,
        previews: !args.no_previews,
        keep_hidden: args.keep_hidden,
    };
    config.validate()?;
    check_output_folder(&args.out, args.force)?;

    let start = Instant::now();
    let bar = phase_bar("ray casting");
    let scene = synth::generate_with_progress(&config, &follow(&bar))?;
    bar.finish_and_clear();
    let generated = start.elapsed();
    // The scene alone, before its views' images (their compressed size is not known
    // yet): a full disk found at the write would leave a stopped room.
    let scene_bytes =
        scene.gaussians.len() * every_scenes_vertex_bytes(scene.gaussians.sh_coeffs());
    check_free_space("--out", &args.out, scene_bytes as u64, "the room's scene")?;
    let bar = phase_bar("writing");
    synth::write_synth_with_progress(&args.out, &scene, &follow(&bar))?;
    bar.finish_and_clear();

    let room = &scene.room;
    println!(
        "wrote {}: {} train + {} test views at {}x{}, {} classes, {} instances, {} Gaussians, {} init points ({:.1}s: {:.1}s generating)",
        args.out.display(),
        config.train_views,
        config.test_views,
        config.width,
        config.height,
        room.classes.classes.len(),
        room.instances.len(),
        scene.gaussians.len(),
        scene.init_points.len(),
        start.elapsed().as_secs_f64(),
        generated.as_secs_f64(),
    );
    if let Some(noisy) = &scene.noisy {
        print_noise(&noisy.report);
    }
    Ok(())
}

/// The noise's measured rates, the objects labeled consistently wrong, and a warning where
/// fewer were picked than asked for.
fn print_noise(report: &NoiseReport) {
    let m = &report.measured;
    println!(
        "noise {} (seed {}): flicker {:.3} of (view, object) pairs; salt {:.4}, missing {:.4}, boundary {:.4} of pixels",
        report.spec, report.seed, m.flicker.rate, m.salt.rate, m.missing.rate, m.boundary.rate
    );
    for c in &report.consistent {
        println!(
            "  consistent: {} ({}) labeled {} in {} of {} views",
            c.instance_name, c.true_class_name, c.wrong_class_name, c.views_wrong, c.views_visible
        );
    }
    let asked = &report.requested;
    let picked = report.consistent.len();
    if asked.consistent > 0.0 && picked < asked.consistent_objects {
        eprintln!(
            "warning: consistent={} picked {picked} of the {} objects asked for: the room \
             has no more objects that a train view sees and that have a look-alike class \
             (walls, floor and ceiling are never picked)",
            asked.consistent, asked.consistent_objects
        );
    }
}

/// Refuses to scatter files into a folder holding something else, unless forced.
fn check_output_folder(out: &Path, force: bool) -> Result<()> {
    if out.exists() && !out.is_dir() {
        bail!("--out {} exists and is not a folder", out.display());
    }
    let non_empty = out.is_dir()
        && std::fs::read_dir(out)
            .with_context(|| format!("reading {}", out.display()))?
            .next()
            .is_some();
    // room.json alone: a run stopped part-way (the summary is written last).
    let earlier_synth = [SUMMARY_FILE, ROOM_FILE]
        .iter()
        .any(|f| out.join(f).is_file());
    if non_empty && !force && !earlier_synth {
        bail!(
            "--out {} is not empty and holds no earlier synth output; pick another folder or pass --force",
            out.display()
        );
    }
    semsplat::util::check_output_folder("--out", out)
}
