//! Label folders matched to cameras: by the image's relative path (mirrored subfolders, so
//! rig cameras `cam0/00001` and `cam1/00001` do not collide), falling back to the file stem
//! when it is unique; label maps at another resolution than their cameras (images_2/4/8,
//! INRIA `-r`) scale the intrinsics when the aspect ratio matches.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};

use super::decode::{read_label_png_as, read_png_header, LabelFormat, JPEG_LABELS};
use super::LabelMap;
use crate::scene::camera::Camera;
use crate::scene::classes::{ClassTable, IGNORE_U16};

/// How many missing names or bad ids an error message lists before "...".
const LIST_IN_ERRORS: usize = 5;

/// How deep [`list_label_pngs`] looks into subfolders (rigs mirror one or two levels; the
/// bound keeps a symlink loop from running away).
const MAX_FOLDER_DEPTH: usize = 8;

/// The `.png` files of a folder and its subfolders, keyed by relative path without the
/// extension (`cam0/00001`, `/`-separated), sorted. Hidden entries and other files are
/// skipped; two files with the same key (e.g. `a.png`, `a.PNG`) are an error.
pub fn list_label_pngs(dir: &Path) -> Result<BTreeMap<String, PathBuf>> {
    let mut found = BTreeMap::new();
    collect_pngs(dir, "", 0, &mut found)?;
    Ok(found)
}

/// Where `dir` (not its subfolders) holds JPEG files, how many and what to do: label maps
/// must be PNG ([`JPEG_LABELS`]).
pub fn jpeg_note(dir: &Path) -> Option<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|name| {
            let ext = name.rsplit_once('.').map_or("", |(_, ext)| ext);
            ext.eq_ignore_ascii_case("jpg") || ext.eq_ignore_ascii_case("jpeg")
        })
        .collect();
    names.sort();
    (!names.is_empty()).then(|| {
        format!(
            "{} JPEG files ({}): {JPEG_LABELS}",
            names.len(),
            list_some(&names)
        )
    })
}

fn collect_pngs(
    dir: &Path,
    prefix: &str,
    depth: usize,
    found: &mut BTreeMap<String, PathBuf>,
) -> Result<()> {
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("reading label folder {}", dir.display()))?;
    for entry in entries {
        let path = entry
            .with_context(|| format!("reading label folder {}", dir.display()))?
            .path();
        let Some(name) = path.file_name().and_then(|s| s.to_str()) else {
            continue;
        };
        if name.starts_with('.') {
            continue;
        }
        if path.is_dir() {
            if depth < MAX_FOLDER_DEPTH {
                collect_pngs(&path, &format!("{prefix}{name}/"), depth + 1, found)?;
            }
            continue;
        }
        let is_png = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"));
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()) else {
            continue;
        };
        if !is_png || !path.is_file() {
            continue;
        }
        let key = format!("{prefix}{stem}");
        if let Some(prev) = found.insert(key.clone(), path.clone()) {
            bail!(
                "label folder {} has two maps for '{key}': {} and {}",
                dir.display(),
                prev.display(),
                path.display()
            );
        }
    }
    Ok(())
}

/// The last component of a `/`-separated key.
fn stem_of(key: &str) -> &str {
    key.rsplit('/').next().unwrap_or(key)
}

/// Each camera's label map, as its key in `files` ([`list_label_pngs`]), by
/// [`match_camera`]; None where it has none. A map that would serve two cameras is an error:
/// a flat folder's `00000.png` matches rig cameras `cam0/00000` and `cam1/00000` by its
/// stem, and one camera's labels would be fused as the other's.
pub fn match_cameras<'a, 'n>(
    files: &'a BTreeMap<String, PathBuf>,
    names: impl Iterator<Item = &'n str>,
) -> Result<Vec<Option<&'a str>>> {
    let mut by_stem: HashMap<&str, Vec<&str>> = HashMap::new();
    for key in files.keys() {
        by_stem.entry(stem_of(key)).or_default().push(key);
    }
    let mut served: HashMap<&str, &str> = HashMap::new();
    let mut matched = Vec::new();
    for name in names {
        let key = match_camera(files, &by_stem, name)?;
        if let Some(key) = key {
            if let Some(other) = served.insert(key, name) {
                bail!(
                    "label map {key}.png matches two cameras by its stem, '{other}' and \
                     '{name}': mirror the images' subfolders in the label folder ({other}.png, \
                     {name}.png) so each camera has its own map"
                );
            }
        }
        matched.push(key);
    }
    Ok(matched)
}

/// The label file of a camera, as its key: the key equal to its name (a relative image path
/// without extension, or a bare stem), else the one file with its stem; two such files are
/// an error.
fn match_camera<'a>(
    files: &'a BTreeMap<String, PathBuf>,
    by_stem: &HashMap<&str, Vec<&'a str>>,
    name: &str,
) -> Result<Option<&'a str>> {
    let same_stem = by_stem.get(stem_of(name)).map(Vec::as_slice);
    if let Some((key, _)) = files.get_key_value(name) {
        // A camera named by a bare stem (its rig's stems are unique) whose image lies in
        // a subfolder: a map there is as much its own as one at the top.
        let bare = !name.contains('/');
        match same_stem {
            Some(many) if bare && many.len() > 1 => {
                let names: Vec<String> = many.iter().map(|k| format!("{k}.png")).collect();
                bail!(
                    "camera '{name}' matches several label maps: {}; keep the one that mirrors \
                     the image's path (cam0/00001.png for images/cam0/00001.jpg) and remove \
                     the others",
                    list_some(&names)
                )
            }
            _ => return Ok(Some(key)),
        }
    }
    match same_stem {
        Some([one]) => Ok(Some(one)),
        Some(many) if many.len() > 1 => {
            let names: Vec<String> = many.iter().map(|k| format!("{k}.png")).collect();
            bail!(
                "camera '{name}' matches several label maps by its stem: {}; mirror the image's \
                 subfolders in the label folder (cam0/00001.png for images/cam0/00001.jpg) so \
                 the relative path decides",
                list_some(&names)
            )
        }
        _ => Ok(None),
    }
}

/// How a label map's size relates to its camera's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SizeFit {
    Same,
    /// Another resolution with the same aspect ratio (within a pixel of rounding).
    Scaled,
    Mismatch,
}

/// Compares a label size with a camera size (both `(width, height)`).
pub fn label_size_fit(camera: (u32, u32), label: (u32, u32)) -> SizeFit {
    if camera == label {
        return SizeFit::Same;
    }
    if size_mismatch(camera, label).is_some() {
        return SizeFit::Mismatch;
    }
    let (cw, ch) = (camera.0 as f64, camera.1 as f64);
    let (lw, lh) = (label.0 as f64, label.1 as f64);
    // Downscaled copies round each side on its own (3DGS: round(W / r)), so each side may
    // be off by up to a pixel from the other side's exact ratio.
    if (lh - ch * lw / cw).abs() <= 1.0 && (lw - cw * lh / ch).abs() <= 1.0 {
        SizeFit::Scaled
    } else {
        SizeFit::Mismatch
    }
}

/// Label maps smaller than this share of their camera's side are not a scaled copy (a map
/// of 1x1 or 3x2 for a 160x120 camera passed as one): the dataset downscales in use stop
/// at 8 (3DGS's images_8).
const SMALLEST_SCALE: u64 = 32;

/// Why a label map of another size than its camera's is not a scaled copy of its view, in
/// words for an error (None: it may be one, if the aspect ratio matches).
fn size_mismatch(camera: (u32, u32), label: (u32, u32)) -> Option<&'static str> {
    // No pipeline resizes by a factor that moves each side by at most a pixel: that is an
    // off-by-one crop or pad, and scaling the camera for it would hide the mistake.
    if camera.0.abs_diff(label.0) <= 1 && camera.1.abs_diff(label.1) <= 1 {
        return Some("a pixel off on a side is a crop or pad, not a scaled copy");
    }
    let too_small = |l: u32, c: u32| u64::from(l) * SMALLEST_SCALE < u64::from(c);
    if too_small(label.0, camera.0) || too_small(label.1, camera.1) {
        return Some("under a 32nd of the camera's side, too small to be a scaled copy");
    }
    None
}

/// Why the label map of size `label` does not fit its camera's `camera`, and the remedy,
/// for an error.
pub fn size_mismatch_reason(camera: (u32, u32), label: (u32, u32)) -> String {
    let why = size_mismatch(camera, label)
        .unwrap_or("the aspect ratios differ, so it is not a scaled copy");
    format!(
        "{why}: give each view a map of its camera's size (resized with nearest neighbour, \
         never interpolated), or cameras of the maps' size"
    )
}

/// What to do with a camera that has no label map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MissingLabels {
    /// Fail, listing the first few missing names (the default: a silently skipped view is
    /// usually a naming mistake).
    #[default]
    Error,
    /// Leave those cameras out; [`LabelDir::skipped`] lists them.
    Skip,
}

struct LabelEntry {
    camera: usize,
    path: PathBuf,
    /// The camera's size as loaded.
    camera_size: (u32, u32),
    /// The size the map must have: the camera's, or the map's own when it is a scaled copy
    /// (then [`LabelDir::fit_cameras`] scales the camera to it).
    size: (u32, u32),
}

/// A label folder matched to cameras. Maps are read one at a time by [`LabelDir::iter`] or
/// [`LabelDir::load`], so fusion can stream views without holding every map in memory.
pub struct LabelDir {
    dir: PathBuf,
    entries: Vec<LabelEntry>,
    skipped: Vec<String>,
    format: LabelFormat,
    /// The class table: colours of colour-coded maps, and `allowed` ids.
    table: Option<ClassTable>,
    /// `allowed[id]`: the id is in the class table (None: no table).
    allowed: Option<Vec<bool>>,
    notes: Vec<String>,
}

impl LabelDir {
    /// [`LabelDir::open_as`] with the default [`LabelFormat`].
    pub fn open(
        dir: &Path,
        cameras: &[Camera],
        table: Option<&ClassTable>,
        missing: MissingLabels,
    ) -> Result<LabelDir> {
        Self::open_as(dir, cameras, &[], table, &LabelFormat::default(), missing)
    }

    /// Matches the label folder to every camera (see the module doc) and reads each matched
    /// map's PNG header for its size. With a class table, every loaded map is checked to use
    /// only the table's ids (and ignore), and colour-coded maps are read through its colours.
    /// `held_out`: the names of cameras left out (`--train-only`'s test cameras), whose maps
    /// are not said to match no camera.
    pub fn open_as(
        dir: &Path,
        cameras: &[Camera],
        held_out: &[String],
        table: Option<&ClassTable>,
        format: &LabelFormat,
        missing: MissingLabels,
    ) -> Result<LabelDir> {
        check_ignore_id(format, table)?;
        let files = list_label_pngs(dir)?;
        let matched = match_cameras(&files, cameras.iter().map(|c| c.name.as_str()))
            .with_context(|| format!("label folder {}", dir.display()))?;
        let mut entries = Vec::with_capacity(cameras.len());
        let mut skipped = Vec::new();
        for (i, (cam, key)) in cameras.iter().zip(&matched).enumerate() {
            match key {
                Some(key) => entries.push(entry_for(i, cam, &files[*key])),
                None => skipped.push(cam.name.clone()),
            }
        }
        // Cameras without a map beside maps without a camera: likely a naming mistake.
        let unread_note = (!skipped.is_empty())
            .then(|| unread_maps_note(dir, &files, &matched, held_out, &skipped))
            .flatten();
        if (missing == MissingLabels::Error && !skipped.is_empty()) || entries.is_empty() {
            bail!(
                "label folder {} has no label map for {} of {} cameras: {} (expected <image name>.png, \
                 in the image's subfolder when it has one, e.g. {}); it holds {}",
                dir.display(),
                skipped.len(),
                cameras.len(),
                list_some(&skipped),
                expected_names(&skipped),
                found_names(&files, dir)
            );
        }
        let allowed = table.map(allowed_ids);
        // 16-bit maps count class 255: the note is for folders holding 8-bit maps.
        let ignored = table
            .and_then(|t| ignored_class_note(format, t))
            .filter(|_| entries.iter().any(|e| holds_8_bit_ids(&e.path)));
        let notes = (scaled_note(&entries, cameras).into_iter())
            .chain(ignored)
            .chain(unread_note)
            .collect();
        Ok(LabelDir {
            dir: dir.to_owned(),
            entries,
            skipped,
            format: *format,
            table: table.cloned(),
            allowed,
            notes,
        })
    }

    /// Keeps the class table for colour-coded maps but accepts ids outside it (true maps
    /// scored against a scene whose table lists only the classes it predicts).
    pub fn without_id_check(mut self) -> LabelDir {
        self.allowed = None;
        self
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn format(&self) -> &LabelFormat {
        &self.format
    }

    /// Number of cameras with a label map.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Names of cameras without a label map (only with [`MissingLabels::Skip`]).
    pub fn skipped(&self) -> &[String] {
        &self.skipped
    }

    /// What the user should hear once (e.g. that intrinsics were scaled to the label size).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The camera index of the `i`-th map.
    pub fn camera_index(&self, i: usize) -> Option<usize> {
        self.entries.get(i).map(|e| e.camera)
    }

    /// The size (width, height) of the `i`-th map, from its header.
    pub fn size(&self, i: usize) -> Option<(u32, u32)> {
        self.entries.get(i).map(|e| e.size)
    }

    /// The file of the `i`-th map.
    pub fn path(&self, i: usize) -> Option<&Path> {
        self.entries.get(i).map(|e| e.path.as_path())
    }

    /// Scales the intrinsics of the cameras whose label maps are a resized copy (same aspect
    /// ratio) to the label size, so renders line up with the maps pixel for pixel. `cameras`
    /// must be the slice the folder was opened with.
    pub fn fit_cameras(&self, cameras: &mut [Camera]) {
        for e in &self.entries {
            if e.size != e.camera_size {
                if let Some(cam) = cameras.get_mut(e.camera) {
                    *cam = cam.scaled_to(e.size.0, e.size.1);
                }
            }
        }
    }

    /// Reads and checks the `i`-th map: its size (from the PNG header, before decoding) must
    /// match its camera, and its ids must be in the class table (when one was given).
    pub fn load(&self, i: usize) -> Result<LabelMap> {
        let e = self
            .entries
            .get(i)
            .ok_or_else(|| anyhow!("label map index {i} out of range"))?;
        let header =
            read_png_header(&e.path).with_context(|| format!("label map {}", e.path.display()))?;
        if (header.width, header.height) != e.size {
            bail!(
                "label map {} is {}x{} but its camera is {}x{} ({})",
                e.path.display(),
                header.width,
                header.height,
                e.camera_size.0,
                e.camera_size.1,
                size_mismatch_reason(e.camera_size, (header.width, header.height))
            );
        }
        let map = read_label_png_as(&e.path, &self.format, self.table.as_ref())?;
        if let Some(allowed) = &self.allowed {
            check_ids_in_table(&map, allowed)
                .with_context(|| format!("label map {}", e.path.display()))?;
        }
        Ok(map)
    }

    /// Streams `(camera index, map)` pairs in camera order.
    pub fn iter(&self) -> impl Iterator<Item = Result<(usize, LabelMap)>> + '_ {
        (0..self.entries.len()).map(move |i| Ok((self.entries[i].camera, self.load(i)?)))
    }
}

/// An explicit ignore id that is also a class of the table would hide that class.
fn check_ignore_id(format: &LabelFormat, table: Option<&ClassTable>) -> Result<()> {
    if let (Some(id), Some(table)) = (format.ignore_id, table) {
        if let Some(c) = table.get(id as u32) {
            bail!(
                "--ignore-id {id} is class '{}' in the class table: its pixels would never count; \
                 pick an id no class uses",
                c.name
            );
        }
    }
    Ok(())
}

/// Whether the map at `path` holds 8-bit ids (its header says; an unreadable one is
/// reported where the map is read).
fn holds_8_bit_ids(path: &Path) -> bool {
    read_png_header(path).is_ok_and(|h| h.bit_depth <= 8)
}

/// A class of the table at 8-bit maps' default "no label", 255: tables that list it as
/// "void" mean exactly that, but a real class there would silently never count, so the
/// user hears which it is taken for, and how to count it.
pub fn ignored_class_note(format: &LabelFormat, table: &ClassTable) -> Option<String> {
    let ignore = u32::from(format.ignore_for_depth(8));
    let class = table.get(ignore).filter(|_| format.ignore_id.is_none())?;
    Some(format!(
        "note: class {ignore} '{}' of the class table is 8-bit label maps' default \
         \"no label\": in 8-bit maps its pixels are ignored; to count them as a class, pass \
         --ignore-id with an id no class uses",
        class.name
    ))
}

/// A matched entry; the size it must have comes from the PNG header when the map is a
/// scaled copy. An unreadable header is reported by [`LabelDir::load`], with the file.
fn entry_for(camera: usize, cam: &Camera, path: &Path) -> LabelEntry {
    let camera_size = (cam.width, cam.height);
    let size = match read_png_header(path) {
        Ok(h) if label_size_fit(camera_size, (h.width, h.height)) == SizeFit::Scaled => {
            (h.width, h.height)
        }
        _ => camera_size,
    };
    LabelEntry {
        camera,
        path: path.to_owned(),
        camera_size,
        size,
    }
}

impl LabelDir {
    /// The cameras (of `cameras`, those the folder was opened with) scaled to their maps'
    /// size, by name, with the size their cameras file gives (for
    /// [`crate::scene::images::ImageDir::with_scaled_cameras`]).
    pub fn scaled_cameras(&self, cameras: &[Camera]) -> HashMap<String, (u32, u32)> {
        let scaled = self.entries.iter().filter(|e| e.size != e.camera_size);
        scaled
            .map(|e| (cameras[e.camera].name.clone(), e.camera_size))
            .collect()
    }
}

/// One line saying how many cameras were scaled to their label size, with an example.
fn scaled_note(entries: &[LabelEntry], cameras: &[Camera]) -> Option<String> {
    let scaled: Vec<&LabelEntry> = entries.iter().filter(|e| e.size != e.camera_size).collect();
    let first = scaled.first()?;
    Some(format!(
        "note: {} of {} label maps are at another resolution than their cameras (e.g. '{}': \
         label {}x{}, camera {}x{}); the intrinsics of those cameras are scaled to the label size",
        scaled.len(),
        entries.len(),
        cameras[first.camera].name,
        first.size.0,
        first.size.1,
        first.camera_size.0,
        first.camera_size.1
    ))
}

fn allowed_ids(table: &ClassTable) -> Vec<bool> {
    let mut allowed = vec![false; IGNORE_U16 as usize + 1];
    for c in &table.classes {
        if let Some(slot) = allowed.get_mut(c.id as usize) {
            *slot = true;
        }
    }
    allowed[LabelMap::IGNORE as usize] = true;
    allowed
}

fn expected_names(missing: &[String]) -> String {
    let names: Vec<String> = missing.iter().map(|n| format!("{n}.png")).collect();
    list_some(&names[..names.len().min(3)])
}

fn found_names(files: &BTreeMap<String, PathBuf>, dir: &Path) -> String {
    if files.is_empty() {
        return match jpeg_note(dir) {
            Some(jpegs) => format!("no PNG files but {jpegs}"),
            None => "no PNG files".to_owned(),
        };
    }
    let names: Vec<String> = files.keys().map(|k| format!("{k}.png")).collect();
    format!("{} PNG files: {}", names.len(), list_some(&names))
}

fn check_ids_in_table(map: &LabelMap, allowed: &[bool]) -> Result<()> {
    let mut bad: HashMap<u16, u64> = HashMap::new();
    for &l in &map.labels {
        if !allowed[l as usize] {
            *bad.entry(l).or_default() += 1;
        }
    }
    if bad.is_empty() {
        return Ok(());
    }
    let mut ids: Vec<u16> = bad.keys().copied().collect();
    ids.sort_unstable();
    let pixels: u64 = bad.values().sum();
    let names: Vec<String> = ids.iter().map(|id| id.to_string()).collect();
    bail!(
        "{pixels} pixels use class ids that are not in the class table: {}",
        list_some(&names)
    )
}

/// The label maps of `files` no camera matched, where some cameras have none: a naming
/// mistake, said with the names the cameras expect.
fn unread_maps_note(
    dir: &Path,
    files: &BTreeMap<String, PathBuf>,
    matched: &[Option<&str>],
    held_out: &[String],
    skipped: &[String],
) -> Option<String> {
    let held_out = match_cameras(files, held_out.iter().map(String::as_str)).ok()?;
    let read: HashSet<&str> = matched.iter().chain(&held_out).flatten().copied().collect();
    let unread: Vec<String> = (files.keys())
        .filter(|key| !read.contains(key.as_str()))
        .cloned()
        .collect();
    (!unread.is_empty()).then(|| {
        format!(
            "note: {} label map(s) in {} match no camera and are not read: {} (a camera's \
             map is <image name>.png, e.g. {})",
            unread.len(),
            dir.display(),
            list_some(&unread),
            expected_names(skipped)
        )
    })
}

/// "a, b, c, d, e and 3 more".
pub fn list_some(names: &[String]) -> String {
    let shown: Vec<&str> = names
        .iter()
        .take(LIST_IN_ERRORS)
        .map(String::as_str)
        .collect();
    let mut s = shown.join(", ");
    if names.len() > LIST_IN_ERRORS {
        s.push_str(&format!(" and {} more", names.len() - LIST_IN_ERRORS));
    }
    s
}

/// The loud warning for a label folder that holds one class and the ignore id only: most
/// often binary masks (SAM-style 0/255) whose object is the ignored value and would vanish.
/// `class_ids` are the ids present (ignore excluded), `ignored_pixels` the ignored count.
pub fn binary_mask_warning(
    dir: &Path,
    class_ids: &[u32],
    ignored_pixels: u64,
    format: &LabelFormat,
) -> Option<String> {
    let [only] = class_ids else { return None };
    if ignored_pixels == 0 {
        return None;
    }
    if holds_alpha(dir) {
        // Transparent pixels are unlabeled whatever --ignore-id says: suggesting one loops.
        return Some(format!(
            "warning: label folder {} holds only two values: class {only} and unlabeled \
             pixels, and its maps have an alpha channel: transparent pixels (alpha 0) carry no \
             label whatever --ignore-id says. If these are masks on a transparent background \
             (SAM exports), the background is dropped: save them without alpha, or with an \
             opaque background, to count it as a class",
            dir.display()
        ));
    }
    // Neither of the two values: not the class, not the ignore id in effect.
    let ignoring = format.ignore_id.map(u32::from);
    let suggested = [1000, 65534, 1001]
        .into_iter()
        .find(|&v| v != *only && Some(v) != ignoring)
        .expect("three candidates, two excluded at most");
    Some(format!(
        "warning: label folder {} holds only two values: class {only} and the ignore id ({}), \
         whose pixels count as unlabeled. If these are binary masks (e.g. SAM's 0/255), the \
         object is being dropped: pass --ignore-id with a value the maps do not use as a class \
         (e.g. --ignore-id {}) to keep both values as classes",
        dir.display(),
        format.describe_ignore(),
        suggested
    ))
}

/// The largest id below 255 that still reads as an ordinary class beside a class 255 of
/// 16-bit maps: where every other id is below it, 255 stands apart, as an 8-bit map's
/// no-label value carried into 16 bits would.
const STRAY_255_BELOW: u32 = 128;

/// The warning for label maps where 255 is a class far above every other id, with no class
/// table naming it and no --ignore-id given: 16-bit maps leave only 65535 unlabeled, and
/// maps converted from 8-bit ones (or written by code that used 255 for "no label") would
/// fuse their unlabeled pixels as a class. `class_ids` are the ids present.
pub fn stray_255_warning(
    dir: &Path,
    class_ids: &[u32],
    format: &LabelFormat,
    table: Option<&ClassTable>,
) -> Option<String> {
    let named = table.is_some_and(|t| t.contains(255));
    if !class_ids.contains(&255) || format.ignore_id.is_some() || named {
        return None;
    }
    let below = class_ids.iter().copied().filter(|&id| id != 255).max();
    if below.is_some_and(|id| id >= STRAY_255_BELOW) {
        return None;
    }
    let others = match below {
        Some(id) => format!("every other id is {id} or less"),
        None => "it is the only id".to_owned(),
    };
    Some(format!(
        "warning: label folder {} uses 255 as a class and {others}; 255 means no label only \
         in 8-bit maps (in 16-bit maps only 65535 does). If 255 marks unlabeled pixels here, \
         pass --ignore-id 255; if it is a class, name it in a class table (classes.json) to \
         silence this",
        dir.display()
    ))
}

/// Whether the label map `path`, or the first of the folder `path`, has an alpha channel
/// (gray+alpha or RGBA).
fn holds_alpha(path: &Path) -> bool {
    let first = match path.is_dir() {
        true => list_label_pngs(path)
            .ok()
            .and_then(|maps| maps.into_values().next()),
        false => Some(path.to_owned()),
    };
    first.is_some_and(|map| read_png_header(&map).is_ok_and(|h| matches!(h.color_type, 4 | 6)))
}

/// Loads every camera's label map (checked as in [`LabelDir::load`]) into memory, in camera
/// order; prefer [`LabelDir::iter`] for large scenes.
pub fn load_label_dir(
    dir: &Path,
    cameras: &[Camera],
    table: Option<&ClassTable>,
) -> Result<Vec<LabelMap>> {
    let labels = LabelDir::open(dir, cameras, table, MissingLabels::Error)?;
    labels.iter().map(|r| r.map(|(_, m)| m)).collect()
}
