//! Writes a generated scene as an output folder (layout in `OUTPUT_LAYOUT`). Every file is
//! written atomically; views are written several at a time. A folder never mixes runs, even
//! when a run stops part-way (a signal, a full disk): an earlier run's cameras and summary go
//! first, then every view file in our own subfolders, and this run's cameras and summary are
//! written last, once every view is. A folder without `cameras.json` is refused by every
//! command that reads the room; `room.json`, written first, marks it as synth's for a rerun.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::{Context, Result};
use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder};
use serde::Serialize;

use super::raycast::ViewTruth;
use super::views::is_view_png;
use super::{Progress, SynthScene};
use crate::dataset::CLASS_TABLE_FILE;
use crate::scene::cameras_json::write_semsplat_cameras;
use crate::scene::classes::{default_color, write_class_table, ClassInfo, ClassTable};
use crate::scene::labels::{write_label_png, write_palette_png, LabelMap};
use crate::scene::ply::{write_classes_sidecar, write_ply};
use crate::scene::scene_file::{CAMERAS_FILE, SCENE_FILE};
use crate::util::{write_atomic, write_bytes_atomic};

/// The output layout, for `--help`.
// No line continuation before the first line: it would eat the indentation.
pub const OUTPUT_LAYOUT: &str = "  scene.ply              ground-truth Gaussians (flat discs on the surfaces the cameras see, SH degree 0)
                         with per-Gaussian `class` and `instance`; scene.classes.json beside it
  init.ply               sparse jittered surface point cloud (no labels) for training from scratch
  cameras.json           all views (semsplat camera JSON; \"split\": \"train\" | \"test\")
  classes.json           class table: id (as in label maps), name, palette color
  instances.json         instance table: id (as in instances/), name, class
  room.json              the room description; reusable with --preset DIR/room.json
  synth.json             the settings of this run and the resulting counts
  images/NAME.png        ray-cast RGB (NAME = train_0000.., test_0000..)
  labels/NAME.png        true class ids (8-bit gray PNG, 255 = ignore: pixel sees nothing)
  instances/NAME.png     true instance ids (8-bit gray, 255 = ignore; a view showing an id
                         >= 255 is written 16-bit, 65535 = ignore: map by map)
  instances/classes.json the instances as a class table (id, name, color), read with the maps
  labels_noisy/NAME.png  noisy class ids for every view, with --noise (evaluate on labels/)
  labels_noisy/noise.json  spec, seed, the consistently mislabeled objects and measured rates
  vis/labels*/NAME.png   palette-colored previews of the label maps (unless --no-previews)";

/// The run's summary; written last, with the cameras.
pub const SUMMARY_FILE: &str = "synth.json";
/// The room's description; written first, so a folder a run left part-way is known as
/// synth's to the next run.
pub const ROOM_FILE: &str = "room.json";

const VIEW_DIRS: &[&str] = &[
    "images",
    "labels",
    "instances",
    "labels_noisy",
    "vis/labels",
    "vis/labels_noisy",
];

#[derive(Serialize)]
struct InstanceEntry<'a> {
    id: u32,
    name: &'a str,
    class_id: u32,
    class: &'a str,
    structural: bool,
}

#[derive(Serialize)]
struct RunSummary<'a> {
    generator: String,
    room: String,
    seed: u64,
    train_views: usize,
    test_views: usize,
    width: u32,
    height: u32,
    hfov_deg: f64,
    spacing: f64,
    init_spacing: f64,
    init_jitter: f64,
    keep_hidden: bool,
    noise: Option<String>,
    classes: usize,
    instances: usize,
    primitives: usize,
    gaussians: usize,
    init_points: usize,
    views: Vec<&'a str>,
}

/// Writes `scene` into `dir` (created if needed).
pub fn write_synth(dir: &Path, scene: &SynthScene) -> Result<()> {
    write_synth_with_progress(dir, scene, &|_, _| {})
}

/// `write_synth`, calling `progress(done, total)` once per written view.
pub fn write_synth_with_progress(dir: &Path, scene: &SynthScene, progress: Progress) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("creating output folder {}", dir.display()))?;
    let held_a_room = dir.join(CAMERAS_FILE).is_file();
    let written = remove_previous_run(dir, scene).and_then(|()| write_run(dir, scene, progress));
    written.map_err(|e| match held_a_room && !dir.join(CAMERAS_FILE).is_file() {
        true => e.context(format!(
            "{} no longer holds the earlier run's room: its cameras and views were removed \
             before this run's were written (a folder never mixes two runs); run synth again \
             once the cause is fixed",
            dir.display()
        )),
        false => e,
    })
}

/// This run's files, into a folder the earlier run's views were removed from.
fn write_run(dir: &Path, scene: &SynthScene, progress: Progress) -> Result<()> {
    let room = &scene.room;
    write_json(&dir.join(ROOM_FILE), &room.spec)?;
    write_ply(&dir.join(SCENE_FILE), &scene.gaussians)?;
    write_classes_sidecar(&dir.join(SCENE_FILE), &room.classes)?;
    write_ply(&dir.join("init.ply"), &scene.init_points)?;
    write_class_table(&dir.join(CLASS_TABLE_FILE), &room.classes)?;
    let instances: Vec<InstanceEntry> = room
        .instances
        .iter()
        .map(|i| InstanceEntry {
            id: i.id,
            name: &i.name,
            class_id: i.class_id,
            class: room.class_name(i.class_id),
            structural: i.structural,
        })
        .collect();
    write_json(&dir.join("instances.json"), &instances)?;
    // The instance maps' own table, inside their folder where `fuse`, `eval` and `inspect`
    // look first (the class table beside the folder would name instance ids as classes).
    let instance_table = ClassTable {
        classes: (room.instances.iter())
            .map(|i| ClassInfo {
                id: i.id,
                name: i.name.clone(),
                color: default_color(i.id),
            })
            .collect(),
    };
    let instance_dir = dir.join("instances");
    std::fs::create_dir_all(&instance_dir)
        .with_context(|| format!("creating {}", instance_dir.display()))?;
    write_class_table(&instance_dir.join(CLASS_TABLE_FILE), &instance_table)?;
    if let Some(noisy) = &scene.noisy {
        write_json(&dir.join("labels_noisy").join("noise.json"), &noisy.report)?;
    }
    write_views(dir, scene, progress)?;
    // Last: with them the folder reads as a room (see the module's description).
    write_semsplat_cameras(&dir.join(CAMERAS_FILE), &scene.cameras)?;
    write_json(&dir.join(SUMMARY_FILE), &summary(scene))
}

/// Writes every view's files, several views at a time; the first error stops the others.
fn write_views(dir: &Path, scene: &SynthScene, progress: Progress) -> Result<()> {
    let next = AtomicUsize::new(0);
    // Counted under a lock so the calls see `done` rising, whichever thread finishes first.
    let done = Mutex::new(0);
    let first_error: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    let threads = crate::util::cores().min(scene.views.len()).max(1);
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= scene.views.len() || first_error.lock().map_or(true, |e| e.is_some()) {
                    break;
                }
                if let Err(e) = write_view(dir, scene, i) {
                    if let Ok(mut slot) = first_error.lock() {
                        slot.get_or_insert(e);
                    }
                    break;
                }
                if let Ok(mut done) = done.lock() {
                    *done += 1;
                    progress(*done, scene.views.len());
                }
            });
        }
    });
    match first_error.into_inner().unwrap_or_else(|e| e.into_inner()) {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

fn write_view(dir: &Path, scene: &SynthScene, i: usize) -> Result<()> {
    let view = &scene.views[i];
    let file = format!("{}.png", scene.cameras[i].name);
    write_bytes_atomic(&dir.join("images").join(&file), &encode_rgb(view)?)?;
    let labels = label_map(view, view.labels.clone())?;
    write_label_png(&dir.join("labels").join(&file), &labels)?;
    write_label_png(
        &dir.join("instances").join(&file),
        &label_map(view, view.instances.clone())?,
    )?;
    let classes = &scene.room.classes;
    if scene.config.previews {
        write_palette_png(&dir.join("vis/labels").join(&file), &labels, classes)?;
    }
    if let Some(noisy) = &scene.noisy {
        let map = label_map(view, noisy.maps[i].clone())?;
        write_label_png(&dir.join("labels_noisy").join(&file), &map)?;
        if scene.config.previews {
            write_palette_png(&dir.join("vis/labels_noisy").join(&file), &map, classes)?;
        }
    }
    Ok(())
}

fn label_map(view: &ViewTruth, labels: Vec<u16>) -> Result<LabelMap> {
    LabelMap::new(view.width, view.height, labels)
}

fn encode_rgb(view: &ViewTruth) -> Result<Vec<u8>> {
    let mut png = Vec::new();
    PngEncoder::new(&mut png).write_image(
        &view.rgb,
        view.width,
        view.height,
        ExtendedColorType::Rgb8,
    )?;
    Ok(png)
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value)?;
        std::io::Write::write_all(w, b"\n")?;
        Ok(())
    })
}

fn summary(scene: &SynthScene) -> RunSummary<'_> {
    let c = &scene.config;
    let room = match &c.room {
        super::RoomSource::Preset(name) => name.clone(),
        super::RoomSource::File(path) => path.display().to_string(),
        super::RoomSource::Spec(_) => "(in-memory room)".to_string(),
    };
    RunSummary {
        generator: format!("semsplat {} synth", env!("CARGO_PKG_VERSION")),
        room,
        seed: c.seed,
        train_views: c.train_views,
        test_views: c.test_views,
        width: c.width,
        height: c.height,
        hfov_deg: c.hfov_deg,
        spacing: c.spacing,
        init_spacing: c.init_spacing,
        init_jitter: c.init_jitter,
        keep_hidden: c.keep_hidden,
        noise: c.noise.as_ref().map(|n| n.to_string()),
        classes: scene.room.classes.classes.len(),
        instances: scene.room.instances.len(),
        primitives: scene.room.primitives.len(),
        gaussians: scene.gaussians.len(),
        init_points: scene.init_points.len(),
        views: scene.cameras.iter().map(|c| c.name.as_str()).collect(),
    }
}

/// Removes what an earlier run wrote that could be read with this run's files: its cameras
/// and summary first (a folder without them is no room, whatever else is left), then every
/// view PNG in our view folders, named as synth names views (this run rewrites the views it
/// has; the others were an earlier, larger run's, or noisy labels or previews this run does
/// not produce; other files, a user's, stay) and an outdated noise.json.
fn remove_previous_run(dir: &Path, scene: &SynthScene) -> Result<()> {
    for file in [CAMERAS_FILE, SUMMARY_FILE] {
        let path = dir.join(file);
        if path.is_file() {
            std::fs::remove_file(&path)
                .with_context(|| format!("removing the earlier run's {}", path.display()))?;
        }
    }
    let keep = |sub: &str| -> bool {
        match sub {
            "labels_noisy" => scene.noisy.is_some(),
            "vis/labels" => scene.config.previews,
            "vis/labels_noisy" => scene.config.previews && scene.noisy.is_some(),
            _ => true,
        }
    };
    for sub in VIEW_DIRS {
        let folder = dir.join(sub);
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        let mut stale: Vec<PathBuf> = Vec::new();
        for entry in entries.flatten() {
            let path = entry.path();
            let ours = (path.file_name().and_then(|n| n.to_str())).is_some_and(is_view_png);
            if ours && path.is_file() {
                stale.push(path);
            }
        }
        stale.sort();
        for path in stale {
            std::fs::remove_file(&path)
                .with_context(|| format!("removing the earlier run's {}", path.display()))?;
        }
    }
    let noise_json = dir.join("labels_noisy").join("noise.json");
    if scene.noisy.is_none() && noise_json.is_file() {
        std::fs::remove_file(&noise_json)
            .with_context(|| format!("removing stale {}", noise_json.display()))?;
    }
    // A folder this run does not fill, left empty, would read as an empty label folder.
    for sub in VIEW_DIRS.iter().rev().filter(|sub| !keep(sub)) {
        let _ = std::fs::remove_dir(dir.join(sub)); // only when empty: a user's files stay
    }
    Ok(())
}
