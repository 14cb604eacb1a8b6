//! `semsplat fuse`: training-free lifting of per-view label maps onto a scene's Gaussians.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, ensure, Context, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;

use super::args;
use super::fuse_consensus::{fuse_by_consensus, ConsensusOutputs};
use super::merge::ShardJob;
use super::progress::{follow, views_bar};
use super::render::{RenderedFiles, LABELS_PNG, PALETTE_PNG};
use super::{
    check_outputs, open_dataset, write_scene_with_table, Input, Interruptible, FRAME_HINT,
};
use semsplat::dataset::Dataset;
use semsplat::dataset::{user_classes, DatasetPaths};
use semsplat::eval::label_render::{check_ids_fit_16_bit, LabelRenderer};
use semsplat::fuse::consensus_report::SegmentReport;
use semsplat::fuse::partial::manifest_path;
use semsplat::fuse::{
    accumulate_assigned, assign_semantic_near, class_totals, evidence_passes, nearest_neighbours,
    one_vs_rest_row, Accumulation, AssignOnGpu, Assignment, ClassScores, Clustering, EvidenceRows,
    FuseConfig, FuseStats, Method, Shard, SpilledRows, TieNeighbours, TIE_NEIGHBOURS,
};
use semsplat::gpu::{Gpu, GpuError};
use semsplat::render::GpuScene;
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::classes::{read_class_table, write_class_table, ClassInfo, ClassTable};
use semsplat::scene::labels::{write_label_png, write_palette_png, LabelMap};
use semsplat::scene::ply::{
    classes_sidecar_path, every_scenes_vertex_bytes, read_classes_sidecar, write_ply,
};
use semsplat::scene::scene_file::{cameras_for_scene, read_scene, resolve_scene_path};
use semsplat::scene::{Camera, Gaussians, Split};
use semsplat::util::free_space::check_free_space;
use semsplat::util::npy::write_npy_rows;
use semsplat::util::{interrupt, write_bytes_atomic, OutputBatch};

/// The base methods of `--method`; their variant flags (`--occlusion`, `--weighted`,
/// `--per-view`) pick the [`Method`] from `semsplat::fuse::SPELLINGS`.
#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum MethodArg {
    /// Majority vote of the Gaussian centers projected into each view (Semantic Fusion).
    Vote,
    /// FlashSplat: optimal assignment from every pixel's alpha*T contributions.
    Flashsplat,
    /// Segment consensus: 3D segments from co-occurrence in connected label regions, one
    /// vote per view and segment (robust to per-view label flicker; a near tie whose two
    /// last-joined halves their views decide clearly apart is split, other near ties go to
    /// the class the scene's own label confusions make likeliest). Also writes each
    /// Gaussian's `class_entropy` and `segment`, and with --report the segments whose views
    /// disagree (docs/robustness.md).
    SegmentConsensus,
}

#[derive(Args)]
pub struct FuseArgs {
    /// The scene: a 3DGS PLY (INRIA layout, or SuperSplat's compressed PLY), a .splat, an
    /// .spz, an INRIA training-output folder (its latest iteration) or a scene folder holding
    /// scene.ply (as `synth` writes). --out is always a standard PLY.
    #[arg(long)]
    scene: PathBuf,
    /// Cameras: COLMAP model folder, INRIA cameras.json, nerfstudio transforms.json or semsplat cameras.json. Default
    /// (with --labels or --render-views): the cameras.json of the scene's folder (a `synth`
    /// room, an INRIA run).
    #[arg(long)]
    cameras: Option<PathBuf>,
    /// Folder of label PNGs (gray or palette class ids, or colour-coded through the class
    /// table; see --ignore-id and docs/label-maps.md), matched to cameras by image name
    /// (subfolders mirror the images'). Views without a label map are skipped.
    #[arg(long)]
    labels: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = MethodArg::Flashsplat)]
    method: MethodArg,
    /// vote: count a center only where it is visible (depth within --depth-tol of the
    /// rendered expected depth at that pixel).
    #[arg(long, conflicts_with = "weighted")]
    occlusion: bool,
    /// vote: weigh each vote by the Gaussian's alpha*T at the pixel holding its center.
    #[arg(long)]
    weighted: bool,
    /// flashsplat: divide each view's alpha*T by the Gaussian's projected footprint in that
    /// view, so every view counts about once (as in a vote) instead of by the pixels it
    /// covers. More robust when the segmenter flickers from view to view; on consistent
    /// labels it matches plain flashsplat within a fraction of a percent. --save-contrib then
    /// writes this normalized evidence.
    #[arg(long)]
    per_view: bool,
    /// segment-consensus: then relabel every view's connected label regions with the
    /// consensus classes of the Gaussians seen in them and run FlashSplat on the relabeled
    /// views, so object edges fall where the pixels put them (the best held-out mIoU under
    /// flicker; on a CPU device such as lavapipe it walks every view once, as FlashSplat
    /// does, keeping each Gaussian's weights per label region until the regions' classes are
    /// known, then reads each view's labels again to relabel them: about 1.25x FlashSplat's
    /// time there; on a GPU it walks the relabeled views again, cheaper there than reading
    /// the kept weights back). A region whose Gaussians' classes are mixed is left
    /// undecided (its pixels count for the consensus class of each Gaussian that
    /// renders there), unless its own class holds a quarter of them and, with those of
    /// other classes lying within 8 pixels of their own class's label (a label edge drawn a
    /// few pixels off), 85%. Nor does a region take a class the view labels within 8 pixels
    /// of half or more of that class's Gaussians there: an edge the segmenter drew (then
    /// decided as a mixed region). A region no class takes keeps its label where under 15%
    /// of its Gaussians are of other classes that the views call by that label more than
    /// 3% of the time (in the scene's clearly decided segments): the label cannot be the
    /// others' flicker, so its edge was drawn off.
    #[arg(long)]
    relabel: bool,
    /// segment-consensus: how the segments join once the pairs every view saw in one region
    /// are joined. `order` (default): one order, strongest evidence first, on one core.
    /// `rounds`: that order among those pieces, then the single Gaussians left join in
    /// rounds decided on every core, then the order among what is left; on many cores
    /// faster (most joins take in one Gaussian). Under flicker 0.3 the same per-Gaussian
    /// accuracy as `order`, held-out mIoU 0.04 points higher with --relabel and 0.78 lower
    /// without (mean of 10 synthetic runs; small objects decided otherwise).
    #[arg(long, value_enum, default_value_t = Clustering::Order)]
    clustering: Clustering,
    /// Relative depth tolerance of the visibility test (> 0; default 0.05): vote
    /// --occlusion's, against the expected depth, and segment consensus's, against the
    /// median depth (the depth of the Gaussian that takes a pixel's transmittance below one
    /// half). The other methods have no such test (a note says so).
    #[arg(long, value_parser = args::positive::<f32>)]
    depth_tol: Option<f32>,
    /// The consensus methods' visibility test also hides a Gaussian whose center lies
    /// behind the surface its pixel shows: more than this fraction of the median depth
    /// behind the opaque depth (the depth of the Gaussian that takes the transmittance below
    /// 5%), the farthest of its pixel's and the eight neighbours' (a surface seen at a slant
    /// changes depth across a pixel). A wall or floor a few centimetres behind an object
    /// standing in front of it passes --depth-tol there, and would count as seen on the
    /// object. A pixel that never turns opaque hides nothing; 1e9 turns the test off.
    /// Default 0.01.
    #[arg(long, value_parser = args::non_negative::<f32>)]
    behind_tol: Option<f32>,
    /// Class table (JSON: id, name, color). Default: classes.json beside or inside the label
    /// folder, else the ids found in the label maps; selecting from a fused scene (no
    /// --labels), its `.classes.json`, else its ids.
    #[arg(long)]
    classes: Option<PathBuf>,
    #[command(flatten)]
    label_format: super::LabelFormatArgs,
    /// Reassign from a saved evidence matrix (`--save-contrib` of an earlier run) instead of
    /// rendering (no GPU needed), e.g. to try another --gamma: each Gaussian takes its
    /// class of most evidence, so the options of how the evidence is gathered (--method and
    /// its variants) do not apply, and its rows are the classes of the table saved beside
    /// it (FILE.classes.json, not --classes); a segment-consensus run is not reproduced from
    /// its evidence (its classes are decided per segment).
    #[arg(long, conflicts_with_all = [
        "labels", "save_contrib", "method", "occlusion", "weighted", "per_view", "relabel",
        "depth_tol", "behind_tol", "float_atomics", "train_only", "ignore_id", "mem_budget",
        "classes", "clustering",
    ])]
    contrib: Option<PathBuf>,
    /// Accumulate with float32 atomics instead of 64-bit fixed point (fixed point gives the
    /// same A on every run).
    #[arg(long)]
    float_atomics: bool,
    /// Fuse only the cameras marked "train" (semsplat cameras.json), keeping the test views
    /// held out for `semsplat eval`.
    #[arg(long)]
    train_only: bool,
    /// Device memory for the evidence matrix, e.g. 512M or 2G; larger class counts are
    /// processed in batches (same result). Default: a quarter of device memory.
    #[arg(long, value_parser = args::bytes)]
    mem_budget: Option<u64>,
    /// Fuse only shard K of N of the labeled views (the views, in camera order, whose
    /// position among those with a label map is K modulo N) and write its partial evidence
    /// exactly (uint64 fixed point or uint32 vote counts, NumPy [classes, Gaussians]) to
    /// --out, with a manifest naming the inputs beside it (part0.npy: part0.manifest.json);
    /// `semsplat merge` sums the N parts into what one fuse of every view gives, bit for bit
    /// (docs/sharded-fusion.md).
    #[arg(long, value_parser = Shard::parse, conflicts_with_all = [
        "contrib", "save_contrib", "float_atomics", "extract", "remove", "render_views",
        "save_membership", "palette_ply", "report",
    ])]
    shard: Option<Shard>,
    #[command(flatten)]
    output: OutputArgs,
}

/// `--gamma` when not given: no bias toward the background.
const DEFAULT_GAMMA: f64 = 0.0;

/// What `fuse` and `merge` write from the evidence matrix.
#[derive(Args)]
pub struct OutputArgs {
    /// Background bias of the one-vs-rest assignment used by --extract, --remove and
    /// --save-membership, in [-1, 1] (FlashSplat's Listing 1.1; default 0): larger keeps
    /// fewer Gaussians in the object. Gaussians no view saw are in no object at any gamma
    /// (the listing puts them in every one below 0).
    #[arg(long, allow_hyphen_values = true, value_parser = args::signed_unit_interval)]
    pub gamma: Option<f64>,
    /// Output PLY: the input Gaussians with `class` (label id, -1 for Gaussians no view saw,
    /// or whose evidence tied and neither their neighbours' evidence nor the whole scene's
    /// broke the tie; segment consensus gives the Gaussians whose centers no view observed
    /// their neighbours' class where they agree, outward from the observed ones) and `class_conf` (the winning
    /// class's share of the evidence; `fuse`'s segment consensus: its posterior probability
    /// with every view counted once, 0 where no view observed the Gaussian's center, beside
    /// `class_entropy`, ln(classes) there, and `segment`); semantics the input scene held
    /// (a trained scene's logits) are replaced. The class table goes beside it, its `.ply`
    /// replaced (fused.ply: fused.classes.json; a name without `.ply` gets `.classes.json`
    /// added). `fuse --shard` only: the partial evidence (.npy, see --shard) instead.
    #[arg(long)]
    pub out: PathBuf,
    /// Write a JSON report: per-class counts, the assignment's time and (`fuse` of views) the
    /// views' timings, views/s and peak device memory (`fuse`'s segment consensus: also the
    /// segments, their vote splits and the flagged ones, each with where it is and which
    /// views called it what; a segment is flagged where another class than its own holds
    /// the votes of several views and a good share of all, in a segment of more than a few
    /// Gaussians: a scene of a handful of views flags nothing; docs/robustness.md).
    /// Class -1 in the counts: no class (no view saw the Gaussian, or its evidence tied).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write the evidence matrix A as float64 NumPy [classes, Gaussians], rows in the order
    /// of FILE.classes.json written beside it. Each Gaussian's class is its column's
    /// argmax; segment consensus writes the view votes it decided from (the Gaussian's
    /// segment's, its own views', or its neighbours' classes where no view observed it),
    /// `--relabel` FlashSplat's weights over the relabeled views where those decided the
    /// Gaussian, else the consensus votes: a column's values are of one kind, not every
    /// column of the same; where a segment's votes are a near tie the scene's class
    /// confusions decide it, which may be the column's second class.
    #[arg(long)]
    pub save_contrib: Option<PathBuf>,
    /// Keep only the Gaussians of this class (name, any case, or id) in --out, by FlashSplat's
    /// one-vs-rest assignment with --gamma (which may keep Gaussians whose own class is
    /// another; `fuse`'s segment consensus selects by the classes it decided). `fuse` of an
    /// already fused scene (a `class` property) without --labels or --contrib selects by
    /// that class directly (no re-fusing).
    #[arg(long, conflicts_with = "remove")]
    pub extract: Option<String>,
    /// Drop the Gaussians of this class (name, any case, or id) from --out (as --extract
    /// selects them); `fuse` of a fused
    /// scene without --labels or --contrib drops by its `class` property.
    #[arg(long)]
    pub remove: Option<String>,
    /// Render label and palette PNGs of every view from the fused scene into DIR
    /// (<view>.labels.png with label ids, 255/65535 where nothing is drawn; <view>.palette.png;
    /// rig views named by a relative path go into subfolders: DIR/cam0/00001.labels.png).
    /// The whole scene's classes, before --extract or --remove select. Files of those names
    /// that no render wrote are refused, as `render` refuses them.
    #[arg(long)]
    pub render_views: Option<PathBuf>,
    /// Write the multi-instance membership S of FlashSplat's Listing 1.1 (with --gamma) as a
    /// float32 NumPy array [classes, Gaussians] of 0/1: a Gaussian may belong to several
    /// classes or none. Rows follow --out's class table.
    #[arg(long)]
    pub save_membership: Option<PathBuf>,
    /// Also write a copy colored by class palette, viewable in any 3DGS viewer.
    #[arg(long)]
    pub palette_ply: Option<PathBuf>,
}

fn contrib_sidecar(path: &Path) -> PathBuf {
    path.with_extension("classes.json")
}

#[derive(Serialize)]
struct ClassCount {
    id: i64,
    name: String,
    gaussians: usize,
}

#[derive(Serialize)]
struct Report<'a> {
    method: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    accumulation: Option<Accumulation>,
    gaussians: usize,
    classes: usize,
    stats: Option<FuseStats>,
    assign_s: f64,
    total_s: f64,
    per_class: Vec<ClassCount>,
    /// Consensus methods: the segments, those flagged, and per class the views' votes.
    #[serde(skip_serializing_if = "Option::is_none")]
    segments: Option<SegmentReport>,
}

fn find_class(table: &ClassTable, key: &str) -> Result<ClassInfo> {
    table.find(key).cloned()
}

/// Refuses an --extract or --remove that leaves no Gaussian (`selected`): an empty PLY says
/// nothing (nothing of the class won a Gaussian, or every Gaussian is of it). `gamma`: the
/// bias the one-vs-rest selection used, where it selected by evidence (the reason to name
/// when it left none: `--gamma 1` keeps no Gaussian of any class).
fn check_selected_some(
    args: &OutputArgs,
    selected: &Gaussians,
    class: Option<&ClassInfo>,
    gamma: Option<f64>,
) -> Result<()> {
    let Some(class) = class.filter(|_| selected.is_empty()) else {
        return Ok(());
    };
    let named = format!("class '{}' (id {})", class.name, class.id);
    let by = match gamma {
        Some(gamma) => format!(
            " by FlashSplat's one-vs-rest test at --gamma {gamma} (a larger --gamma keeps \
             fewer Gaussians in the class)"
        ),
        None => String::new(),
    };
    match args.extract.is_some() {
        true => bail!("no Gaussian is of {named}{by}: nothing to extract, nothing written"),
        false => {
            bail!("every Gaussian is of {named}{by}: removing it leaves none, nothing written")
        }
    }
}

/// The class --extract or --remove names, among a fusion's classes (`table`: those its
/// label maps use, not every class of a class table given).
pub(super) fn selected_class(args: &OutputArgs, table: &ClassTable) -> Result<Option<ClassInfo>> {
    let name = args.extract.as_ref().or(args.remove.as_ref());
    name.map(|name| {
        find_class(table, name)
            .context("--extract and --remove choose among the classes the label maps use")
    })
    .transpose()
}

/// Every Gaussian's class, the evidence rows where an output reads them, and the rows'
/// class table, with the fusion statistics when it was rendered.
pub(super) struct Evidence {
    pub assignment: Assignment,
    /// Kept only where an output needs them ([`needs_rows`]) or they are in memory anyway.
    pub rows: Option<Box<dyn EvidenceRows>>,
    pub table: ClassTable,
    pub stats: Option<FuseStats>,
    /// The consensus methods' entropy, segments and segment report.
    pub consensus: Option<ConsensusOutputs>,
}

impl Evidence {
    /// Evidence held whole in memory (--contrib, merge), assigned on the host: ties go to
    /// the class the Gaussian's nearest neighbours hold most evidence for.
    pub fn from_matrix(scores: ClassScores, g: &Gaussians, table: ClassTable) -> Evidence {
        let knn = nearest_neighbours(&g.means, TIE_NEIGHBOURS);
        Evidence {
            assignment: assign_semantic_near(&scores, Some((&knn, TIE_NEIGHBOURS))),
            rows: Some(Box::new(scores)),
            table,
            stats: None,
            consensus: None,
        }
    }
}

/// The evidence rows, which [`needs_rows`] made sure were kept for the outputs that read
/// them.
fn kept(rows: &mut Option<Box<dyn EvidenceRows>>) -> Result<&mut dyn EvidenceRows> {
    match rows.as_deref_mut() {
        Some(rows) => Ok(rows),
        None => bail!("internal: the evidence rows were not kept for this output"),
    }
}

/// Whether an output reads the evidence itself (not only the assignment): then fusion
/// spills its rows to disk as they stream from the GPU.
fn needs_rows(args: &OutputArgs) -> bool {
    args.save_contrib.is_some() || args.save_membership.is_some() || selecting(args)
}

/// Whether --extract or --remove selects Gaussians by class.
fn selecting(args: &OutputArgs) -> bool {
    args.extract.is_some() || args.remove.is_some()
}

/// How the evidence was gathered, for the report.
pub(super) struct Provenance {
    /// How the report names the method: its CLI spelling, or where the evidence came from.
    pub method: &'static str,
    /// How the views' sums were taken; None where nothing summed them here (a saved
    /// matrix) or the method does not read it ([`Method::reads_accumulation`]).
    pub accumulation: Option<Accumulation>,
    pub start: Instant,
}

pub fn run(mut args: FuseArgs) -> Result<()> {
    let start = Instant::now();
    // --render-views needs cameras only where there is something to fuse (from a fused
    // scene's class it is refused for another reason, said first).
    let renders_fused = args.contrib.is_some() && args.output.render_views.is_some();
    if args.cameras.is_none() && (args.labels.is_some() || renders_fused) {
        args.cameras = Some(cameras_for_scene(None, &args.scene)?);
    }
    let contrib_table = args.contrib.as_deref().map(contrib_sidecar);
    // A shard's manifest is written after its part.
    let manifest = args.shard.map(|_| manifest_path(&args.output.out));
    check_output_args(
        &args.output,
        &[("--out's manifest", manifest.as_deref())],
        &[
            Input::Scene("--scene", Some(&args.scene)),
            Input::Cameras("--cameras", args.cameras.as_deref()),
            Input::Labels("--labels", args.labels.as_deref()),
            Input::File("--classes", args.classes.as_deref()),
            Input::File("--contrib", args.contrib.as_deref()),
            Input::File("--contrib's class table", contrib_table.as_deref()),
        ],
        args.shard.is_none(),
    )?;
    let g = read_scene(&args.scene)?;
    // An empty scene would fuse to an empty PLY, exit 0: nearly always the wrong file.
    ensure!(
        !g.is_empty(),
        "--scene {} holds no Gaussians: nothing to fuse",
        args.scene.display()
    );
    if args.shard.is_none() {
        // Every scene's properties and the class and its confidence (4 bytes each); a
        // trained scene's logits are replaced, not kept.
        let vertex = every_scenes_vertex_bytes(g.sh_coeffs()) + 2 * 4;
        let at_least = (g.len() * vertex) as u64;
        check_free_space("--out", &args.output.out, at_least, "the fused scene")?;
    }
    let method = selected_method(&args)?;
    let fused_table = fused_scene_table(&args, &g)?;
    match (&fused_table, &args.contrib) {
        (Some(_), _) => note_fusion_options_unread(&args),
        (None, None) => note_options_without_effect(&args, method),
        (None, Some(_)) => {}
    }
    let accumulation = if args.float_atomics {
        Accumulation::Float
    } else {
        Accumulation::FixedPoint
    };
    if let Some(shard) = args.shard {
        return fuse_shard(&args, &g, method, shard);
    }
    if let Some(table) = fused_table {
        return select_from_fused(&args, g, &table, start);
    }
    let evidence = match &args.contrib {
        Some(path) => load_evidence(path, &g)?,
        None => {
            fuse_views(&args, &g, method, accumulation).map_err(|e| with_tiled_hint(e, method))?
        }
    };
    let provenance = Provenance {
        method: match args.contrib {
            Some(_) => "saved evidence (--contrib)",
            None => method.name(),
        },
        accumulation: (args.contrib.is_none() && method.reads_accumulation())
            .then_some(accumulation),
        start,
    };
    write_fused(
        &args.output,
        args.cameras.as_deref(),
        g,
        evidence,
        &provenance,
    )
}

/// Writes the evidence (--save-contrib, with its class table) and membership
/// (--save-membership) matrices; returns each Gaussian's evidence over every class where
/// one-vs-rest needs it (--save-membership, --extract, --remove), else nothing.
fn write_matrices(
    args: &OutputArgs,
    rows: &mut Option<Box<dyn EvidenceRows>>,
    table: &ClassTable,
) -> Result<Vec<f64>> {
    if let Some(path) = &args.save_contrib {
        kept(rows)?.save_npy(path)?;
        write_class_table(&contrib_sidecar(path), table)?;
    }
    // One read of the rows for the totals, once.
    let one_vs_rest = args.save_membership.is_some() || selecting(args);
    let totals = match one_vs_rest {
        true => class_totals(kept(rows)?)?,
        false => Vec::new(),
    };
    if let Some(path) = &args.save_membership {
        let gamma = args.gamma.unwrap_or(DEFAULT_GAMMA);
        save_membership(path, kept(rows)?, &totals, gamma)?;
    }
    Ok(totals)
}

/// Assigns every Gaussian from the evidence and writes every output `args` asks for: the
/// labelled PLY and its class table, the palette PLY, --extract/--remove, the evidence and
/// membership matrices, label renders and the report. `fuse` and `merge` both end here.
pub(super) fn write_fused(
    args: &OutputArgs,
    cameras: Option<&Path>,
    mut g: Gaussians,
    evidence: Evidence,
    provenance: &Provenance,
) -> Result<()> {
    let Evidence {
        assignment,
        mut rows,
        table,
        stats,
        consensus,
    } = evidence;
    let assign_start = Instant::now();
    assign_classes(&mut g, assignment, &table);
    let segments = consensus.map(|c| c.annotate(&mut g));
    // Everything that can refuse the run, before its first file is written.
    check_assigned(args, &g)?;
    let selected_class = selected_class(args, &table)?;
    let label_views = match &args.render_views {
        Some(dir) => Some(LabelViews::open(
            cameras.context("--render-views needs --cameras")?,
            &g,
            dir,
        )?),
        None => None,
    };
    // Every file from here lands with the others or none does (a failed PLY left the
    // membership matrix written before it beside the last run's PLY).
    let batch = OutputBatch::open();
    let totals = write_matrices(args, &mut rows, &table)?;
    // The report's assign_s is the assignment's and selection's: not the views' render.
    let render_start = Instant::now();
    if let (Some(dir), Some(views)) = (&args.render_views, label_views) {
        views.render(dir, &g, &table)?;
    }
    let render_s = render_start.elapsed().as_secs_f64();
    // The consensus decides per segment, which its evidence rows do not hold: it selects by
    // the classes it decided; the evidence methods by FlashSplat's one-vs-rest.
    let selected_id = selected_class.as_ref().map(|c| c.id);
    let selected = match segments {
        Some(_) => select_by_class(args, selected_id, g),
        None => select_members(args, selected_id, g, &mut rows, &totals, &table)?,
    };
    let gamma = segments
        .is_none()
        .then(|| args.gamma.unwrap_or(DEFAULT_GAMMA));
    check_selected_some(args, &selected, selected_class.as_ref(), gamma)?;
    let assign_s = assign_start.elapsed().as_secs_f64() - render_s;

    write_outputs(args, &selected, &table)?;
    let report = Report {
        method: provenance.method,
        accumulation: provenance.accumulation,
        gaussians: selected.len(),
        classes: table.len(),
        stats,
        assign_s,
        total_s: provenance.start.elapsed().as_secs_f64(),
        per_class: per_class_counts(&selected, &table),
        segments,
    };
    write_report(args, &report, selected_class.as_ref(), batch)
}

/// With --extract/--remove on an already fused scene (a `class` property) and no evidence
/// to fuse from (neither --labels nor --contrib), the class table to select with: --classes,
/// else the scene's `.classes.json` sidecar, else the ids present. `None` when fusing as
/// usual.
fn fused_scene_table(args: &FuseArgs, g: &Gaussians) -> Result<Option<ClassTable>> {
    if !selecting(&args.output) || args.labels.is_some() || args.contrib.is_some() {
        return Ok(None);
    }
    let Some(ids) = &g.class_ids else {
        return Ok(None);
    };
    if args.output.save_contrib.is_some()
        || args.output.save_membership.is_some()
        || args.output.render_views.is_some()
    {
        bail!(
            "selecting from a fused scene's class (no --labels or --contrib) has no evidence \
             matrix: --save-contrib, --save-membership and --render-views need --labels or \
             --contrib (render a fused scene with `semsplat render --semantics`)"
        );
    }
    if let Some(path) = &args.classes {
        return read_class_table(path).map(Some);
    }
    let scene_file = resolve_scene_path(&args.scene)?;
    Ok(Some(match read_classes_sidecar(&scene_file)? {
        Some(table) => table,
        None => ClassTable::from_ids(ids.iter().filter(|&&c| c >= 0).map(|&c| c as u32)),
    }))
}

/// --extract/--remove straight from a fused scene's `class` (no re-fusing): keeps (or drops)
/// the Gaussians whose class is the one named. --gamma does not apply: it needs the evidence
/// matrix (--contrib).
fn select_from_fused(
    args: &FuseArgs,
    g: Gaussians,
    table: &ClassTable,
    start: Instant,
) -> Result<()> {
    let ((Some(name), _) | (_, Some(name))) = (&args.output.extract, &args.output.remove) else {
        unreachable!("fused_scene_table checked --extract/--remove");
    };
    if args.output.gamma.is_some() {
        eprintln!("note: --gamma has no effect selecting by a fused scene's class");
    }
    let class = find_class(table, name)?;
    let id = class.id as i32;
    let ids = g
        .class_ids
        .as_deref()
        .expect("fused_scene_table checked class");
    let keep: Vec<bool> = ids
        .iter()
        .map(|&c| (c == id) == args.output.extract.is_some())
        .collect();
    let selected = g.select(&keep);
    check_selected_some(&args.output, &selected, Some(&class), None)?;
    let batch = OutputBatch::open();
    write_outputs(&args.output, &selected, table)?;
    let report = Report {
        method: "class property of a fused scene",
        accumulation: None,
        gaussians: selected.len(),
        classes: table.len(),
        stats: None,
        assign_s: 0.0,
        total_s: start.elapsed().as_secs_f64(),
        per_class: per_class_counts(&selected, table),
        segments: None,
    };
    write_report(&args.output, &report, Some(&class), batch)
}

/// Every file and folder the run will write (`args`' and the `extra` files) can be
/// written, and is none of `inputs` (checked before any work).
pub(super) fn check_output_args(
    args: &OutputArgs,
    extra: &[(&str, Option<&Path>)],
    inputs: &[Input],
    out_is_ply: bool,
) -> Result<()> {
    // A PLY named .npy would load in no NumPy and look like a part to `merge`, one named
    // .png like a label map or photo (and replace it); a part named .ply would look like a
    // scene to every reader of PLYs.
    let named = |ext: &str| (args.out.extension()).is_some_and(|e| e.eq_ignore_ascii_case(ext));
    ensure!(
        !(out_is_ply && named("npy")),
        "--out {} is written as a PLY (the fused scene), not a NumPy array: give it a .ply \
         name (--save-contrib writes the evidence as .npy; fuse --shard K/N writes a part)",
        args.out.display()
    );
    ensure!(
        out_is_ply || !named("ply"),
        "--out {} is a shard's part, a NumPy array of evidence, not a PLY: give it a .npy \
         name (`semsplat merge` writes the fused PLY from the parts)",
        args.out.display()
    );
    let contrib_table = args.save_contrib.as_deref().map(contrib_sidecar);
    if args.gamma.is_some()
        && args.extract.is_none()
        && args.remove.is_none()
        && args.save_membership.is_none()
    {
        eprintln!("note: --gamma has no effect without --extract, --remove or --save-membership");
    }
    let files = [
        ("--out", Some(args.out.as_path())),
        (
            "--out's class table",
            Some(&classes_sidecar_path(&args.out)),
        ),
        ("--report", args.report.as_deref()),
        ("--save-contrib", args.save_contrib.as_deref()),
        ("--save-contrib's class table", contrib_table.as_deref()),
        ("--save-membership", args.save_membership.as_deref()),
        ("--palette-ply", args.palette_ply.as_deref()),
    ];
    check_outputs(
        &[&files[..], extra].concat(),
        &[("--render-views", args.render_views.as_deref())],
        inputs,
    )?;
    // After the inputs: an --out that is one is refused as that, whatever its name.
    if let (true, Some(ext)) = (out_is_ply && !named("ply"), args.out.extension()) {
        bail!(
            "--out {} is written as a PLY (the fused scene), not a .{} file: give it a .ply \
             name",
            args.out.display(),
            ext.to_string_lossy()
        );
    }
    Ok(())
}

/// The method `--method` and its variant flags name.
fn selected_method(args: &FuseArgs) -> Result<Method> {
    let base = args
        .method
        .to_possible_value()
        .expect("no --method value is skipped");
    let flags: Vec<&str> = [
        ("occlusion", args.occlusion),
        ("weighted", args.weighted),
        ("per-view", args.per_view),
        ("relabel", args.relabel),
    ]
    .into_iter()
    .filter_map(|(flag, set)| set.then_some(flag))
    .collect();
    Method::from_flags(base.get_name(), &flags).map_err(|e| anyhow!(e))
}

/// A saved evidence matrix (`--contrib`) and its row table, checked against the scene.
fn load_evidence(path: &Path, g: &Gaussians) -> Result<Evidence> {
    // A shard's part is partial sums in integers, of part of the views.
    let manifest = manifest_path(path);
    ensure!(
        !manifest.is_file(),
        "{} is a part of a sharded fusion (its manifest {} is beside it): `semsplat merge` \
         sums the parts into what --contrib reads (merge --save-contrib), or fuses them",
        path.display(),
        manifest.display()
    );
    let scores = ClassScores::load_npy(path)?;
    let table = read_class_table(&contrib_sidecar(path)).with_context(|| {
        format!(
            "{} needs its row table {}",
            path.display(),
            contrib_sidecar(path).display()
        )
    })?;
    if scores.n != g.len() || scores.classes != table.len() {
        bail!(
            "{} holds [{}, {}] but the scene has {} Gaussians and the row table {} classes",
            path.display(),
            scores.classes,
            scores.n,
            g.len(),
            table.len()
        );
    }
    Ok(Evidence::from_matrix(scores, g, table))
}

/// Accumulates the evidence of every labeled view on the GPU and assigns every Gaussian
/// (on the GPU where the method's evidence allows: `accumulate_assigned`). The evidence
/// rows are spilled beside --out only when an output reads them.
fn fuse_views(
    args: &FuseArgs,
    g: &Gaussians,
    method: Method,
    accumulation: Accumulation,
) -> Result<Evidence> {
    let data = open_labeled_views(args)?;
    // Known before the first view: a name no map uses would fail after the whole fusion.
    selected_class(&args.output, &data.table)?;
    let cfg = fuse_config(args, method, accumulation);
    if method.is_consensus() {
        return fuse_by_consensus(g, data, &cfg);
    }
    let gpu = Gpu::new()?;
    let scene = GpuScene::upload_for(&gpu, g, method.scene_attributes())?;
    let mut spill = match needs_rows(&args.output) {
        true => Some(SpilledRows::beside(
            &args.output.out,
            data.classes.len(),
            g.len(),
        )?),
        false => None,
    };
    let keep_rows = spill.is_some();
    let mut append = |e: usize, row: &[f64]| match spill.as_mut() {
        Some(spill) => spill.append(e, row),
        None => Ok(()),
    };
    let with = AssignOnGpu {
        knn: Some(TieNeighbours::Search(&g.means, TIE_NEIGHBOURS)),
        rows: keep_rows.then_some(&mut append as &mut dyn FnMut(usize, &[f64]) -> Result<()>),
    };
    note_passes(&gpu, &cfg, data.classes.len(), g.len())?;
    let bar = views_bar(data.cameras.len());
    let track = follow(&bar);
    let (assignment, stats) = accumulate_assigned(
        &gpu,
        &scene,
        &data.cameras,
        &Interruptible(&data),
        data.classes.len(),
        &cfg,
        with,
        |done, total| {
            track(done, total);
            bar.set_message(memory_line(scene.n, &gpu));
        },
    )?;
    bar.finish_and_clear();
    Ok(Evidence {
        assignment,
        rows: spill.map(|s| Box::new(s) as Box<dyn EvidenceRows>),
        table: data.table,
        stats: Some(stats),
        consensus: None,
    })
}

/// `e`, where it is a binding over the device's limit in a method that holds a view's
/// pixels in one binding (vote at centers, segment consensus), with what to do: there the
/// image's size is the cause, and the tiled methods take a view a block of tiles at a time.
fn with_tiled_hint(e: anyhow::Error, method: Method) -> anyhow::Error {
    let binding = |c: &(dyn std::error::Error + 'static)| {
        matches!(
            c.downcast_ref::<GpuError>(),
            Some(GpuError::BindingRange { .. })
        )
    };
    if method.is_tiled() || !e.chain().any(binding) {
        return e;
    }
    // The chain as `{e:#}` writes it, but the binding error's generic remedy (fewer classes
    // or Gaussians would not help a view's pixels) gives way to the one that does.
    let chain: Vec<String> = e
        .chain()
        .map(|c| match c.downcast_ref::<GpuError>() {
            Some(g) => g.fact(),
            None => c.to_string(),
        })
        .collect();
    anyhow!(
        "{}\n{} holds a whole view's pixels in one binding: downscale the label maps (and the \
         cameras' intrinsics with them), or use `--method flashsplat` or `--method vote \
         --weighted`, which walk a view a block of tiles at a time and take images this large",
        chain.join(": "),
        method.name()
    )
}

/// Says where the evidence matrix takes more than one pass over the views: each pass runs
/// every view again, so thousands of classes multiply the run's time.
fn note_passes(gpu: &Gpu, cfg: &FuseConfig, classes: usize, gaussians: usize) -> Result<()> {
    let (rows, passes) = evidence_passes(gpu, cfg, classes, gaussians)?;
    if passes > 1 {
        eprintln!(
            "note: the evidence of {classes} classes x {gaussians} Gaussians takes {passes} \
             passes over the views ({rows} classes a pass, within --mem-budget or a quarter of \
             the device's memory): a larger --mem-budget takes fewer"
        );
    }
    Ok(())
}

/// The progress line's tail: the scene's size and the memory in use.
fn memory_line(gaussians: u32, gpu: &Gpu) -> String {
    let mib = |b: u64| b >> 20;
    let host = semsplat::util::memory::peak_host_bytes().unwrap_or(0);
    format!(
        "{gaussians} Gaussians, device {} MiB, host peak {} MiB",
        mib(gpu.memory_reserved()),
        mib(host)
    )
}

/// The cameras, label maps and class table of --cameras, --labels and --classes.
fn open_labeled_views(args: &FuseArgs) -> Result<Dataset> {
    let (Some(cameras), Some(labels)) = (&args.cameras, &args.labels) else {
        let missing = match (&args.cameras, &args.labels) {
            (None, None) => "--cameras and --labels are",
            (None, Some(_)) => "--cameras is",
            _ => "--labels is",
        };
        bail!("{missing} needed (or --contrib to reassign from a saved matrix)");
    };
    let paths = DatasetPaths {
        cameras,
        labels,
        class_table: args.classes.as_deref(),
        train_only: args.train_only,
        format: args.label_format.format(),
    };
    let data = open_dataset(&paths, "are skipped")?;
    // Those with a label map: the others are skipped, not fused.
    let held_out = (data.cameras.iter().enumerate())
        .filter(|&(view, c)| c.split == Split::Test && data.has_label_map(view))
        .count();
    if held_out > 0 {
        // Scored by `eval`'s default views, they would score what was fused from them.
        let (cameras, are) = match held_out {
            1 => ("camera", "is"),
            _ => ("cameras", "are"),
        };
        eprintln!(
            "note: {held_out} {cameras} marked \"test\" {are} fused too; --train-only keeps \
             them held out for `semsplat eval`"
        );
    }
    Ok(data)
}

fn fuse_config(args: &FuseArgs, method: Method, accumulation: Accumulation) -> FuseConfig {
    let defaults = FuseConfig::default();
    FuseConfig {
        method,
        accumulation,
        mem_budget: args.mem_budget,
        depth_tolerance: args.depth_tol.unwrap_or(defaults.depth_tolerance),
        behind_tolerance: args.behind_tol.unwrap_or(defaults.behind_tolerance),
        clustering: args.clustering,
        ..defaults
    }
}

/// A note for each option given that `method` does not read (the run goes on: the result
/// is what it would be without it).
fn note_options_without_effect(args: &FuseArgs, method: Method) {
    use Method::*;
    let unread = [
        (
            "--depth-tol",
            args.depth_tol.is_some() && !method.reads_depth_tolerance(),
        ),
        (
            "--behind-tol",
            args.behind_tol.is_some() && !method.is_consensus(),
        ),
        (
            "--clustering",
            args.clustering != Clustering::Order && !method.is_consensus(),
        ),
        (
            "--float-atomics",
            args.float_atomics && !method.reads_accumulation(),
        ),
        (
            "--mem-budget",
            args.mem_budget.is_some() && method == SegmentConsensus,
        ),
        // The consensus selects by its decided classes; only --save-membership reads it.
        (
            "--gamma",
            args.output.gamma.is_some()
                && method.is_consensus()
                && args.output.save_membership.is_none()
                && (args.output.extract.is_some() || args.output.remove.is_some()),
        ),
    ];
    for (option, _) in unread.iter().filter(|(_, unread)| *unread) {
        eprintln!("note: {option} has no effect with {}", method.name());
    }
}

/// Selecting from a fused scene's class reads no views: a note for each option of how
/// views are fused that was given (likely --labels was meant, and forgotten).
fn note_fusion_options_unread(args: &FuseArgs) {
    let given = [
        ("--method", args.method != MethodArg::Flashsplat),
        ("--occlusion", args.occlusion),
        ("--weighted", args.weighted),
        ("--per-view", args.per_view),
        ("--relabel", args.relabel),
        ("--clustering", args.clustering != Clustering::Order),
        ("--depth-tol", args.depth_tol.is_some()),
        ("--behind-tol", args.behind_tol.is_some()),
        ("--float-atomics", args.float_atomics),
        ("--train-only", args.train_only),
        ("--mem-budget", args.mem_budget.is_some()),
        ("--ignore-id", args.label_format.ignore_id.is_some()),
    ];
    let given: Vec<&str> = (given.iter())
        .filter_map(|&(option, given)| given.then_some(option))
        .collect();
    if !given.is_empty() {
        eprintln!(
            "note: {} {} no effect: without --labels (or --contrib) fuse selects by the fused \
             scene's `class`, fusing nothing; give --labels to fuse again",
            given.join(", "),
            if given.len() == 1 { "has" } else { "have" }
        );
    }
}

/// `--shard K/N`: the shard's partial evidence and its manifest (see `super::merge`).
fn fuse_shard(args: &FuseArgs, g: &Gaussians, method: Method, shard: Shard) -> Result<()> {
    let data = open_labeled_views(args)?;
    let job = ShardJob {
        scene_path: &args.scene,
        cameras_path: args.cameras.as_deref().context("--shard needs --cameras")?,
        gaussians: g,
        data: &data,
        cfg: fuse_config(args, method, Accumulation::FixedPoint),
        train_only: args.train_only,
        shard,
        out: &args.output.out,
    };
    super::merge::fuse_shard(&job)
}

/// Gives every Gaussian its winning class (user id, -1 unseen) and that class's share.
/// The fusion's classes and confidences replace whatever semantics the input scene held: a
/// trained scene's logits (which `render --semantics` would otherwise draw, through the new
/// class table) and an earlier consensus's entropies and segments.
fn assign_classes(g: &mut Gaussians, assignment: Assignment, table: &ClassTable) {
    let rows: Vec<u32> = table.classes.iter().map(|c| c.id).collect();
    g.semantics = None;
    g.class_entropy = None;
    g.segment_ids = None;
    g.class_ids = Some(user_classes(&rows, assignment.class.iter().copied()));
    g.class_conf = Some(assignment.confidence);
}

/// Refuses a fusion in which no Gaussian took a class: its output would say nothing, and
/// the cause is nearly always the inputs.
fn check_assigned(args: &OutputArgs, g: &Gaussians) -> Result<()> {
    let classes = g.class_ids.as_deref().unwrap_or(&[]);
    if classes.is_empty() || classes.iter().any(|&c| c >= 0) || selecting(args) {
        return Ok(());
    }
    bail!(
        "no Gaussian took a class (nothing written): the evidence holds none, or ties every \
         Gaussian's classes (with views: no view saw a Gaussian on a labeled pixel, or, for \
         vote --occlusion and segment consensus, the visibility test took none for seen \
         there: images of a few pixels, or depths far from the render's; see --depth-tol). \
         {FRAME_HINT}, and that the label maps hold classes (`semsplat inspect LABELS \
         --cameras CAMERAS`)"
    )
}

/// Writes the one-vs-rest membership matrix S as float32 0/1 [classes, Gaussians], a row
/// at a time (`totals`: [`class_totals`] of the rows).
fn save_membership(
    path: &Path,
    rows: &mut dyn EvidenceRows,
    totals: &[f64],
    gamma: f64,
) -> Result<()> {
    let shape = [rows.classes() as u64, rows.n() as u64];
    write_npy_rows::<f32, Vec<f32>>(path, &shape, |e| {
        let members = one_vs_rest_row(&rows.row(e)?, totals, gamma);
        Ok(members
            .into_iter()
            .map(|m| f32::from(u8::from(m)))
            .collect())
    })
}

/// What `--render-views` writes for each view.
const VIEW_FILES: [&str; 2] = [LABELS_PNG, PALETTE_PNG];

/// `--render-views`' cameras and device, opened before a fusion writes its first file (a
/// camera file that does not parse, or no device, must not leave the other outputs behind).
struct LabelViews {
    cams: Vec<Camera>,
    gpu: Gpu,
}

impl LabelViews {
    fn open(cameras: &Path, g: &Gaussians, dir: &Path) -> Result<LabelViews> {
        let cams = load_cameras(cameras)?;
        RenderedFiles::of(dir)?.check_overwrites("--render-views", None, &cams, &VIEW_FILES)?;
        let ids = g.class_ids.as_deref().expect("classes assigned");
        check_ids_fit_16_bit(ids.iter().map(|&id| i64::from(id)))?;
        Ok(LabelViews {
            cams,
            gpu: Gpu::new()?,
        })
    }

    /// Label and palette PNGs of every camera, rendered from the fused scene.
    fn render(self, dir: &Path, g: &Gaussians, table: &ClassTable) -> Result<()> {
        let ids = g.class_ids.as_deref().expect("classes assigned");
        let mut renderer = LabelRenderer::new(&self.gpu, g, ids)?;
        let mut rendered = RenderedFiles::of(dir)?;
        rendered.start_batched();
        let mut one_view = |cam: &Camera| -> Result<()> {
            interrupt::check()?;
            let labels: Vec<u16> = renderer
                .render(cam)?
                .into_iter()
                .map(|l| l.unwrap_or(LabelMap::IGNORE))
                .collect();
            let map = LabelMap::new(cam.width, cam.height, labels)?;
            let file = |suffix: &str| dir.join(format!("{}{suffix}", cam.name));
            write_label_png(&file(LABELS_PNG), &map)?;
            write_palette_png(&file(PALETTE_PNG), &map, table)?;
            rendered.add(cam, &VIEW_FILES)
        };
        // On an error the batch's files go, and the folders made for them.
        self.cams.iter().try_for_each(&mut one_view)?;
        rendered.write_batched()
    }
}

/// The Gaussians `--extract` keeps or `--remove` leaves (one-vs-rest with --gamma, `totals`:
/// [`class_totals`] of the rows); all of them without either.
fn select_members(
    args: &OutputArgs,
    selected_class: Option<u32>,
    g: Gaussians,
    rows: &mut Option<Box<dyn EvidenceRows>>,
    totals: &[f64],
    table: &ClassTable,
) -> Result<Gaussians> {
    let Some(id) = selected_class else {
        return Ok(g);
    };
    let row = table
        .classes
        .iter()
        .position(|c| c.id == id)
        .expect("class in table");
    let members = one_vs_rest_row(
        &kept(rows)?.row(row)?,
        totals,
        args.gamma.unwrap_or(DEFAULT_GAMMA),
    );
    let keep: Vec<bool> = members
        .iter()
        .map(|&m| m == args.extract.is_some())
        .collect();
    Ok(g.select(&keep))
}

/// --extract / --remove by each Gaussian's decided class.
fn select_by_class(args: &OutputArgs, selected_class: Option<u32>, g: Gaussians) -> Gaussians {
    let Some(id) = selected_class else {
        return g;
    };
    let classes = g.class_ids.as_deref().unwrap_or(&[]);
    let keep: Vec<bool> = (classes.iter())
        .map(|&c| (c == id as i32) == args.extract.is_some())
        .collect();
    g.select(&keep)
}

/// The output PLY with its class table, and the palette-colored copy if asked for.
fn write_outputs(args: &OutputArgs, selected: &Gaussians, table: &ClassTable) -> Result<()> {
    write_scene_with_table(&args.out, selected, table)?;
    if let Some(path) = &args.palette_ply {
        let colors: Vec<[f32; 3]> = selected
            .class_ids
            .as_ref()
            .expect("classes assigned")
            .iter()
            .map(|&c| {
                if c < 0 {
                    [0.0; 3]
                } else {
                    table.color_of(c as u32).map(|v| v as f32 / 255.0)
                }
            })
            .collect();
        write_ply(path, &selected.with_flat_colors(&colors))?;
    }
    Ok(())
}

/// The JSON report if asked for, the run's outputs landed (`batch`), and the summary line
/// (naming the class --extract or --remove chose, `selected`).
fn write_report(
    args: &OutputArgs,
    report: &Report,
    selected: Option<&ClassInfo>,
    batch: OutputBatch,
) -> Result<()> {
    if let Some(path) = &args.report {
        write_bytes_atomic(path, serde_json::to_string_pretty(report)?.as_bytes())?;
    }
    batch.commit()?;
    // Class -1: Gaussians no view decided (unobserved, or tied).
    let without_class = report
        .per_class
        .iter()
        .find(|c| c.id == -1)
        .map_or(0, |c| c.gaussians);
    let out = args.out.display();
    let seconds = report.total_s;
    let named = |c: &ClassInfo| format!("class '{}' (id {})", c.name, c.id);
    match (selected, args.extract.is_some()) {
        (Some(class), true) => eprintln!(
            "kept the {} Gaussians of {} in {seconds:.2} s -> {out}",
            report.gaussians,
            named(class)
        ),
        (Some(class), false) => eprintln!(
            "kept {} Gaussians, those of {} removed, in {seconds:.2} s -> {out}",
            report.gaussians,
            named(class)
        ),
        (None, _) => {
            // The classes that won a Gaussian, of those the labels gave.
            let held = (report.per_class.iter())
                .filter(|c| c.id >= 0 && c.gaussians > 0)
                .count();
            let of = match held == report.classes {
                true => String::new(),
                false => format!(" of the labels' {}", report.classes),
            };
            eprintln!(
                "fused {} Gaussians into {held}{of} class{} ({without_class} Gaussians left \
                 without a class) in {seconds:.2} s -> {out}",
                report.gaussians,
                if held == 1 && of.is_empty() { "" } else { "es" }
            )
        }
    }
    if let Some(segments) = &report.segments {
        note_unobserved(segments);
    }
    note_votes_unclassified(report.method, without_class, report.gaussians);
    // A flag is a finding the user acts on (an object the views disagree on, often one a
    // segmenter mislabels in most of them): say so even without --report.
    let flagged = report.segments.as_ref().map_or(0, |s| s.flagged.len());
    if flagged > 0 {
        let listed = match &args.report {
            Some(path) => format!("listed in {} (`segments.flagged`)", path.display()),
            None => "--report lists them".into(),
        };
        eprintln!(
            "{flagged} segment(s) flagged: their views disagree on their class; {listed}, \
             with the views that called each what"
        );
    }
    Ok(())
}

/// A vote classifies only the Gaussians whose centers the views show (--occlusion and
/// --weighted: visibly), which in a dense scene may leave many without a class: where it
/// left more than a twentieth, a note names the methods that classify those.
fn note_votes_unclassified(method: &str, without_class: usize, gaussians: usize) {
    if !method.starts_with("vote") || without_class * 20 <= gaussians {
        return;
    }
    let visible = if method == "vote" {
        ""
    } else {
        " and are visible there"
    };
    eprintln!(
        "note: {without_class} of the {gaussians} Gaussians ({:.0}%) have no class: {method} \
         classifies only Gaussians whose centers fall on labeled pixels{visible}; flashsplat \
         classifies every Gaussian a view renders, segment-consensus also hidden ones, from \
         their neighbours",
        100.0 * without_class as f64 / gaussians as f64
    );
}

/// Segment consensus classes the Gaussians no view observed from their neighbours, outward
/// from the observed ones: one line says how many, and where the views observed few of the
/// scene's Gaussians (a label map of one pixel, a depth tolerance too tight, cameras that
/// see little of the scene) a warning says the classes came from those few.
fn note_unobserved(segments: &SegmentReport) {
    let filled = segments.from_neighbours;
    if filled == 0 {
        return;
    }
    // Every Gaussian of the scene, however --extract or --remove selected from them.
    let observed =
        segments.from_segment + segments.from_neighbour_segments + segments.from_own_views;
    let gaussians = observed + segments.unobserved;
    match observed * 2 < gaussians {
        false => eprintln!(
            "{} of the scene's {gaussians} Gaussians no view observed: {filled} of them took \
             their neighbours' class (`segments.from_neighbours` of --report)",
            segments.unobserved
        ),
        true => eprintln!(
            "warning: the views observed only {observed} of the {gaussians} Gaussians' \
             centers; {filled} others took their classes from those, neighbour by neighbour. \
             Check that the label maps label the scene (semsplat inspect LABELS --cameras \
             CAMERAS), that the cameras see it, and --depth-tol"
        ),
    }
}

fn per_class_counts(g: &Gaussians, table: &ClassTable) -> Vec<ClassCount> {
    let ids = g.class_ids.as_deref().unwrap_or(&[]);
    let mut out: Vec<ClassCount> = table
        .classes
        .iter()
        .map(|c| ClassCount {
            id: c.id as i64,
            name: c.name.clone(),
            gaussians: ids.iter().filter(|&&i| i == c.id as i32).count(),
        })
        .collect();
    out.push(ClassCount {
        id: -1,
        name: "no class (unseen, or tied)".into(),
        gaussians: ids.iter().filter(|&&i| i == -1).count(),
    });
    out
}

#[cfg(test)]
mod tests {
    use clap::{Args, Command, ValueEnum};
    use semsplat::fuse::SPELLINGS;

    use super::{FuseArgs, MethodArg};

    /// `selected_method` reads the variant flags by field; they must be the table's flags,
    /// and `--method` must take exactly the table's bases.
    #[test]
    fn flags_and_bases_are_the_method_table_s() {
        let cmd = FuseArgs::augment_args(Command::new("fuse"));
        for s in SPELLINGS {
            if let Some(flag) = s.flag {
                assert!(cmd.get_arguments().any(|a| a.get_long() == Some(flag)));
            }
            assert!(MethodArg::value_variants().iter().any(|m| m
                .to_possible_value()
                .unwrap()
                .get_name()
                == s.base));
        }
    }
}
