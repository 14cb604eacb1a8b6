//! `semsplat inspect`: summarize a PLY scene, a camera model, a label folder or a class table,
//! and report problems (exit status 1 when any are found).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use serde_json::{json, Map, Value};

use semsplat::dataset::default_class_table;
use semsplat::fuse::partial::MANIFEST_FORMAT;
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::cameras_json::{read_cameras_json_kind, CameraJsonKind};
use semsplat::scene::classes::{read_class_table, ClassTable, IGNORE_U16};
use semsplat::scene::colmap::{find_colmap_model, ColmapFormat};
use semsplat::scene::labels::{
    binary_mask_warning, ignored_class_note, jpeg_note, label_size_fit, list_label_pngs,
    match_cameras, read_label_png_as, size_mismatch_reason, stray_255_warning, LabelFormat,
    LabelMap, SizeFit, StepTally, JPEG_LABELS, PNG_SIGNATURE,
};
use semsplat::scene::ply::{classes_sidecar_path, read_classes_sidecar};
use semsplat::scene::scene_file::{read_scene_unchecked, resolve_scene_path, scene_format};
use semsplat::scene::{Camera, Gaussians, Split};

const INSPECT_DETAILS: &str = "\
PATH can be:
  - a scene: a 3DGS PLY, SuperSplat's compressed PLY, a .splat or .spz file (or a folder
    holding one: an INRIA training output's latest iteration, a `synth` room's scene.ply): Gaussian count, SH degree, bounds, opacity (after sigmoid) and scale (after exp)
    ranges, semantic fields, per-class counts (named from <scene>.classes.json or --classes)
  - cameras: a COLMAP model folder (or a dataset folder with sparse/0), an INRIA cameras.json,
    a nerfstudio transforms.json or a semsplat camera JSON: count, resolutions, intrinsics ranges, splits
  - a folder of PNG label maps (or one label PNG; gray, palette, gray+alpha, or RGB coded with
    the class table's colours, see docs/label-maps.md): sizes, class pixel shares, ignore share
    (--ignore-id; default 255 in 8-bit maps, 65535 in 16-bit maps); --cameras and --classes add
    consistency checks. A folder holding one class and the ignore id only (binary masks whose
    object would vanish) is a problem
  - a class table JSON
A file whose extension names none of these is read by its first bytes (a PLY, a PNG).

Problems found (NaN/Inf values, zero quaternions, unreadable or mismatched label maps, class ids
missing from the class table, ...) are listed, and the exit status is then 1.
File formats and conventions: docs/CONVENTIONS.md.";

/// Arguments of `semsplat inspect` (the subcommand's one-line help lives in main.rs; the
/// details are in `after_help` so both `-h` and `--help` show them).
#[derive(Args)]
#[command(after_help = INSPECT_DETAILS)]
pub struct InspectArgs {
    /// The PLY file, camera model or JSON, label folder or PNG, or class table to inspect.
    pub path: PathBuf,

    /// Print the summary as JSON on stdout (problems are in its "problems" list).
    #[arg(long)]
    pub json: bool,

    /// Class table JSON used to name classes and to check that label ids are known.
    /// For a PLY, defaults to its <scene>.classes.json sidecar when present.
    #[arg(long, value_name = "FILE")]
    pub classes: Option<PathBuf>,

    /// Cameras to check a label folder against: every camera needs <name>.png of its size
    /// (or of the same aspect ratio: a resized copy).
    #[arg(long, value_name = "PATH")]
    pub cameras: Option<PathBuf>,

    #[command(flatten)]
    pub label_format: super::LabelFormatArgs,
}

/// What `inspect` found: ordered fields for printing, and the problems.
struct Report {
    kind: &'static str,
    path: PathBuf,
    fields: Vec<(&'static str, Value)>,
    problems: Vec<String>,
}

impl Report {
    fn new(kind: &'static str, path: &Path) -> Report {
        Report {
            kind,
            path: path.to_owned(),
            fields: Vec::new(),
            problems: Vec::new(),
        }
    }

    fn add(&mut self, key: &'static str, value: impl Into<Value>) {
        self.fields.push((key, value.into()));
    }

    fn to_json(&self) -> Value {
        let mut obj = Map::new();
        obj.insert("kind".into(), self.kind.into());
        obj.insert("path".into(), self.path.display().to_string().into());
        for (k, v) in &self.fields {
            obj.insert((*k).into(), v.clone());
        }
        obj.insert("problems".into(), self.problems.clone().into());
        Value::Object(obj)
    }

    fn text(&self) -> String {
        let mut out = format!("{} ({})\n", self.path.display(), self.kind);
        for (k, v) in &self.fields {
            value_text(&mut out, k, v, 1);
        }
        if self.problems.is_empty() {
            out.push_str("no problems found\n");
        } else {
            out.push_str(&format!("problems ({}):\n", self.problems.len()));
            for p in &self.problems {
                out.push_str(&format!("  - {p}\n"));
            }
        }
        out
    }
}

fn value_text(out: &mut String, key: &str, v: &Value, depth: usize) {
    let pad = "  ".repeat(depth);
    match v {
        Value::Object(map) if map.contains_key("min") && map.contains_key("max") => {
            let mut line = format!(
                "{pad}{key}: {} .. {}",
                compact_text(&map["min"]),
                compact_text(&map["max"])
            );
            if let Some(mean) = map.get("mean") {
                line.push_str(&format!(" (mean {})", compact_text(mean)));
            }
            out.push_str(&line);
            out.push('\n');
        }
        Value::Object(map) => {
            out.push_str(&format!("{pad}{key}:\n"));
            for (k, v) in map {
                value_text(out, k, v, depth + 1);
            }
        }
        Value::Array(items) if items.iter().any(|i| i.is_object()) => {
            out.push_str(&format!("{pad}{key}:\n"));
            for i in items {
                out.push_str(&format!("{pad}  {}\n", compact_text(i)));
            }
        }
        other => out.push_str(&format!("{pad}{key}: {}\n", compact_text(other))),
    }
}

/// One-line text of a value; objects list `id`, `name` and `size` first.
fn compact_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Number(n) => match n.as_f64() {
            Some(f) if n.is_f64() => {
                let s = format!("{:.6}", f + 0.0); // + 0.0 turns -0 into 0
                s.trim_end_matches('0').trim_end_matches('.').to_owned()
            }
            _ => n.to_string(),
        },
        Value::Object(map) => {
            let first = ["id", "name", "size"];
            let keys = first
                .iter()
                .copied()
                .filter(|k| map.contains_key(*k))
                .chain(
                    map.keys()
                        .map(String::as_str)
                        .filter(|k| !first.contains(k)),
                );
            let parts: Vec<String> = keys
                .map(|k| format!("{k}: {}", compact_text(&map[k])))
                .collect();
            parts.join(", ")
        }
        Value::Array(items) => {
            let parts: Vec<String> = items.iter().map(compact_text).collect();
            parts.join(", ")
        }
        other => other.to_string(),
    }
}

/// Prints to stdout; a closed pipe (`inspect ... | head`) is not an error.
fn print_stdout(text: &str) -> Result<()> {
    use std::io::Write;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

pub fn run(args: InspectArgs) -> Result<()> {
    let path = args.path.as_path();
    let table = args.classes.as_deref().map(read_class_table).transpose()?;
    let labels = LabelInputs {
        table: table.as_ref(),
        cameras: args.cameras.as_deref(),
        format: args.label_format.format(),
    };
    let inspected = match path.exists() {
        true => inspect_path(path, &labels),
        false => Err(anyhow!("{} does not exist", path.display())),
    };
    let report = match inspected {
        Ok(report) => report,
        // What --json's reader parses says so too: a file that could not be read.
        Err(e) if args.json => {
            let mut unreadable = Report::new("unreadable", path);
            unreadable.problems.push(format!("{e:#}"));
            print_stdout(&(serde_json::to_string_pretty(&unreadable.to_json())? + "\n"))?;
            return Err(e);
        }
        Err(e) => return Err(e),
    };
    if args.json {
        print_stdout(&(serde_json::to_string_pretty(&report.to_json())? + "\n"))?;
    } else {
        print_stdout(&report.text())?;
    }
    if !report.problems.is_empty() {
        bail!(
            "{} problem(s) found in {}",
            report.problems.len(),
            path.display()
        );
    }
    Ok(())
}

/// What the label checks use besides the maps.
struct LabelInputs<'a> {
    table: Option<&'a ClassTable>,
    cameras: Option<&'a Path>,
    format: LabelFormat,
}

/// A folder: a COLMAP model, a scene folder or INRIA run (its scene), or label maps.
fn inspect_folder(path: &Path, labels: &LabelInputs) -> Result<Report> {
    if find_colmap_model(path).is_ok() {
        return inspect_cameras(path);
    }
    // A scene folder (synth's) or an INRIA run holds label PNGs in subfolders too
    // (images, labels): its scene is what the folder is.
    if let Ok(scene) = resolve_scene_path(path) {
        return inspect_ply(&scene, labels.table);
    }
    let pngs = list_label_pngs(path)?;
    if pngs.is_empty() {
        let jpegs = jpeg_note(path).map_or(String::new(), |n| format!("; it holds {n}"));
        bail!(
            "{} is neither a COLMAP model (cameras/images .bin or .txt, or sparse/0) nor a \
             folder of PNG label maps{jpegs}",
            path.display()
        );
    }
    let files: Vec<(String, PathBuf)> = pngs.into_iter().collect();
    inspect_labels(path, "label folder", &files, labels)
}

/// A JSON file: cameras or a class table, or a message naming what it is instead.
fn inspect_json(path: &Path, format: &LabelFormat) -> Result<Report> {
    match json_kind(path)? {
        JsonKind::ClassTable => inspect_class_table(path, format),
        JsonKind::Cameras | JsonKind::Unparsable => inspect_cameras(path),
        JsonKind::ShardManifest => bail!(
            "{} is the manifest of a `fuse --shard` part (what the part was fused from), \
             which `semsplat merge` reads beside its part: {KINDS}",
            path.display()
        ),
        JsonKind::Other(keys) => bail!(
            "{} is JSON of no kind inspect reads (its top-level keys: {}): neither cameras \
             (an INRIA list, nerfstudio's \"frames\", semsplat's \"format\": \
             \"semsplat-cameras\") nor a class table (a list of {{\"id\", \"name\", \
             \"color\"}}, or {{\"classes\": [...]}}); semsplat's own summaries and reports \
             (synth.json, room.json, --report and --json outputs) are plain JSON to read \
             as they are",
            path.display(),
            semsplat::scene::labels::list_some(&keys)
        ),
        // A JSON of neither kind (a class list of another tool's layout) hears of both.
        JsonKind::Unknown => inspect_cameras(path).map_err(|e| {
            anyhow!(
                "{e:#}; nor is it a class table (a list of {{\"id\", \"name\", \"color\": \
                 [r, g, b]}}, or {{\"classes\": [...]}})"
            )
        }),
    }
}

fn inspect_path(path: &Path, labels: &LabelInputs) -> Result<Report> {
    let table = labels.table;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    if path.is_dir() {
        return inspect_folder(path, labels);
    }
    match ext.as_str() {
        "ply" | "splat" | "spz" => inspect_ply(path, table),
        "png" => {
            let stem = path
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or_default()
                .to_owned();
            inspect_labels(path, "label map", &[(stem, path.to_owned())], labels)
        }
        "json" => inspect_json(path, &labels.format),
        "txt" | "bin" => inspect_cameras(path),
        "jpg" | "jpeg" => bail!(
            "{} is a JPEG image, which inspect does not read ({JPEG_LABELS})",
            path.display()
        ),
        "npy" => bail!(
            "{} is a NumPy array (fuse's --save-contrib or --save-membership, or a --shard \
             part): {KINDS}",
            path.display()
        ),
        _ => {
            // Names the scene formats it knows of but does not read.
            scene_format(path)?;
            // A name that says nothing (`scene`, `map.label`): its first bytes may.
            match file_magic(path) {
                Some(Magic::Ply) => return inspect_ply(path, table),
                Some(Magic::Png) => {
                    let name = path.file_name().unwrap_or_default().to_string_lossy();
                    let files = [(name.into_owned(), path.to_owned())];
                    return inspect_labels(path, "label map", &files, labels);
                }
                None => {}
            }
            bail!(
                "cannot tell what {} is from its name or its first bytes: {KINDS}",
                path.display()
            )
        }
    }
}

/// The formats a file's first bytes name.
#[derive(Debug, PartialEq)]
enum Magic {
    Ply,
    Png,
}

/// What `path`'s first bytes say it is, if they say (None also where it cannot be read: the
/// error that follows names the file).
fn file_magic(path: &Path) -> Option<Magic> {
    use std::io::Read;
    let mut head = [0u8; 8];
    let mut file = std::fs::File::open(path).ok()?;
    let read = file.read(&mut head).ok()?;
    match &head[..read] {
        [b'p', b'l', b'y', b'\n' | b'\r', ..] => Some(Magic::Ply),
        head if head == PNG_SIGNATURE => Some(Magic::Png),
        _ => None,
    }
}

/// What `inspect` reads, for the errors of what it does not.
const KINDS: &str = "inspect reads scenes (.ply, .splat, .spz, or their folders), cameras (a \
                     COLMAP model, a cameras.json or transforms.json), label maps (.png or a \
                     folder of them) and class tables (.json)";

/// Which of inspect's JSON layouts `path` holds, told from its top level.
fn json_kind(path: &Path) -> Result<JsonKind> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let Ok(value) = serde_json::from_str::<Value>(&text) else {
        return Ok(JsonKind::Unparsable); // the camera reader gives the parse error
    };
    if value.get("format").and_then(Value::as_str) == Some(MANIFEST_FORMAT) {
        return Ok(JsonKind::ShardManifest);
    }
    // The keys each camera layout has at its top (semsplat's, nerfstudio's or INRIA's).
    let camera_keys = ["format", "cameras", "frames"];
    Ok(match &value {
        Value::Object(o) if camera_keys.iter().any(|k| o.contains_key(*k)) => JsonKind::Cameras,
        Value::Array(items) if items.first().is_some_and(|e| e.get("img_name").is_some()) => {
            JsonKind::Cameras
        }
        v if ClassTable::json_has_shape(v) => JsonKind::ClassTable,
        Value::Object(o) => JsonKind::Other(o.keys().cloned().collect()),
        _ => JsonKind::Unknown,
    })
}

/// What a `.json` file's top level says it holds.
enum JsonKind {
    ClassTable,
    Cameras,
    /// Neither layout: read as cameras, and the error names both.
    Unknown,
    /// An object of neither layout (a run's summary or report): its top-level keys.
    Other(Vec<String>),
    /// No JSON: read as cameras, whose reader says where it breaks.
    Unparsable,
    /// The manifest beside a `fuse --shard` part.
    ShardManifest,
}

// ---------------------------------------------------------------------------------------

fn sigmoid(x: f32) -> f64 {
    1.0 / (1.0 + (-(x as f64)).exp())
}

/// min/max/mean over the finite values.
fn range(values: impl Iterator<Item = f64>) -> Value {
    let (mut lo, mut hi, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0u64);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
        sum += v;
        n += 1;
    }
    if n == 0 {
        return Value::Null;
    }
    // The sum's rounding can put the mean of equal values an ulp outside them.
    let mean = (sum / n as f64).clamp(lo, hi);
    json!({"min": lo, "max": hi, "mean": mean})
}

fn inspect_ply(path: &Path, table: Option<&ClassTable>) -> Result<Report> {
    let g = read_scene_unchecked(path)?;
    let mut r = Report::new("3DGS scene", path);
    let sidecar = if table.is_none() {
        read_classes_sidecar(path)?
    } else {
        None
    };
    let table = table.or(sidecar.as_ref());
    r.add("gaussians", g.len());
    r.add("sh_degree", g.sh_degree);
    if !g.is_empty() {
        add_geometry(&mut r, &g);
    }
    r.add("semantic_fields", semantic_fields(&g));
    if let Some(ids) = &g.class_ids {
        add_class_counts(&mut r, &g, ids, table);
        if let Some(conf) = &g.class_conf {
            r.add("class_conf", range(conf.iter().map(|&c| c as f64)));
        }
        if let Some(entropy) = &g.class_entropy {
            r.add("class_entropy", range(entropy.iter().map(|&e| e as f64)));
        }
        if table.is_none() {
            let sidecar = classes_sidecar_path(path);
            r.add(
                "class_names",
                format!("no class table ({} not found)", sidecar.display()),
            );
        }
    }
    if let Some(segments) = &g.segment_ids {
        let distinct: std::collections::BTreeSet<i32> =
            segments.iter().copied().filter(|&s| s >= 0).collect();
        r.add("segments", distinct.len());
    }
    if let Some(inst) = &g.instance_ids {
        let distinct: std::collections::BTreeSet<i32> =
            inst.iter().copied().filter(|&i| i >= 0).collect();
        r.add("instances", distinct.len());
    }
    if g.is_empty() {
        r.problems
            .push("the scene holds no Gaussians (fuse, train and eval refuse it)".to_string());
    }
    if let Err(e) = g.check_layout() {
        r.problems.push(format!("{e:#}"));
    }
    r.problems
        .extend(g.value_problems().iter().map(|p| p.to_string()));
    r.problems.extend(huge_gaussians(&g));
    r.problems.extend(transparent_scene(&g));
    r.problems.extend(huge_colours(&g));
    Ok(r)
}

/// Below this opacity a Gaussian adds nothing to any pixel (the renderers' alpha cut).
const INVISIBLE_OPACITY: f64 = 1.0 / 255.0;

/// A scene none of whose Gaussians shows: every command renders nothing of it, and their
/// errors blame the cameras (nothing in view), where the opacities are the cause.
fn transparent_scene(g: &Gaussians) -> Option<String> {
    let invisible = |o: &f32| sigmoid(*o) < INVISIBLE_OPACITY;
    (!g.is_empty() && g.opacity_logits.iter().all(invisible)).then(|| {
        format!(
            "every Gaussian is transparent (opacity under 1/255; the largest opacity logit, \
             before the sigmoid, is {:.1}): nothing renders. Opacities saved after the \
             sigmoid, or logits of another convention?",
            g.opacity_logits
                .iter()
                .copied()
                .fold(f32::NEG_INFINITY, f32::max)
        )
    })
}

/// A colour coefficient no trained scene holds: a corrupt or diverged model, whose renders
/// overflow (training on it diverges at once).
const HUGE_COLOUR: f32 = 1e6;

/// Gaussians with a colour (SH) coefficient past [`HUGE_COLOUR`] in magnitude.
fn huge_colours(g: &Gaussians) -> Option<String> {
    let k3 = (g.sh_coeffs() * 3).max(1);
    let huge = |c: &[f32]| c.iter().any(|v| v.abs() > HUGE_COLOUR);
    let count = g.sh.chunks(k3).filter(|c| huge(c)).count();
    let first = g.sh.chunks(k3).position(huge)?;
    Some(format!(
        "{count} Gaussians have a colour (SH) coefficient larger than {HUGE_COLOUR:e} in \
         magnitude (first: index {first}): a corrupt or diverged model? Renders of them \
         overflow"
    ))
}

/// Gaussians larger than any scene ([`HUGE_SCALE_M`]): a corrupt or diverged model. Those
/// whose 2D covariance passes float32's range are culled by every command; the others
/// cover whole views.
fn huge_gaussians(g: &Gaussians) -> Option<String> {
    let largest = |s: &[f32; 3]| s.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let huge: Vec<f32> = (g.log_scales.iter())
        .map(largest)
        .filter(|&s| (s as f64).exp() > HUGE_SCALE_M)
        .collect();
    let max = huge.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let largest = match max.is_finite() {
        true => format!("e^{max:.1} m"),
        false => "of infinite scale".to_owned(),
    };
    (!huge.is_empty()).then(|| {
        format!(
            "{} Gaussian(s) larger than {HUGE_SCALE_M:e} m (the largest {largest}): a corrupt \
             or diverged model? Past float32's range a Gaussian is culled, below it it covers \
             whole views",
            huge.len()
        )
    })
}

/// A Gaussian scale no scene needs (a thousand kilometres).
const HUGE_SCALE_M: f64 = 1e6;

/// Bounds of the finite centers, opacity and scale ranges.
fn add_geometry(r: &mut Report, g: &Gaussians) {
    let mut bmin = [f32::INFINITY; 3];
    let mut bmax = [f32::NEG_INFINITY; 3];
    for m in g.means.iter().filter(|m| m.iter().all(|v| v.is_finite())) {
        for a in 0..3 {
            bmin[a] = bmin[a].min(m[a]);
            bmax[a] = bmax[a].max(m[a]);
        }
    }
    if bmin[0].is_finite() {
        r.add("bounds", json!({"min": bmin, "max": bmax}));
    }
    r.add(
        "opacity",
        range(g.opacity_logits.iter().map(|&o| sigmoid(o))),
    );
    r.add(
        "scale",
        range(g.log_scales.iter().flatten().map(|&s| (s as f64).exp())),
    );
}

/// The semantic properties the scene carries ("none" without any).
fn semantic_fields(g: &Gaussians) -> Vec<String> {
    let mut semantic = Vec::new();
    if g.class_ids.is_some() {
        semantic.push("class".to_owned());
    }
    if g.class_conf.is_some() {
        semantic.push("class_conf".to_owned());
    }
    if g.instance_ids.is_some() {
        semantic.push("instance".to_owned());
    }
    if g.class_entropy.is_some() {
        semantic.push("class_entropy".to_owned());
    }
    if g.segment_ids.is_some() {
        semantic.push("segment".to_owned());
    }
    if let Some(s) = &g.semantics {
        semantic.push(format!(
            "sem_0..sem_{} ({} channels)",
            s.channels - 1,
            s.channels
        ));
    }
    if semantic.is_empty() {
        vec!["none".to_owned()]
    } else {
        semantic
    }
}

fn add_class_counts(r: &mut Report, g: &Gaussians, ids: &[i32], table: Option<&ClassTable>) {
    let mut counts: BTreeMap<i32, u64> = BTreeMap::new();
    for &c in ids {
        *counts.entry(c).or_default() += 1;
    }
    let n = g.len().max(1) as f64;
    let rows: Vec<Value> = counts
        .iter()
        .map(|(&id, &count)| {
            // No name where the scene has no class table (the label rows do the same).
            let name = match (id, table) {
                (-1, _) => Some("(unseen)".to_owned()),
                (id, Some(t)) if id >= 0 => Some(
                    t.get(id as u32)
                        .map_or_else(|| "(not in table)".into(), |c| c.name.clone()),
                ),
                _ => None,
            };
            let mut row = json!({"id": id, "count": count, "share": count as f64 / n});
            if let Some(name) = name {
                row["name"] = name.into();
            }
            row
        })
        .collect();
    if let Some(t) = table {
        let unknown: Vec<String> = counts
            .keys()
            .filter(|&&id| id >= 0 && !t.contains(id as u32))
            .map(|id| id.to_string())
            .collect();
        if !unknown.is_empty() {
            r.problems.push(format!(
                "class ids not in the class table: {}",
                unknown.join(", ")
            ));
        }
    }
    r.add("classes", rows);
}

// ---------------------------------------------------------------------------------------

fn inspect_cameras(path: &Path) -> Result<Report> {
    let (kind, cams) = if path.is_dir() {
        let (_, format) = find_colmap_model(path)?;
        let kind = match format {
            ColmapFormat::Binary => "COLMAP model (binary)",
            ColmapFormat::Text => "COLMAP model (text)",
        };
        (kind, load_cameras(path)?)
    } else if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        let (kind, cams) = read_cameras_json_kind(path)?;
        let kind = match kind {
            CameraJsonKind::Inria => "INRIA cameras.json",
            CameraJsonKind::Semsplat => "semsplat camera JSON",
            CameraJsonKind::Nerfstudio => "nerfstudio transforms.json",
        };
        (kind, cams)
    } else {
        ("COLMAP model", load_cameras(path)?)
    };
    let mut r = Report::new(kind, path);
    summarize_cameras(&mut r, &cams);
    Ok(r)
}

fn summarize_cameras(r: &mut Report, cams: &[Camera]) {
    r.add("cameras", cams.len());
    let mut sizes: BTreeMap<(u32, u32), usize> = BTreeMap::new();
    for c in cams {
        *sizes.entry((c.width, c.height)).or_default() += 1;
    }
    let sizes: Vec<Value> = sizes
        .iter()
        .map(|(&(w, h), &n)| json!({"size": format!("{w}x{h}"), "cameras": n}))
        .collect();
    r.add("resolutions", sizes);
    r.add("fx", range(cams.iter().map(|c| c.fx)));
    r.add("fy", range(cams.iter().map(|c| c.fy)));
    r.add("cx", range(cams.iter().map(|c| c.cx)));
    r.add("cy", range(cams.iter().map(|c| c.cy)));
    let train = cams.iter().filter(|c| c.split == Split::Train).count();
    r.add(
        "splits",
        json!({"train": train, "test": cams.len() - train}),
    );
    let centers: Vec<[f64; 3]> = cams.iter().map(|c| c.center().to_array()).collect();
    let axis = |a: usize| range(centers.iter().map(|c| c[a]));
    r.add("centers", json!({"x": axis(0), "y": axis(1), "z": axis(2)}));
    let first: Vec<&str> = cams.iter().take(3).map(|c| c.name.as_str()).collect();
    r.add("first_names", first);
    r.problems.extend(camera_problems(cams));
}

/// Camera centers farther than this from the origin: no capture spans a thousand
/// kilometers; a pose in another unit or a corrupt one.
const FAR_CAMERA_M: f64 = 1e6;

/// Cameras whose values parse but cannot be a capture's: a principal point more than an
/// image's side outside the image (intrinsics of another resolution, or in another unit),
/// a center farther than [`FAR_CAMERA_M`].
fn camera_problems(cams: &[Camera]) -> Vec<String> {
    let off = |c: f64, side: u32| c < -(side as f64) || c > 2.0 * side as f64;
    let off_image: Vec<&Camera> = (cams.iter())
        .filter(|c| off(c.cx, c.width) || off(c.cy, c.height))
        .collect();
    let far: Vec<&Camera> = (cams.iter())
        .filter(|c| c.center().length() > FAR_CAMERA_M)
        .collect();
    let mut problems = Vec::new();
    if let Some(c) = off_image.first() {
        problems.push(format!(
            "{} camera(s) have their principal point more than an image side outside the \
             image (e.g. {}: cx {:.6e}, cy {:.6e} for {}x{}): intrinsics of another \
             resolution, or in another unit?",
            off_image.len(),
            c.name,
            c.cx,
            c.cy,
            c.width,
            c.height
        ));
    }
    if let Some(c) = far.first() {
        problems.push(format!(
            "{} camera(s) are farther than {FAR_CAMERA_M:e} m from the origin (e.g. {}, at \
             {:.3e} m): poses in another unit, or corrupt?",
            far.len(),
            c.name,
            c.center().length()
        ));
    }
    problems
}

// ---------------------------------------------------------------------------------------

fn inspect_labels(
    path: &Path,
    kind: &'static str,
    files: &[(String, PathBuf)],
    labels: &LabelInputs,
) -> Result<Report> {
    let table = labels.table;
    let mut r = Report::new(kind, path);
    let cams = labels.cameras.map(load_cameras).transpose()?;
    // Colour-coded maps decode through --classes, else the folder's classes.json.
    let folder = if path.is_dir() {
        path
    } else {
        path.parent().unwrap_or(path)
    };
    let default_table = match table {
        Some(_) => None,
        None => default_class_table(folder).and_then(|p| read_class_table(&p).ok()),
    };
    let colors = table.or(default_table.as_ref());
    // Each map's camera as `fuse` matches them (a map two cameras would share is a problem).
    let keyed: BTreeMap<String, PathBuf> = files.iter().cloned().collect();
    let names = || cams.iter().flatten().map(|c| c.name.as_str());
    let matched = match match_cameras(&keyed, names()) {
        Ok(matched) => matched,
        Err(e) => {
            r.problems.push(format!("{e:#}"));
            Vec::new()
        }
    };
    let camera_of: BTreeMap<&str, &Camera> = (matched.iter().zip(cams.iter().flatten()))
        .filter_map(|(key, cam)| Some(((*key)?, cam)))
        .collect();
    let tally = tally_label_maps(&mut r, files, &camera_of, colors, &labels.format);
    r.add("label_maps", tally.read);
    let sizes: Vec<Value> = tally
        .sizes
        .iter()
        .map(|(&(w, h), &n)| json!({"size": format!("{w}x{h}"), "maps": n}))
        .collect();
    r.add("sizes", sizes);
    // Ids checked against the table fuse reads (--classes, else the folder's classes.json).
    add_label_classes(&mut r, &tally.counts, colors);
    add_ignored_class_note(&mut r, colors, &labels.format);
    let present: Vec<u32> = (0..IGNORE_U16)
        .filter(|&id| tally.counts[id as usize] > 0)
        .collect();
    let ignored = tally.counts[LabelMap::IGNORE as usize];
    let value_warnings = [
        binary_mask_warning(path, &present, ignored, &labels.format),
        stray_255_warning(path, &present, &labels.format, colors),
    ];
    for w in value_warnings.into_iter().flatten() {
        r.problems
            .push(w.trim_start_matches("warning: ").to_owned());
    }
    if let Some(w) = tally.steps.warning("these maps") {
        r.problems
            .push(w.trim_start_matches("warning: ").to_owned());
    }
    if let (Some(cams), false) = (&cams, matched.is_empty()) {
        add_unmatched(&mut r, files, cams, &matched, &camera_of);
    }
    Ok(r)
}

/// The cameras without a label map (a problem) and the maps without a camera.
fn add_unmatched(
    r: &mut Report,
    files: &[(String, PathBuf)],
    cams: &[Camera],
    matched: &[Option<&str>],
    camera_of: &BTreeMap<&str, &Camera>,
) {
    let missing: Vec<&str> = (cams.iter().zip(matched))
        .filter(|(_, key)| key.is_none())
        .map(|(c, _)| c.name.as_str())
        .collect();
    if !missing.is_empty() {
        let shown: Vec<&str> = missing.iter().take(5).copied().collect();
        r.problems.push(format!(
            "{} of {} cameras have no label map: {}{}",
            missing.len(),
            cams.len(),
            shown.join(", "),
            if missing.len() > 5 { ", ..." } else { "" }
        ));
    }
    let unmatched: Vec<String> = (files.iter().map(|(key, _)| key.clone()))
        .filter(|key| !camera_of.contains_key(key.as_str()))
        .collect();
    if !unmatched.is_empty() {
        r.add("maps_without_camera", unmatched);
    }
}

/// What the label maps of a folder hold, summed over the maps.
struct LabelTally {
    /// Pixels per 16-bit label value (the last one: ignored pixels).
    counts: Vec<u64>,
    /// Maps per size.
    sizes: BTreeMap<(u32, u32), usize>,
    /// Maps read.
    read: usize,
    /// Ids that look made by interpolation, over every map.
    steps: StepTally,
}

/// Reads every map, noting unreadable maps and size mismatches with their camera as
/// problems.
fn tally_label_maps(
    r: &mut Report,
    files: &[(String, PathBuf)],
    camera_of: &BTreeMap<&str, &Camera>,
    colors: Option<&ClassTable>,
    format: &LabelFormat,
) -> LabelTally {
    let mut tally = LabelTally {
        counts: vec![0u64; IGNORE_U16 as usize + 1],
        sizes: BTreeMap::new(),
        read: 0,
        steps: StepTally::default(),
    };
    for (stem, file) in files {
        let map = match read_label_png_as(file, format, colors) {
            Ok(m) => m,
            Err(e) => {
                r.problems.push(format!("{e:#}"));
                continue;
            }
        };
        tally.read += 1;
        *tally.sizes.entry((map.width, map.height)).or_default() += 1;
        map.count_into(&mut tally.counts);
        tally.steps.add(&map);
        if let Some(c) = camera_of.get(stem.as_str()) {
            if label_size_fit((c.width, c.height), (map.width, map.height)) == SizeFit::Mismatch {
                r.problems.push(format!(
                    "label map {} is {}x{} but camera '{}' is {}x{} ({})",
                    file.display(),
                    map.width,
                    map.height,
                    c.name,
                    c.width,
                    c.height,
                    size_mismatch_reason((c.width, c.height), (map.width, map.height))
                ))
            }
        }
    }
    tally
}

/// Pixel totals, the ignored share and a row per label id present (named from `table`).
fn add_label_classes(r: &mut Report, counts: &[u64], table: Option<&ClassTable>) {
    let total: u64 = counts.iter().sum();
    let ignore = counts[LabelMap::IGNORE as usize];
    let share = |n: u64| {
        if total == 0 {
            0.0
        } else {
            n as f64 / total as f64
        }
    };
    r.add("pixels", total);
    r.add("ignore_share", share(ignore));
    let mut unknown = Vec::new();
    let rows: Vec<Value> = (0..IGNORE_U16)
        .filter(|&id| counts[id as usize] > 0)
        .map(|id| {
            let name = table.map(|t| match t.get(id) {
                Some(c) => c.name.clone(),
                None => {
                    unknown.push(id.to_string());
                    "(not in table)".to_owned()
                }
            });
            let mut row = json!({"id": id, "pixels": counts[id as usize], "share": share(counts[id as usize])});
            if let Some(name) = name {
                row["name"] = name.into();
            }
            row
        })
        .collect();
    if total > 0 && rows.is_empty() {
        r.problems.push(
            "every pixel is the ignore value: the maps hold no class (fuse, train and eval \
             refuse them; see --ignore-id)"
                .into(),
        );
    }
    r.add("classes_present", rows.len());
    r.add("classes", rows);
    if !unknown.is_empty() {
        r.problems.push(format!(
            "label ids not in the class table: {}",
            unknown.join(", ")
        ));
    }
}

// ---------------------------------------------------------------------------------------

fn inspect_class_table(path: &Path, format: &LabelFormat) -> Result<Report> {
    let table = read_class_table(path)?;
    let mut r = Report::new("class table", path);
    r.add("classes", table.len());
    let rows: Vec<Value> = table
        .classes
        .iter()
        .map(|c| json!({"id": c.id, "name": c.name, "color": c.color}))
        .collect();
    r.add("entries", rows);
    add_ignored_class_note(&mut r, Some(&table), format);
    if table.is_empty() {
        r.problems.push("the table lists no class".to_string());
    }
    if let Some((a, b, color)) = table.shared_colour() {
        r.problems.push(format!(
            "classes {a} and {b} share the colour {color:?}: colour-coded label maps cannot be \
             read through this table (fuse, train and eval refuse them), and palette previews \
             draw both alike"
        ));
    }
    if let Some((a, b)) = table.names_alike_but_case() {
        r.problems.push(format!(
            "classes {} '{}' and {} '{}' differ only in case: a name given in another case \
             (--extract, --remove) matches both and is refused; give the exact name or the id",
            a.id, a.name, b.id, b.name
        ));
    }
    Ok(r)
}

/// The note `fuse`, `train` and `eval` print when the class table lists 8-bit maps' default
/// "no label" (255) as a class.
fn add_ignored_class_note(r: &mut Report, table: Option<&ClassTable>, format: &LabelFormat) {
    if let Some(note) = table.and_then(|t| ignored_class_note(format, t)) {
        r.add("note", note.trim_start_matches("note: "));
    }
}

#[cfg(test)]
mod tests {
    /// Ten values of 0.1 sum to 0.9999999999999999: their mean is still their value, not an
    /// ulp below the minimum.
    #[test]
    fn the_mean_of_equal_values_is_their_value() {
        assert!([0.1f64; 10].iter().sum::<f64>() / 10.0 < 0.1);
        let r = super::range(std::iter::repeat_n(0.1, 10));
        assert_eq!(r["mean"].as_f64(), Some(0.1));
        assert_eq!(r["min"].as_f64(), Some(0.1));
    }
}
