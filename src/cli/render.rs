//! `semsplat render`: renders views of a scene on the GPU and writes images (and, with
//! --raw, float arrays for comparison with other tools).

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context, Result};
use clap::Args;

use super::progress::render_bar;
use super::{args, check_outputs, Input};
use semsplat::eval::label_render::LabelRenderer;
use semsplat::gpu::Gpu;
use semsplat::render::{GpuScene, Rasterizer, RenderOptions, RenderedFrame, SemanticMode};
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::classes::ClassTable;
use semsplat::scene::labels::{list_some, write_label_png, write_palette_png, LabelMap};
use semsplat::scene::ply::{classes_sidecar_path, read_classes_sidecar};
use semsplat::scene::scene_file::{cameras_for_scene, read_scene, resolve_scene_path};
use semsplat::scene::{Camera, Gaussians};
use semsplat::util::free_space::check_free_space;
use semsplat::util::npy::write_npy_f32;
use semsplat::util::{interrupt, write_bytes_atomic};

#[derive(Args)]
pub struct RenderArgs {
    /// The scene: a 3DGS PLY (INRIA layout, or SuperSplat's compressed PLY), a .splat, an
    /// .spz, an INRIA training-output folder (its latest iteration) or a scene folder holding
    /// scene.ply (as `synth` writes). --semantics uses the
    /// sem_0..sem_{C-1} logits, or a fused PLY's `class` property when it has no logits;
    /// class ids and colors come from the `<scene>.classes.json` sidecar if present.
    #[arg(long)]
    scene: PathBuf,
    /// Cameras: a COLMAP model folder (cameras/images .bin or .txt, or a folder with
    /// sparse/0), an INRIA cameras.json, a nerfstudio transforms.json or a semsplat cameras.json. Default: the
    /// cameras.json of the scene's folder (a `synth` room, an INRIA run).
    #[arg(long)]
    cameras: Option<PathBuf>,
    /// Render only these views (image names without extension, e.g. 00001, or cam0/00001
    /// for rig cameras whose stems repeat); default: all.
    #[arg(long, num_args = 1.., value_delimiter = ',')]
    views: Vec<String>,
    /// Output folder: <view>.png (RGB) and, with --semantics, <view>.labels.png (class ids,
    /// 255/65535 where nothing was drawn) and <view>.palette.png (class colors). Rig views
    /// named by a relative path write into subfolders: <out>/cam0/00001.png.
    #[arg(long)]
    out: PathBuf,
    /// Overwrite files in --out that no earlier `render` wrote (by default refused: a
    /// render into a scene's labels/ or images/ folder would replace its label maps or
    /// photos with renderings).
    #[arg(long)]
    force: bool,
    /// Also render the semantic channels (the argmax class per pixel), or for a fused PLY
    /// without logits the class the Gaussians carry.
    #[arg(long)]
    semantics: bool,
    /// Blend softmax(logits) per Gaussian instead of raw logits.
    #[arg(long, requires = "semantics")]
    softmax: bool,
    /// Background color, three values in [0, 1]: 0.2,0.5,1 or 0.2 0.5 1.
    // num_args counts before the comma split, so 1..=3 takes both spellings; run checks 3.
    #[arg(long, value_delimiter = ',', num_args = 1..=3, default_values_t = [0.0f32, 0.0, 0.0], value_parser = args::unit_interval::<f32>)]
    background: Vec<f32>,
    /// Also write float32 NumPy arrays per view: <view>.rgb.npy [H,W,3], .alpha.npy [H,W],
    /// .depth.npy [H,W], and with --semantics of a scene with logits .sem.npy [H,W,C]
    /// (blended) and .sem_norm.npy [H,W,C] (divided by the accumulated alpha); a fused
    /// scene's classes are in its label images only.
    #[arg(long)]
    raw: bool,
}

fn select_views(cams: Vec<Camera>, wanted: &[String]) -> Result<Vec<Camera>> {
    if wanted.is_empty() {
        return Ok(cams);
    }
    let missing: Vec<&String> = wanted
        .iter()
        .filter(|w| !cams.iter().any(|c| &c.name == *w))
        .collect();
    if let Some(&first) = missing.first() {
        // A rig's cameras are named by their image's path where stems repeat.
        let stem_of = |c: &&Camera| c.name.rsplit('/').next() == Some(first.as_str());
        let by_stem: Vec<&str> = cams
            .iter()
            .filter(stem_of)
            .map(|c| c.name.as_str())
            .collect();
        if by_stem.len() > 1 {
            bail!(
                "--views {first}: several cameras have images of that name ({}): name one by \
                 its path",
                by_stem.join(", ")
            );
        }
        let known: Vec<&str> = cams.iter().take(10).map(|c| c.name.as_str()).collect();
        bail!("no camera named {missing:?} (cameras include {known:?})");
    }
    Ok(cams
        .into_iter()
        .filter(|c| wanted.contains(&c.name))
        .collect())
}

fn write_rgb_png(path: &Path, f: &RenderedFrame) -> Result<()> {
    let bytes: Vec<u8> = f
        .rgb
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let img = image::RgbImage::from_raw(f.width, f.height, bytes).context("image size")?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)?;
    write_bytes_atomic(path, &png)
}

/// Maps argmax channel k to the user's class id: row k of the class table, else k.
fn label_map(f: &RenderedFrame, table: Option<&ClassTable>) -> Result<LabelMap> {
    let labels = f
        .argmax_labels()
        .into_iter()
        .map(|k| match k {
            None => LabelMap::IGNORE,
            Some(k) => table
                .and_then(|t| t.classes.get(k as usize))
                .map_or(k as u16, |c| c.id as u16),
        })
        .collect();
    LabelMap::new(f.width, f.height, labels)
}

/// Where `--semantics` labels come from: the scene's `sem_*` logits, or (a fused PLY without
/// logits) its per-Gaussian `class`, rendered as one-hot channels.
enum LabelSource {
    None,
    Logits,
    Classes(Box<LabelRenderer>),
}

fn label_source(args: &RenderArgs, g: &Gaussians, gpu: &Gpu) -> Result<LabelSource> {
    if !args.semantics {
        return Ok(LabelSource::None);
    }
    if g.semantics.is_some() {
        return Ok(LabelSource::Logits);
    }
    let Some(ids) = &g.class_ids else {
        bail!(
            "{} has neither sem_* logits nor a class property: nothing to render with --semantics",
            args.scene.display()
        );
    };
    if args.softmax {
        bail!(
            "{} has a class per Gaussian but no sem_* logits: --softmax blends logits (drop \
             it to render the classes)",
            args.scene.display()
        );
    }
    if args.raw {
        eprintln!(
            "note: {} has a class per Gaussian but no sem_* logits: --raw writes no .sem and \
             .sem_norm arrays (the classes are in <view>{LABELS_PNG})",
            args.scene.display()
        );
    }
    let renderer = LabelRenderer::new(gpu, g, ids)?;
    renderer.check_fits_16_bit()?;
    Ok(LabelSource::Classes(Box::new(renderer)))
}

/// Channel k of the logits is the table's k-th class: a table of another length (one
/// copied from another scene) would name every channel wrong.
fn check_table_fits_logits(scene: &Path, g: &Gaussians, table: Option<&ClassTable>) -> Result<()> {
    if let (Some(s), Some(table)) = (&g.semantics, table) {
        ensure!(
            table.len() == s.channels,
            "{} has {} semantic channels (sem_*) but its class table lists {} classes: the \
             table is not this scene's (train writes both together)",
            scene.display(),
            s.channels,
            table.len()
        );
    }
    Ok(())
}

/// What a view's files append to its camera's name.
const RGB_PNG: &str = ".png";
pub(super) const LABELS_PNG: &str = ".labels.png";
pub(super) const PALETTE_PNG: &str = ".palette.png";
const RAW_NPY: [&str; 5] = [
    ".rgb.npy",
    ".alpha.npy",
    ".depth.npy",
    ".sem.npy",
    ".sem_norm.npy",
];

/// The file in an output folder listing the files `render` (or `fuse --render-views`) wrote
/// there, one name a line below its first: only those are replaced without --force.
const RENDER_MARKER: &str = ".semsplat-render";
const RENDER_MARKER_HEADER: &str = "files here were written by semsplat render";

/// The suffixes of the files each view writes with these options.
fn view_suffixes(args: &RenderArgs) -> Vec<&'static str> {
    let mut suffixes = vec![RGB_PNG];
    if args.semantics {
        suffixes.extend([LABELS_PNG, PALETTE_PNG]);
    }
    if args.raw {
        let [rgb, alpha, depth, sem, sem_norm] = RAW_NPY;
        suffixes.extend([rgb, alpha, depth]);
        if args.semantics {
            suffixes.extend([sem, sem_norm]);
        }
    }
    suffixes
}

/// The files renders wrote into a folder, as its [`RENDER_MARKER`] lists them.
pub(super) struct RenderedFiles {
    folder: PathBuf,
    listed: HashSet<String>,
    /// What [`RenderedFiles::start`] created, the folder and its list: a stop before the
    /// first view's files removes them again rather than leave an empty folder behind.
    created: Created,
    /// Whether the files go through an [`semsplat::util::OutputBatch`] (fuse's
    /// --render-views): the list is then written with them, when the batch commits.
    batched: bool,
}

#[derive(Clone, Copy, Default)]
struct Created {
    folder: bool,
    list: bool,
}

impl RenderedFiles {
    /// The list of `out` (empty where no render wrote there).
    pub(super) fn of(out: &Path) -> Result<RenderedFiles> {
        let marker = out.join(RENDER_MARKER);
        let listed = match std::fs::read_to_string(&marker) {
            Ok(text) => text.lines().skip(1).map(str::to_owned).collect(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => HashSet::new(),
            Err(e) => return Err(e).with_context(|| format!("reading {}", marker.display())),
        };
        let folder = out.to_owned();
        let created = Created::default();
        Ok(RenderedFiles {
            folder,
            listed,
            created,
            batched: false,
        })
    }

    fn marker(&self) -> PathBuf {
        self.folder.join(RENDER_MARKER)
    }

    /// Refuses to replace files in the folder (of `option`) that no earlier render wrote,
    /// unless forced: `<view>.png` is also the name of a view's label map and photo.
    /// `force`: None where the command has no --force (fuse's and merge's --render-views).
    pub(super) fn check_overwrites(
        &self,
        option: &str,
        force: Option<bool>,
        cams: &[Camera],
        suffixes: &[&str],
    ) -> Result<()> {
        if force == Some(true) {
            return Ok(());
        }
        let out = &self.folder;
        let targets =
            (cams.iter()).flat_map(|cam| suffixes.iter().map(move |s| format!("{}{s}", cam.name)));
        let existing: Vec<String> = targets
            .filter(|f| !self.listed.contains(f) && out.join(f).exists())
            .collect();
        if let Some(first) = existing.first() {
            let or_force = force.map_or("", |_| ", or pass --force");
            bail!(
                "{option} {} holds {} files these views would replace that no render wrote \
                 (e.g. {first}: a label map or photo of the same name?): choose another \
                 {option}{or_force}",
                out.display(),
                existing.len()
            );
        }
        Ok(())
    }

    /// Creates the folder and its list, before the first view is written (a list there is
    /// kept).
    pub(super) fn start(&mut self) -> Result<()> {
        let (out, marker) = (&self.folder, self.marker());
        self.created.folder = !out.exists();
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        self.created.list = !marker.exists();
        if self.created.list {
            let header = format!("{RENDER_MARKER_HEADER}\n");
            std::fs::write(&marker, header)
                .with_context(|| format!("writing {}", marker.display()))?;
        }
        Ok(())
    }

    /// For files written in an [`semsplat::util::OutputBatch`]: the list is written by
    /// [`RenderedFiles::write_batched`], in the batch (which creates the folder with the
    /// first file, and removes it again if it ends uncommitted).
    pub(super) fn start_batched(&mut self) {
        self.batched = true;
    }

    /// The whole list, written in the output batch beside the files it names (a stop
    /// before the batch commits leaves neither).
    pub(super) fn write_batched(&self) -> Result<()> {
        let mut names: Vec<&str> = self.listed.iter().map(String::as_str).collect();
        names.sort_unstable();
        let text = format!("{RENDER_MARKER_HEADER}\n{}\n", names.join("\n"));
        write_bytes_atomic(&self.marker(), text.as_bytes())
    }

    /// After a stop: lists the files of the view under way (`partial`) that were written
    /// (each whole: written to a temp file and renamed), so a rerun may replace them; then,
    /// where no view's file was written, removes the list [`RenderedFiles::start`] created,
    /// and the folder it created. Returns whether the folder is gone.
    pub(super) fn stop(&mut self, partial: Option<&Camera>, suffixes: &[&str]) -> bool {
        if let Some(cam) = partial {
            let written: Vec<&str> = (suffixes.iter().copied())
                .filter(|s| self.folder.join(format!("{}{s}", cam.name)).is_file())
                .collect();
            if !written.is_empty() && self.add(cam, &written).is_err() {
                return false;
            }
        }
        // A list found at the start names earlier renders' files: kept, and its folder.
        if !self.created.list || !self.listed.is_empty() {
            return false;
        }
        let _ = std::fs::remove_file(self.marker());
        // remove_dir removes only an empty folder.
        self.created.folder && std::fs::remove_dir(&self.folder).is_ok()
    }

    /// Lists a view's files once they are written (a file listed is one a render may
    /// replace: listed after its write, a stop between the two leaves it refused, not a
    /// file of the user's open to replacement).
    pub(super) fn add(&mut self, cam: &Camera, suffixes: &[&str]) -> Result<()> {
        let names = suffixes.iter().map(|s| format!("{}{s}", cam.name));
        let new: Vec<String> = names.filter(|f| !self.listed.contains(f)).collect();
        if new.is_empty() || self.batched {
            self.listed.extend(new);
            return Ok(());
        }
        let mut lines = new.join("\n");
        lines.push('\n');
        let marker = self.marker();
        let mut file = std::fs::OpenOptions::new()
            .append(true)
            .open(&marker)
            .with_context(|| format!("opening {}", marker.display()))?;
        std::io::Write::write_all(&mut file, lines.as_bytes())
            .with_context(|| format!("writing {}", marker.display()))?;
        self.listed.extend(new);
        Ok(())
    }
}

/// Refuses views whose files would land on one path (a camera named `X.labels` wrote its
/// RGB image to `X.labels.png`, camera `X`'s label map), before anything is written.
fn check_view_files_distinct(cams: &[Camera]) -> Result<()> {
    let suffixes: Vec<&str> = [RGB_PNG, LABELS_PNG, PALETTE_PNG]
        .into_iter()
        .chain(RAW_NPY)
        .collect();
    let mut writer: HashMap<String, &str> = HashMap::new();
    for cam in cams {
        for suffix in &suffixes {
            let file = format!("{}{suffix}", cam.name);
            if let Some(other) = writer.insert(file.clone(), &cam.name) {
                bail!(
                    "cameras '{other}' and '{}' would both write {file} in --out: render them \
                     in two runs, or rename one",
                    cam.name
                );
            }
        }
    }
    Ok(())
}

/// The flags and paths that need no file read: --background's values, --out against the
/// inputs.
fn check_render_args(args: &RenderArgs) -> Result<()> {
    if args.background.len() != 3 {
        bail!(
            "--background takes three values (red, green, blue in [0, 1]), got {:?}",
            args.background
        );
    }
    check_outputs(
        &[],
        &[("--out", Some(&args.out))],
        &[
            Input::Scene("--scene", Some(&args.scene)),
            Input::Cameras("--cameras", args.cameras.as_deref()),
        ],
    )
}

/// --raw: room on --out's file system for every view's arrays, less the files they replace.
fn check_raw_room(args: &RenderArgs, g: &Gaussians, cams: &[Camera]) -> Result<()> {
    let channels = (g.semantics.as_ref())
        .filter(|_| args.semantics)
        .map(|s| s.channels);
    let at_least = raw_bytes(cams, channels).saturating_sub(replaced_bytes(&args.out, cams));
    check_free_space("--out", &args.out, at_least, "--raw's arrays")
}

pub fn run(args: RenderArgs) -> Result<()> {
    check_render_args(&args)?;
    let scene_file = resolve_scene_path(&args.scene)?;
    let g = read_scene(&scene_file)?;
    let table = read_classes_sidecar(&scene_file)?;
    let cams = select_views(
        load_cameras(&cameras_for_scene(args.cameras.as_deref(), &args.scene)?)?,
        &args.views,
    )?;
    check_view_files_distinct(&cams)?;
    let suffixes = view_suffixes(&args);
    let mut rendered = RenderedFiles::of(&args.out)?;
    rendered.check_overwrites("--out", Some(args.force), &cams, &suffixes)?;
    if args.semantics {
        check_semantics_table(&scene_file, &g, table.as_ref())?;
    }
    if args.raw {
        check_raw_room(&args, &g, &cams)?;
    }
    let gpu = Gpu::new()?;
    let mut labels_from = label_source(&args, &g, &gpu)?;
    let scene = GpuScene::upload(&gpu, &g)?;
    let mode = if args.softmax {
        SemanticMode::Softmax
    } else {
        SemanticMode::RawLogits
    };
    let opts = RenderOptions {
        background: [args.background[0], args.background[1], args.background[2]],
        semantics: matches!(labels_from, LabelSource::Logits).then_some(mode),
        ..Default::default()
    };
    let palette_table = table.clone().unwrap_or_else(|| ids_without_table(&g));
    let mut raster = Rasterizer::new(&gpu);
    rendered.start()?;
    let bar = render_bar(cams.len());
    let mut one_view = |cam: &Camera| -> Result<()> {
        interrupt::check()?;
        bar.set_message(cam.name.clone());
        let f = raster.render(&scene, cam, &opts)?;
        // Rig names (`cam0/00001`) write into subfolders of --out; check_camera_name keeps
        // every component a plain name, so nothing lands outside it.
        let out = |suffix: &str| args.out.join(format!("{}{suffix}", cam.name));
        write_rgb_png(&out(RGB_PNG), &f)?;
        let labels = match &mut labels_from {
            LabelSource::None => None,
            LabelSource::Logits => Some(label_map(&f, table.as_ref())?),
            LabelSource::Classes(r) => Some(class_label_map(r, cam)?),
        };
        if let Some(labels) = &labels {
            write_label_png(&out(LABELS_PNG), labels)?;
            write_palette_png(&out(PALETTE_PNG), labels, &palette_table)?;
        }
        if args.raw {
            write_raw(&f, &out, opts.semantics.is_some())?;
        }
        rendered.add(cam, &suffixes)?;
        bar.inc(1);
        Ok(())
    };
    for (done, cam) in cams.iter().enumerate() {
        if let Err(e) = one_view(cam) {
            // Interrupted or failed (a full disk, a GPU error): say which views are whole.
            bar.finish_and_clear();
            if !rendered.stop(cams.get(done), &suffixes) {
                eprintln!("{}", partial_render_note(&args.out, &cams, done));
            }
            return Err(e);
        }
    }
    bar.finish_and_clear();
    let views = if cams.len() == 1 { "view" } else { "views" };
    eprintln!(
        "rendered {} {views} into {}",
        cams.len(),
        args.out.display()
    );
    Ok(())
}

/// `--semantics`: the class table must fit the logits; without one, label images hold
/// channel indices, and class ids the table lacks are drawn in colours of their own, which
/// is said.
fn check_semantics_table(
    scene_file: &Path,
    g: &Gaussians,
    table: Option<&ClassTable>,
) -> Result<()> {
    check_table_fits_logits(scene_file, g, table)?;
    if let (Some(table), None, Some(ids)) = (table, &g.semantics, &g.class_ids) {
        let mut missing: Vec<i32> = (ids.iter())
            .filter(|&&id| id >= 0 && !table.contains(id as u32))
            .copied()
            .collect();
        missing.sort_unstable();
        missing.dedup();
        if !missing.is_empty() {
            let missing: Vec<String> = missing.iter().map(i32::to_string).collect();
            eprintln!(
                "note: {} holds class ids its class table ({}) does not list: {}; their \
                 pixels get colours of their own in the palette images",
                scene_file.display(),
                classes_sidecar_path(scene_file).display(),
                list_some(&missing)
            );
        }
    }
    if table.is_none() && g.semantics.is_some() {
        // Without the table the channels have no ids: a trained scene's `class` may
        // hold others (4711), and its label images would silently disagree with them.
        eprintln!(
            "note: {} has no class table ({}): label images hold the logits' channel \
             indices 0..C-1, not class ids",
            scene_file.display(),
            classes_sidecar_path(scene_file).display()
        );
    }
    Ok(())
}

/// The palette's classes where the scene has no class table: its logits' channels, else
/// the class ids it holds.
fn ids_without_table(g: &Gaussians) -> ClassTable {
    match &g.semantics {
        Some(s) => ClassTable::from_ids(0..s.channels as u32),
        None => ClassTable::from_ids(
            g.class_ids
                .iter()
                .flatten()
                .filter(|&&c| c >= 0)
                .map(|&c| c as u32),
        ),
    }
}

/// What a render stopped part-way leaves in `out`: the first `done` of `cams`, perhaps some of
/// the next one's files, and beside them whatever an earlier render wrote (each file is
/// whole: written to a temp name, renamed).
fn partial_render_note(out: &Path, cams: &[Camera], done: usize) -> String {
    let written = match done {
        0 => "no view of this run".to_string(),
        1 => format!("this run's first view ({})", cams[0].name),
        _ => format!(
            "this run's first {done} views ({} to {})",
            cams[0].name,
            cams[done - 1].name
        ),
    };
    let next = match cams.get(done) {
        Some(cam) => format!(" (and perhaps some of {}'s files)", cam.name),
        None => String::new(),
    };
    format!(
        "note: stopped after {done} of {} views: {} holds {written}{next}; files of the \
         other views there, if any, are an earlier render's",
        cams.len(),
        out.display()
    )
}

/// Labels of a fused scene's classes (user ids; ignore where no classified Gaussian shows).
fn class_label_map(r: &mut LabelRenderer, cam: &Camera) -> Result<LabelMap> {
    let labels = r
        .render(cam)?
        .into_iter()
        .map(|l| l.unwrap_or(LabelMap::IGNORE))
        .collect();
    LabelMap::new(cam.width, cam.height, labels)
}

/// The bytes of every view's --raw arrays (float32, each with its NumPy header, at most
/// 128 bytes): RGB, alpha and depth, and with `semantic_channels` the two semantic arrays.
/// Exact to the headers, unlike the PNGs' compressed sizes, which are not known before.
fn raw_bytes(cams: &[Camera], semantic_channels: Option<usize>) -> u64 {
    let per_pixel = 3 + 1 + 1 + 2 * semantic_channels.unwrap_or(0) as u64;
    let arrays = 3 + 2 * u64::from(semantic_channels.is_some());
    (cams.iter())
        .map(|c| u64::from(c.width) * u64::from(c.height) * per_pixel * 4 + arrays * 128)
        .sum()
}

/// The bytes of the --raw arrays of `cams` already in `out`, which the render replaces.
fn replaced_bytes(out: &Path, cams: &[Camera]) -> u64 {
    let files = (cams.iter()).flat_map(|c| RAW_NPY.map(|s| out.join(format!("{}{s}", c.name))));
    files
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum()
}

fn write_raw(f: &RenderedFrame, out: &dyn Fn(&str) -> PathBuf, semantics: bool) -> Result<()> {
    let (h, w, c) = (f.height as u64, f.width as u64, f.channels as u64);
    let [rgb, alpha, depth, sem, sem_norm] = RAW_NPY;
    write_npy_f32(&out(rgb), &[h, w, 3], &f.rgb)?;
    write_npy_f32(&out(alpha), &[h, w], &f.alpha)?;
    write_npy_f32(&out(depth), &[h, w], &f.depth)?;
    if semantics {
        write_npy_f32(&out(sem), &[h, w, c], &f.sem)?;
        write_npy_f32(&out(sem_norm), &[h, w, c], &f.sem_norm)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera of `w` x `h` pixels (where it looks does not matter here).
    fn cam(name: &str, w: u32, h: u32) -> Camera {
        let (eye, up) = (glam::DVec3::new(0.0, 0.0, -1.0), glam::DVec3::Y);
        Camera::look_at(name, eye, glam::DVec3::ZERO, up, w, h, 60.0)
    }

    /// A stem that names several rig cameras is said to be ambiguous, naming them.
    #[test]
    fn a_stem_shared_by_rig_cameras_names_them() {
        let cams = vec![
            cam("cam0/00003", 8, 8),
            cam("cam1/00003", 8, 8),
            cam("00004", 8, 8),
        ];
        let e = select_views(cams.clone(), &["00003".into()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cam0/00003, cam1/00003") && e.contains("by its path"),
            "{e}"
        );
        let picked = select_views(cams, &["cam1/00003".into()]).unwrap();
        assert_eq!(picked.len(), 1);
    }

    /// --raw's bytes, as the free-space check counts them, are the arrays' files' sizes
    /// within their headers' padding.
    #[test]
    fn raw_bytes_are_the_arrays_sizes() {
        let tmp = tempfile::tempdir().unwrap();
        let cams = [cam("a", 7, 5), cam("b", 16, 9)];
        for channels in [None, Some(3)] {
            let mut written = 0;
            for c in &cams {
                let (h, w) = (u64::from(c.height), u64::from(c.width));
                let mut shapes = vec![vec![h, w, 3], vec![h, w], vec![h, w]];
                if let Some(k) = channels {
                    shapes.extend([vec![h, w, k as u64], vec![h, w, k as u64]]);
                }
                for (i, shape) in shapes.iter().enumerate() {
                    let path = tmp.path().join(format!("{}{}", c.name, RAW_NPY[i]));
                    let values = vec![0.0f32; shape.iter().product::<u64>() as usize];
                    write_npy_f32(&path, shape, &values).unwrap();
                    written += std::fs::metadata(&path).unwrap().len();
                }
            }
            assert_eq!(replaced_bytes(tmp.path(), &cams), written);
            let counted = raw_bytes(&cams, channels);
            let arrays = 2 * (3 + 2 * u64::from(channels.is_some()));
            assert!(
                counted >= written && counted - written < arrays * 128,
                "{counted} {written}"
            );
            for f in std::fs::read_dir(tmp.path()).unwrap() {
                std::fs::remove_file(f.unwrap().path()).unwrap();
            }
        }
    }

    /// A render stopped before its first view leaves neither the folder it created nor a
    /// list in a folder that was there; one stopped later keeps both.
    #[test]
    fn a_render_stopped_before_its_first_view_leaves_nothing() {
        let tmp = tempfile::tempdir().unwrap();
        let new = tmp.path().join("new");
        let mut rendered = RenderedFiles::of(&new).unwrap();
        rendered.start().unwrap();
        assert!(new.join(RENDER_MARKER).is_file());
        assert!(rendered.stop(None, &[RGB_PNG]));
        assert!(!new.exists());

        let there = tmp.path().join("there");
        std::fs::create_dir(&there).unwrap();
        let mut rendered = RenderedFiles::of(&there).unwrap();
        rendered.start().unwrap();
        assert!(!rendered.stop(None, &[RGB_PNG]));
        assert!(there.is_dir() && !there.join(RENDER_MARKER).exists());

        // The first view's image written, its label map not yet: the image is listed, so a
        // rerun replaces it.
        let cam = cam("w", 8, 8);
        let mut rendered = RenderedFiles::of(&new).unwrap();
        rendered.start().unwrap();
        std::fs::write(new.join("w.png"), b"").unwrap();
        assert!(!rendered.stop(Some(&cam), &[RGB_PNG, LABELS_PNG]));
        let again = RenderedFiles::of(&new).unwrap();
        assert!(again.listed.contains("w.png") && !again.listed.contains("w.labels.png"));
        assert!(again
            .check_overwrites(
                "--out",
                Some(false),
                std::slice::from_ref(&cam),
                &[RGB_PNG, LABELS_PNG]
            )
            .is_ok());

        // A view listed: everything kept.
        let mut rendered = RenderedFiles::of(&there).unwrap();
        rendered.start().unwrap();
        rendered.add(&cam, &[RGB_PNG]).unwrap();
        assert!(!rendered.stop(None, &[RGB_PNG]));
        assert!(there.join(RENDER_MARKER).is_file());

        // Batched (fuse --render-views): the list is written with the files, in the
        // batch; a batch dropped uncommitted removes both, and the folders made for them.
        let batched = tmp.path().join("batched");
        for commit in [false, true] {
            let batch = semsplat::util::OutputBatch::open();
            let mut rendered = RenderedFiles::of(&batched).unwrap();
            rendered.start_batched();
            write_bytes_atomic(&batched.join("rig/w.labels.png"), b"").unwrap();
            rendered.add(&cam, &[LABELS_PNG]).unwrap();
            rendered.write_batched().unwrap();
            assert!(!batched.join(RENDER_MARKER).exists());
            match commit {
                false => drop(batch),
                true => batch.commit().unwrap(),
            }
            assert_eq!(batched.exists(), commit);
        }
        let listed = RenderedFiles::of(&batched).unwrap().listed;
        assert_eq!(listed, HashSet::from(["w.labels.png".to_string()]));
    }
}
