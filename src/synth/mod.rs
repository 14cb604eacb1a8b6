//! Procedural benchmark rooms with exact ground truth and label-noise models.
//!
//! A room (a built-in preset or a JSON description, see [`room_spec`]) is made of analytic
//! primitives, each belonging to one object instance of one class. From it we derive, all
//! deterministic in the seed:
//! - ground-truth RGB, class and instance maps by exact CPU ray casting ([`raycast`]),
//!   independent of any Gaussian renderer;
//! - Gaussians sampling the visible surfaces with their true class and instance
//!   ([`surface_sampling`]), kept where some camera sees them ([`visibility`]), plus a sparse
//!   jittered point cloud for training from scratch;
//! - cameras inside the room looking at its content ([`views`]);
//! - noisy label maps imitating a 2D segmenter ([`noise`], grammar in [`noise_spec`]).
//!
//! [`generate`] builds everything in memory; [`write_synth`] writes the output folder.

pub mod bvh;
pub mod confusion;
pub mod furniture;
pub mod materials;
pub mod noise;
pub mod noise_spec;
pub mod palette;
pub mod presets;
pub mod primitives;
pub mod raycast;
pub mod room;
pub mod room_spec;
pub mod shading;
pub mod surface_sampling;
pub mod views;
pub mod visibility;
pub mod writer;

use std::path::PathBuf;

use anyhow::{bail, ensure, Result};

pub use noise::{NoiseReport, NoisyLabels};
pub use noise_spec::{NoiseSpec, NOISE_KEYS_HELP};
pub use presets::PRESETS;
pub use raycast::{render_view, ViewTruth, IGNORE};
pub use room::Room;
pub use room_spec::RoomSpec;
pub use writer::{write_synth, write_synth_with_progress};

use crate::scene::{Camera, Gaussians};
use crate::util::Rng;

/// Where the room comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum RoomSource {
    /// A built-in preset (`PRESETS`), jittered by the seed.
    Preset(String),
    /// A room JSON file (the format of `room.json`).
    File(PathBuf),
    Spec(Box<RoomSpec>),
}

impl RoomSource {
    /// A preset name, or a path to a room JSON file; anything else is an error naming the presets.
    pub fn from_arg(arg: &str) -> Result<Self> {
        if PRESETS.iter().any(|(name, _)| *name == arg) {
            return Ok(RoomSource::Preset(arg.to_string()));
        }
        let path = PathBuf::from(arg);
        if path.is_file() {
            return Ok(RoomSource::File(path));
        }
        // A synth output folder: its room.
        let room_file = path.join(writer::ROOM_FILE);
        if path.is_dir() && room_file.is_file() {
            return Ok(RoomSource::File(room_file));
        }
        if arg.ends_with(".json") {
            bail!("room file '{arg}' does not exist");
        }
        bail!(
            "unknown preset '{arg}': choose one of {} or give the path of a room JSON file (the room.json of any synth output is one)",
            presets::preset_names()
        )
    }

    pub fn resolve(&self, seed: u64) -> Result<RoomSpec> {
        match self {
            RoomSource::Preset(name) => match presets::preset(name, seed) {
                Some(spec) => Ok(spec),
                None => bail!(
                    "unknown preset '{name}': choose one of {}",
                    presets::preset_names()
                ),
            },
            RoomSource::File(path) => RoomSpec::load(path),
            RoomSource::Spec(spec) => Ok((**spec).clone()),
        }
    }
}

/// Everything `generate` needs; `SynthConfig::new` gives the CLI defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthConfig {
    pub room: RoomSource,
    pub seed: u64,
    pub train_views: usize,
    pub test_views: usize,
    pub width: u32,
    pub height: u32,
    /// Horizontal field of view in degrees.
    pub hfov_deg: f64,
    /// Gaussian grid spacing on surfaces in meters (density ~ 1 / spacing^2).
    pub spacing: f64,
    /// Point spacing of init.ply in meters.
    pub init_spacing: f64,
    /// Standard deviation of init.ply's offsets along the surface normal, meters.
    pub init_jitter: f64,
    /// Label noise; `None` writes no labels_noisy/.
    pub noise: Option<NoiseSpec>,
    /// Write palette previews of label maps under vis/.
    pub previews: bool,
    /// Keep the Gaussians no camera sees (a trained scene would have pruned them).
    pub keep_hidden: bool,
}

pub const DEFAULT_TRAIN_VIEWS: usize = 24;
pub const DEFAULT_TEST_VIEWS: usize = 8;
pub const DEFAULT_WIDTH: u32 = 640;
pub const DEFAULT_HEIGHT: u32 = 480;
pub const DEFAULT_HFOV_DEG: f64 = 65.0;
pub const DEFAULT_SPACING: f64 = 0.03;
pub const DEFAULT_INIT_SPACING: f64 = 0.12;
pub const DEFAULT_INIT_JITTER: f64 = 0.01;
/// Largest image side `synth` renders, in pixels.
pub const MAX_SIDE: u32 = 8192;
/// The ranges of the numeric settings (checked by [`SynthConfig::validate`] and the CLI's
/// parsers): horizontal field of view in degrees, Gaussian spacing, init point spacing and
/// init jitter in metres.
pub const HFOV_RANGE: std::ops::RangeInclusive<f64> = 20.0..=120.0;
pub const SPACING_RANGE: std::ops::RangeInclusive<f64> = 0.002..=1.0;
pub const INIT_SPACING_RANGE: std::ops::RangeInclusive<f64> = 0.01..=5.0;
pub const INIT_JITTER_RANGE: std::ops::RangeInclusive<f64> = 0.0..=1.0;
const MAX_TOTAL_PIXELS: f64 = 4e8;
const MAX_GAUSSIANS: f64 = 2e7;

impl SynthConfig {
    pub fn new(room: RoomSource) -> Self {
        SynthConfig {
            room,
            seed: 0,
            train_views: DEFAULT_TRAIN_VIEWS,
            test_views: DEFAULT_TEST_VIEWS,
            width: DEFAULT_WIDTH,
            height: DEFAULT_HEIGHT,
            hfov_deg: DEFAULT_HFOV_DEG,
            spacing: DEFAULT_SPACING,
            init_spacing: DEFAULT_INIT_SPACING,
            init_jitter: DEFAULT_INIT_JITTER,
            noise: None,
            previews: true,
            keep_hidden: false,
        }
    }

    pub fn preset(name: &str) -> Self {
        SynthConfig::new(RoomSource::Preset(name.to_string()))
    }

    /// Checks the numbers (the room is checked when built).
    pub fn validate(&self) -> Result<()> {
        ensure!(
            self.train_views >= 1,
            "need at least 1 train view (--views), got 0"
        );
        ensure!(
            (1..=MAX_SIDE).contains(&self.width) && (1..=MAX_SIDE).contains(&self.height),
            "image size must be 1..={MAX_SIDE} pixels per side, got {}x{}",
            self.width,
            self.height
        );
        let pixels =
            (self.train_views + self.test_views) as f64 * self.width as f64 * self.height as f64;
        ensure!(
            pixels <= MAX_TOTAL_PIXELS,
            "{} views of {}x{} are {pixels:.0} pixels in all, more than the {MAX_TOTAL_PIXELS:.0} held in memory; use fewer or smaller views",
            self.train_views + self.test_views,
            self.width,
            self.height
        );
        ensure!(
            HFOV_RANGE.contains(&self.hfov_deg),
            "field of view must be {HFOV_RANGE:?} degrees, got {}",
            self.hfov_deg
        );
        ensure!(
            SPACING_RANGE.contains(&self.spacing),
            "Gaussian spacing must be {SPACING_RANGE:?} m, got {}",
            self.spacing
        );
        ensure!(
            INIT_SPACING_RANGE.contains(&self.init_spacing),
            "init point spacing must be {INIT_SPACING_RANGE:?} m, got {}",
            self.init_spacing
        );
        ensure!(
            INIT_JITTER_RANGE.contains(&self.init_jitter),
            "init jitter must be {INIT_JITTER_RANGE:?} m, got {}",
            self.init_jitter
        );
        Ok(())
    }
}

/// A generated scene, all in memory. `views[i]` is what `cameras[i]` sees.
#[derive(Clone, Debug)]
pub struct SynthScene {
    pub config: SynthConfig,
    pub room: Room,
    /// Train views first, then test views (`Camera::split`).
    pub cameras: Vec<Camera>,
    pub views: Vec<ViewTruth>,
    /// Surface Gaussians with `class_ids` and `instance_ids`.
    pub gaussians: Gaussians,
    /// Source primitive of each Gaussian (index into `room.primitives`).
    pub gaussian_primitives: Vec<u32>,
    /// Sparse jittered cloud for training from scratch (no labels).
    pub init_points: Gaussians,
    pub noisy: Option<NoisyLabels>,
}

/// Reports `(done, total)` views as ray casting or writing goes, from any of the worker
/// threads (the CLI draws it as a progress bar; the library draws nothing).
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

/// Builds the scene described by `config`.
pub fn generate(config: &SynthConfig) -> Result<SynthScene> {
    generate_with_progress(config, &|_, _| {})
}

/// `generate`, calling `progress(done, total)` once per rendered view.
pub fn generate_with_progress(config: &SynthConfig, progress: Progress) -> Result<SynthScene> {
    config.validate()?;
    let room = Room::build(config.room.resolve(config.seed)?)?;
    // Both grids sample every surface: each is bounded before anything is sampled (an
    // init grid of a large room at the smallest spacing would take billions of points).
    for (option, spacing, what) in [
        ("--spacing", config.spacing, "Gaussians"),
        ("--init-spacing", config.init_spacing, "init points"),
    ] {
        let estimate = surface_sampling::estimated_samples(&room, spacing);
        if estimate > MAX_GAUSSIANS {
            let (part_of, area) = surface_sampling::largest_part(&room).unwrap_or(("", 0.0));
            bail!(
                "{option} {spacing} m would give about {estimate:.2e} {what} over the room's \
                 {:.2e} m² of surfaces (limit {MAX_GAUSSIANS:.2e}; the largest part, of \
                 '{part_of}', has {area:.2e} m²); use a larger {option}, or smaller surfaces",
                surface_sampling::estimated_samples(&room, 1.0)
            );
        }
    }
    let root = Rng::new(config.seed);
    let view_cfg = views::ViewConfig {
        width: config.width,
        height: config.height,
        hfov_deg: config.hfov_deg,
        train: config.train_views,
        test: config.test_views,
    };
    let cameras = views::place_cameras(&room, &view_cfg, &root.fork(1))?;
    let rendered = raycast::render_views(&room, &cameras, progress);
    let mut samples = surface_sampling::sample_surfaces(&room, config.spacing);
    if !config.keep_hidden {
        let seen = visibility::seen_by_any(&room, &cameras, &samples);
        let mut flags = seen.into_iter();
        samples.retain(|_| flags.next().unwrap_or(false));
    }
    let gaussians = surface_sampling::gaussians_from_samples(&room, &samples);
    let gaussian_primitives = samples.iter().map(|s| s.primitive).collect();
    let init_points = surface_sampling::init_point_cloud(
        &room,
        config.init_spacing,
        config.init_jitter,
        &mut root.fork(2),
    );
    let noisy = config
        .noise
        .as_ref()
        .map(|spec| noise::apply_noise(&room, &cameras, &rendered, spec, config.seed));
    Ok(SynthScene {
        config: config.clone(),
        room,
        cameras,
        views: rendered,
        gaussians,
        gaussian_primitives,
        init_points,
        noisy,
    })
}
