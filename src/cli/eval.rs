//! `semsplat eval`: scores a scene whose Gaussians carry classes (a `fuse` output) against
//! label maps: 2D mIoU (over the classes the maps hold) and pixel accuracy (per class too)
//! on the chosen views, and 3D per-Gaussian accuracy when a PLY with the true classes is
//! given.

use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;

use semsplat::dataset::{default_class_table, open_truth_views};
use semsplat::eval::image_quality::{image_quality, ImageQuality};
use semsplat::eval::label_render::LabelRenderer;
use semsplat::eval::metrics::{gaussian_accuracy, Confusion, SegmentationScores};
use semsplat::gpu::Gpu;
use semsplat::scene::classes::{read_class_table, ClassTable};
use semsplat::scene::images::ImageDir;
use semsplat::scene::labels::{
    binary_mask_warning, list_some, stray_255_warning, LabelDir, LabelMap,
};
use semsplat::scene::ply::read_classes_sidecar;
use semsplat::scene::scene_file::{cameras_for_scene, read_scene};
use semsplat::scene::{Camera, Gaussians, Split};
use semsplat::util::{interrupt, write_bytes_atomic};

use super::progress::views_bar;
use super::{check_outputs, Input, FRAME_HINT};

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum Views {
    /// Held-out views only (cameras marked "test"; formats without splits have none).
    Test,
    /// Training views only.
    Train,
    /// Every view with a label map.
    All,
}

impl Views {
    /// Whether a camera of `split` is one of these views.
    fn holds(self, split: Split) -> bool {
        self == Views::All || (self == Views::Test) == (split == Split::Test)
    }

    /// The value as --views takes it.
    fn name(self) -> &'static str {
        match self {
            Views::Test => "test",
            Views::Train => "train",
            Views::All => "all",
        }
    }
}

#[derive(Args)]
pub struct EvalArgs {
    /// A PLY whose Gaussians carry `class` (as `fuse` and `train` write it). The labels are
    /// rendered with each Gaussian drawn in its `class` alone (one-hot), so every method is
    /// scored alike: a trained scene by its Gaussians' classes, not by its blended logits
    /// (`render --semantics` draws those, and may differ by a point or so).
    #[arg(long)]
    scene: PathBuf,
    /// Cameras: COLMAP model folder, INRIA cameras.json, nerfstudio transforms.json or semsplat cameras.json. Default:
    /// the cameras.json of the scene's folder.
    #[arg(long)]
    cameras: Option<PathBuf>,
    /// True label maps (gray or palette class ids, or colour-coded through the class table;
    /// see --ignore-id and docs/label-maps.md), matched by image name.
    #[arg(long)]
    labels: PathBuf,
    /// Class table (JSON: id, name, color) naming the classes in the per-class IoU and giving
    /// the colours of colour-coded maps. Default: classes.json in or beside the label
    /// folder, else <scene>.classes.json (written by `fuse`).
    #[arg(long, value_name = "FILE")]
    classes: Option<PathBuf>,
    #[command(flatten)]
    label_format: super::LabelFormatArgs,
    #[arg(long, value_enum, default_value_t = Views::Test)]
    views: Views,
    /// A PLY with the true class of every Gaussian (e.g. a synth scene.ply), for 3D accuracy.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Images of the views (named like the cameras): also report PSNR and SSIM of the
    /// scene's rendered RGB (for trained scenes, whose appearance changed), the means over
    /// the views; a view rendered exactly makes the PSNR infinite (null in the JSON).
    #[arg(long)]
    images: Option<PathBuf>,
    /// Write the scores as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
}

#[derive(Serialize)]
struct EvalReport {
    views: usize,
    #[serde(flatten)]
    segmentation: SegmentationScores,
    gaussian_accuracy: Option<f64>,
    image_quality: Option<ImageQuality>,
}

pub fn run(args: EvalArgs) -> Result<()> {
    check_outputs(
        &[("--json", args.json.as_deref())],
        &[],
        &[
            Input::Scene("--scene", Some(&args.scene)),
            Input::Cameras("--cameras", args.cameras.as_deref()),
            Input::Labels("--labels", Some(&args.labels)),
            Input::File("--classes", args.classes.as_deref()),
            Input::Scene("--truth", args.truth.as_deref()),
            Input::Tree("--images", args.images.as_deref()),
        ],
    )?;
    let g = read_scene(&args.scene)?;
    let Some(classes) = g.class_ids.clone() else {
        bail!(
            "{} has no `class` property: run `semsplat fuse` first",
            args.scene.display()
        );
    };
    let table = eval_class_table(&args)?;
    let format = args.label_format.format();
    let (cams, dir) = open_truth_views(
        &cameras_for_scene(args.cameras.as_deref(), &args.scene)?,
        &args.labels,
        table.as_ref(),
        &format,
    )?;
    note_label_folder(&dir, &cams, args.views);
    let chosen = chosen_views(&args, &cams, &dir)?;
    let gaussian_accuracy = match &args.truth {
        Some(path) => Some(truth_accuracy(path, &classes)?),
        None => None,
    };
    let gpu = Gpu::new()?;
    let (confusion, ignored) = score_views(&gpu, &g, &classes, &chosen, &cams, &dir)?;
    let mut segmentation = confusion.scores();
    let true_ids: Vec<u32> = segmentation.per_class.iter().map(|c| c.id).collect();
    let value_warnings = [
        binary_mask_warning(&args.labels, &true_ids, ignored, &format),
        stray_255_warning(&args.labels, &true_ids, &format, table.as_ref()),
    ];
    if let Some(table) = &table {
        segmentation.name_classes(table);
    }
    let notes = segmentation.notes(&classes, table.is_some()).into_iter();
    let unclassified = unclassified_note(&classes, args.truth.is_some());
    for line in (value_warnings.into_iter().flatten())
        .chain(notes)
        .chain(unclassified)
    {
        eprintln!("{line}");
    }
    let image_quality = match &args.images {
        Some(image_dir) => {
            let views: Vec<&Camera> = chosen
                .iter()
                .map(|&i| chosen_camera(&cams, &dir, i))
                .collect();
            let scaled = dir.scaled_cameras(&cams);
            let images = ImageDir::new(image_dir).with_scaled_cameras(scaled);
            Some(rendered_quality(&gpu, &g, &images, &views)?)
        }
        None => None,
    };
    let report = EvalReport {
        views: chosen.len(),
        segmentation,
        gaussian_accuracy,
        image_quality,
    };
    print_report(&report);
    if let Some(path) = &args.json {
        write_bytes_atomic(path, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(())
}

/// The label folder's notes, and the cameras of --views it has no map for (not scored).
fn note_label_folder(dir: &LabelDir, cams: &[Camera], views: Views) {
    for note in dir.notes() {
        eprintln!("{note}");
    }
    let of_views: Vec<&Camera> = cams.iter().filter(|c| views.holds(c.split)).collect();
    let skipped: Vec<String> = (dir.skipped().iter())
        .filter(|name| of_views.iter().any(|c| &c.name == *name))
        .cloned()
        .collect();
    if !skipped.is_empty() {
        eprintln!(
            "note: {} of the {} cameras of --views {} have no label map and are not scored: {}",
            skipped.len(),
            of_views.len(),
            views.name(),
            list_some(&skipped)
        );
    }
}

/// Gaussians of class -1 occlude but draw no class: the pixels they cover show the classes
/// beside and behind them, so a scene that leaves many unclassified can score as well as
/// one that classes them (80% left at -1 scored mIoU 0.88 against its truth's 0.93).
fn unclassified_note(classes: &[i32], truth_given: bool) -> Option<String> {
    let unclassified = classes.iter().filter(|&&c| c < 0).count();
    let counted = match truth_given {
        true => {
            "; the 3D accuracy counts them wrong where --truth gives them a class (it \
                 scores only the Gaussians --truth classes)"
        }
        false => "",
    };
    (unclassified > 0).then(|| {
        format!(
            "note: {unclassified} of the scene's {} Gaussians ({:.1}%) have no class (-1): they \
             occlude but draw no class, so the pixels they cover take the classes beside and \
             behind them{counted}",
            classes.len(),
            100.0 * unclassified as f64 / classes.len() as f64
        )
    })
}

/// The confusion of the labels rendered from `g` (each Gaussian in its class) against the
/// `chosen` views' label maps, and the pixels those maps leave unlabeled.
fn score_views(
    gpu: &Gpu,
    g: &Gaussians,
    classes: &[i32],
    chosen: &[usize],
    cams: &[Camera],
    dir: &LabelDir,
) -> Result<(Confusion, u64)> {
    let mut renderer = LabelRenderer::new(gpu, g, classes)?;
    let mut confusion = Confusion::default();
    let (mut ignored, mut rendered, mut pixels) = (0u64, 0u64, 0u64);
    let bar = views_bar(chosen.len());
    for &i in chosen {
        interrupt::check()?;
        bar.inc(1);
        let truth = dir.load(i)?;
        pixels += truth.labels.len() as u64;
        ignored += truth
            .labels
            .iter()
            .filter(|&&l| l == LabelMap::IGNORE)
            .count() as u64;
        let predicted = renderer.render_ids(chosen_camera(cams, dir, i))?;
        rendered += predicted.iter().filter(|p| p.is_some()).count() as u64;
        confusion.add(&truth.labels, &predicted, LabelMap::IGNORE);
    }
    bar.finish_and_clear();
    // A score of nothing rendered says nothing of the classes.
    ensure!(
        rendered > 0,
        "no view renders any Gaussian with a class. {FRAME_HINT}, and that the scene's \
         classes are not all -1"
    );
    // Nor does a score against maps with no label: every class's IoU would read 0.
    ensure!(
        ignored < pixels,
        "every pixel of the {} scored views' label maps is unlabeled (the ignore id): there is \
         nothing to score against. Check --ignore-id and --views",
        chosen.len()
    );
    Ok((confusion, ignored))
}

/// `--classes`, else classes.json in or beside the label folder (the table of the maps
/// scored: a fused scene's sidecar holds only the classes its fusion's maps used, and a
/// class only the held-out views show has no colour there), else the scene's sidecar.
fn eval_class_table(args: &EvalArgs) -> Result<Option<ClassTable>> {
    if let Some(path) = &args.classes {
        return read_class_table(path).map(Some);
    }
    if let Some(path) = default_class_table(&args.labels) {
        return read_class_table(&path).map(Some);
    }
    read_classes_sidecar(&args.scene)
}

/// The label map entries of the views `--views` selects (at least one).
fn chosen_views(args: &EvalArgs, cams: &[Camera], dir: &LabelDir) -> Result<Vec<usize>> {
    let chosen: Vec<usize> = (0..dir.len())
        .filter(|&i| args.views.holds(chosen_camera(cams, dir, i).split))
        .collect();
    if chosen.is_empty() {
        bail!("no labeled view matches --views (cameras without splits are all train views; try --views all)");
    }
    Ok(chosen)
}

/// The camera of label map entry `i`.
fn chosen_camera<'a>(cams: &'a [Camera], dir: &LabelDir, i: usize) -> &'a Camera {
    &cams[dir.camera_index(i).expect("entry")]
}

/// 3D accuracy of `classes` against the true classes in the PLY at `path`.
fn truth_accuracy(path: &Path, classes: &[i32]) -> Result<f64> {
    let truth = read_scene(path)?;
    let Some(t) = truth.class_ids else {
        bail!("{} has no `class` property", path.display())
    };
    if t.len() != classes.len() {
        bail!(
            "--truth {} has {} Gaussians, --scene {}: the truth must hold the scene's own \
             Gaussians in their order (the synth scene.ply a fusion of it was made from); a \
             trained scene has others (densified, pruned), so score it by its views alone, \
             without --truth",
            path.display(),
            t.len(),
            classes.len()
        );
    }
    Ok(gaussian_accuracy(classes, &t))
}

/// PSNR and SSIM of the scene rendered from `views` against their images in `image_dir`.
fn rendered_quality(
    gpu: &Gpu,
    g: &Gaussians,
    image_dir: &ImageDir,
    views: &[&Camera],
) -> Result<ImageQuality> {
    let images = views
        .iter()
        .map(|cam| image_dir.load(cam))
        .collect::<Result<Vec<_>>>()?;
    let pairs: Vec<(&Camera, &[f32])> = views
        .iter()
        .zip(&images)
        .map(|(c, im)| (*c, im.as_slice()))
        .collect();
    image_quality(gpu, g, &pairs)
}

fn print_report(report: &EvalReport) {
    println!("views: {}", report.views);
    println!("mIoU: {:.4}", report.segmentation.miou);
    println!("pixel accuracy: {:.4}", report.segmentation.pixel_accuracy);
    if let Some(a) = report.gaussian_accuracy {
        println!("3D accuracy: {a:.4}");
    }
    if let Some(q) = &report.image_quality {
        println!("PSNR: {:.2} dB, SSIM: {:.4}", q.psnr, q.ssim);
    }
    for c in &report.segmentation.per_class {
        let name = c
            .name
            .as_deref()
            .map(|n| format!(" {n}"))
            .unwrap_or_default();
        println!(
            "  class {:>5}{name}: IoU {:.4} ({} px)",
            c.id, c.iou, c.pixels
        );
    }
}
