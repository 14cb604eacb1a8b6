//! COLMAP sparse models (cameras/images, .bin and .txt).
//!
//! Layout: colmap.github.io/format.html. Binary files are little-endian. COLMAP's image poses
//! are world-to-camera (qvec wxyz, tvec) with x right, y down, z forward and pixel centers at
//! +0.5, exactly our [`Camera`] convention, so no conversion is needed. Only undistorted
//! pinhole models are accepted.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use glam::{DMat3, DQuat, DVec3};

use super::camera::{Camera, Split};
use super::cameras::{name_by_image_paths, validate_cameras, validate_cameras_as};
use crate::util::{write_atomic, write_bytes_atomic};

/// Longest image name we accept in a binary file (a missing NUL must not read the rest of the
/// file into one string).
const MAX_NAME_BYTES: usize = 4096;

/// Entries reserved up front from a count in a file header; more grow on demand, so a bogus
/// count cannot allocate more than the data that actually exists.
const MAX_PREALLOC: usize = 1 << 12;

/// COLMAP camera models: (model id, name, number of parameters).
const MODELS: &[(i32, &str, usize)] = &[
    (0, "SIMPLE_PINHOLE", 3),
    (1, "PINHOLE", 4),
    (2, "SIMPLE_RADIAL", 4),
    (3, "RADIAL", 5),
    (4, "OPENCV", 8),
    (5, "OPENCV_FISHEYE", 8),
    (6, "FULL_OPENCV", 12),
    (7, "FOV", 5),
    (8, "SIMPLE_RADIAL_FISHEYE", 4),
    (9, "RADIAL_FISHEYE", 5),
    (10, "THIN_PRISM_FISHEYE", 12),
    (11, "RAD_TAN_THIN_PRISM_FISHEYE", 16),
];

fn model_by_id(id: i32) -> Option<(&'static str, usize)> {
    MODELS.iter().find(|m| m.0 == id).map(|m| (m.1, m.2))
}

fn model_by_name(name: &str) -> Option<(i32, usize)> {
    MODELS.iter().find(|m| m.1 == name).map(|m| (m.0, m.2))
}

/// One entry of cameras.bin/.txt.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    /// Model name as COLMAP spells it, e.g. "PINHOLE".
    pub model: String,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
}

/// One entry of images.bin/.txt (2D points are skipped).
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    /// World-to-camera rotation, w x y z.
    pub qvec: [f64; 4],
    /// World-to-camera translation.
    pub tvec: [f64; 3],
    pub camera_id: u32,
    /// Image path relative to the image folder, as stored.
    pub name: String,
}

/// Which files a model uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColmapFormat {
    Binary,
    Text,
}

impl ColmapFormat {
    pub fn ext(self) -> &'static str {
        match self {
            ColmapFormat::Binary => "bin",
            ColmapFormat::Text => "txt",
        }
    }
}

// ---------------------------------------------------------------------------------------
// Locating a model

/// Finds the model folder and its format: `path` itself, `path/sparse/0` or `path/sparse`.
/// Binary is preferred when both formats are present (as COLMAP does).
pub fn find_colmap_model(path: &Path) -> Result<(PathBuf, ColmapFormat)> {
    let candidates = [
        path.to_path_buf(),
        path.join("sparse").join("0"),
        path.join("sparse"),
    ];
    for dir in &candidates {
        for format in [ColmapFormat::Binary, ColmapFormat::Text] {
            let ext = format.ext();
            if dir.join(format!("cameras.{ext}")).is_file()
                && dir.join(format!("images.{ext}")).is_file()
            {
                return Ok((dir.clone(), format));
            }
        }
    }
    bail!(
        "{} is not a COLMAP model: expected cameras.bin + images.bin (or cameras.txt + \
         images.txt) in it, in sparse/0 or in sparse",
        path.display()
    )
}

/// Reads the cameras of a COLMAP model (see [`find_colmap_model`] for the accepted paths),
/// sorted by name and validated.
pub fn read_colmap_model(path: &Path) -> Result<Vec<Camera>> {
    let (dir, format) = find_colmap_model(path)?;
    let ext = format.ext();
    let cam_path = dir.join(format!("cameras.{ext}"));
    let img_path = dir.join(format!("images.{ext}"));
    let open = |p: &Path| -> Result<BufReader<File>> {
        Ok(BufReader::new(
            File::open(p).with_context(|| format!("opening {}", p.display()))?,
        ))
    };
    let cams = match format {
        ColmapFormat::Binary => read_cameras_bin_from(&mut open(&cam_path)?),
        ColmapFormat::Text => read_cameras_txt_from(&mut open(&cam_path)?),
    }
    .with_context(|| format!("reading COLMAP cameras {}", cam_path.display()))?;
    let images = match format {
        ColmapFormat::Binary => read_images_bin_from(&mut open(&img_path)?),
        ColmapFormat::Text => read_images_txt_from(&mut open(&img_path)?),
    }
    .with_context(|| format!("reading COLMAP images {}", img_path.display()))?;
    colmap_to_cameras(&cams, &images).with_context(|| format!("COLMAP model {}", dir.display()))
}

// ---------------------------------------------------------------------------------------
// Conversion

/// Pinhole intrinsics (fx, fy, cx, cy) of a COLMAP camera, or an error for distorted models.
/// Radial/OpenCV models whose distortion coefficients are all exactly zero are pinhole.
pub fn pinhole_intrinsics(cam: &ColmapCamera) -> Result<[f64; 4]> {
    let p = &cam.params;
    let (_, n) = model_by_name(&cam.model)
        .ok_or_else(|| anyhow!("camera {} has unknown model '{}'", cam.id, cam.model))?;
    if p.len() != n {
        bail!(
            "camera {} ({}) has {} parameters, expected {n}",
            cam.id,
            cam.model,
            p.len()
        );
    }
    let zero_tail = |from: usize| p[from..].iter().all(|&v| v == 0.0);
    let intrinsics = match cam.model.as_str() {
        "SIMPLE_PINHOLE" => Some([p[0], p[0], p[1], p[2]]),
        "PINHOLE" => Some([p[0], p[1], p[2], p[3]]),
        "SIMPLE_RADIAL" | "RADIAL" if zero_tail(3) => Some([p[0], p[0], p[1], p[2]]),
        "OPENCV" | "FULL_OPENCV" if zero_tail(4) => Some([p[0], p[1], p[2], p[3]]),
        _ => None,
    };
    intrinsics.ok_or_else(|| {
        anyhow!(
            "camera {} uses the distorted model {}; semsplat needs undistorted PINHOLE or \
             SIMPLE_PINHOLE cameras: run `colmap image_undistorter --image_path IMAGES \
             --input_path MODEL --output_path OUT` and use OUT/sparse with OUT/images",
            cam.id,
            cam.model
        )
    })
}

/// World-to-camera rotation from a COLMAP qvec (w x y z, normalized here as COLMAP does).
pub fn rotation_from_qvec(q: [f64; 4]) -> Result<DMat3> {
    let quat = DQuat::from_xyzw(q[1], q[2], q[3], q[0]);
    let norm = quat.length();
    if !norm.is_finite() || norm < 1e-12 {
        bail!("quaternion {q:?} is zero or not finite");
    }
    Ok(DMat3::from_quat(quat / norm))
}

/// COLMAP qvec (w x y z, w >= 0) of a world-to-camera rotation.
pub fn qvec_from_rotation(r: DMat3) -> [f64; 4] {
    let q = DQuat::from_mat3(&r).normalize();
    let q = if q.w < 0.0 { -q } else { q };
    [q.w, q.x, q.y, q.z]
}

/// Joins images with their cameras: one [`Camera`] per image, named by the image stem (by
/// the relative image path where stems repeat, as in a multi-camera rig: see
/// [`super::cameras::image_names`]), sorted by name, validated.
pub fn colmap_to_cameras(cams: &[ColmapCamera], images: &[ColmapImage]) -> Result<Vec<Camera>> {
    let mut intrinsics: HashMap<u32, (&ColmapCamera, [f64; 4])> = HashMap::new();
    for cam in cams {
        let k = pinhole_intrinsics(cam)?;
        if intrinsics.insert(cam.id, (cam, k)).is_some() {
            bail!("camera id {} appears twice", cam.id);
        }
    }
    let mut out = Vec::with_capacity(images.len());
    let mut image_ids = Vec::with_capacity(images.len());
    for img in images {
        let (cam, [fx, fy, cx, cy]) = *intrinsics.get(&img.camera_id).ok_or_else(|| {
            anyhow!(
                "image {} ('{}') refers to camera {}, which is not in the model",
                img.id,
                img.name,
                img.camera_id
            )
        })?;
        let (width, height) = match (u32::try_from(cam.width), u32::try_from(cam.height)) {
            (Ok(w), Ok(h)) => (w, h),
            _ => bail!(
                "camera {} has an unsupported size {}x{}",
                cam.id,
                cam.width,
                cam.height
            ),
        };
        let rotation = rotation_from_qvec(img.qvec)
            .with_context(|| format!("image {} ('{}')", img.id, img.name))?;
        let camera = Camera {
            name: img.name.clone(), // the image path until name_by_image_paths
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            rotation,
            translation: DVec3::from_array(img.tvec),
            split: Split::Train,
        };
        // Named by the model's own ids: after sorting, a position in the list is neither.
        camera
            .validate()
            .with_context(|| format!("image {} ('{}') of camera {}", img.id, img.name, cam.id))?;
        out.push(camera);
        image_ids.push(img.id);
    }
    if out.is_empty() {
        bail!("the model has no images");
    }
    name_by_image_paths(&mut out);
    let mut named: Vec<(Camera, u32)> = out.into_iter().zip(image_ids).collect();
    named.sort_by(|a, b| a.0.name.cmp(&b.0.name));
    let (out, image_ids): (Vec<Camera>, Vec<u32>) = named.into_iter().unzip();
    validate_cameras_as(&out, |i| format!("image {}", image_ids[i]))?;
    Ok(out)
}

// ---------------------------------------------------------------------------------------
// Binary reading

fn read_array<const N: usize>(r: &mut impl Read, what: &str) -> Result<[u8; N]> {
    let mut b = [0u8; N];
    r.read_exact(&mut b).map_err(|e| match e.kind() {
        std::io::ErrorKind::UnexpectedEof => anyhow!("file is truncated (while reading {what})"),
        _ => anyhow!("read error while reading {what}: {e}"),
    })?;
    Ok(b)
}

fn read_u64(r: &mut impl Read, what: &str) -> Result<u64> {
    Ok(u64::from_le_bytes(read_array(r, what)?))
}

fn read_u32(r: &mut impl Read, what: &str) -> Result<u32> {
    Ok(u32::from_le_bytes(read_array(r, what)?))
}

fn read_i32(r: &mut impl Read, what: &str) -> Result<i32> {
    Ok(i32::from_le_bytes(read_array(r, what)?))
}

fn read_f64(r: &mut impl Read, what: &str) -> Result<f64> {
    Ok(f64::from_le_bytes(read_array(r, what)?))
}

/// Parses cameras.bin from any reader.
pub fn read_cameras_bin_from(r: &mut impl Read) -> Result<Vec<ColmapCamera>> {
    let count = read_u64(r, "the camera count")?;
    let mut cams = Vec::with_capacity((count as usize).min(MAX_PREALLOC));
    for i in 0..count {
        let what = format!("camera {i} of {count}");
        let id = read_u32(r, &what)?;
        let model_id = read_i32(r, &what)?;
        let (model, n) = model_by_id(model_id)
            .ok_or_else(|| anyhow!("camera {id} has unknown model id {model_id}"))?;
        let width = read_u64(r, &what)?;
        let height = read_u64(r, &what)?;
        let params = (0..n)
            .map(|_| read_f64(r, &what))
            .collect::<Result<Vec<_>>>()?;
        cams.push(ColmapCamera {
            id,
            model: model.to_owned(),
            width,
            height,
            params,
        });
    }
    refuse_more(r, count, "cameras")?;
    Ok(cams)
}

/// Parses images.bin from any reader; 2D points are skipped without being stored.
pub fn read_images_bin_from(r: &mut impl Read) -> Result<Vec<ColmapImage>> {
    let count = read_u64(r, "the image count")?;
    let mut images = Vec::with_capacity((count as usize).min(MAX_PREALLOC));
    for i in 0..count {
        let what = format!("image {i} of {count}");
        let id = read_u32(r, &what)?;
        let mut qvec = [0.0; 4];
        for q in &mut qvec {
            *q = read_f64(r, &what)?;
        }
        let mut tvec = [0.0; 3];
        for t in &mut tvec {
            *t = read_f64(r, &what)?;
        }
        let camera_id = read_u32(r, &what)?;
        let name = read_nul_terminated(r, &what)?;
        let points = read_u64(r, &what)?;
        // Each 2D point is x, y (f64) and a point3D id (i64): 24 bytes.
        let skip = points
            .checked_mul(24)
            .ok_or_else(|| anyhow!("image {id} claims {points} 2D points"))?;
        let skipped = std::io::copy(&mut r.by_ref().take(skip), &mut std::io::sink())
            .map_err(|e| anyhow!("read error in the 2D points of image {id}: {e}"))?;
        if skipped != skip {
            bail!("file is truncated (in the 2D points of image {id} '{name}')");
        }
        images.push(ColmapImage {
            id,
            qvec,
            tvec,
            camera_id,
            name,
        });
    }
    refuse_more(r, count, "images")?;
    Ok(images)
}

/// A binary model holding more than its count says (a count left from an earlier write, two
/// files joined): reading `count` entries would silently leave the rest out.
fn refuse_more(r: &mut impl Read, count: u64, what: &str) -> Result<()> {
    let mut next = [0u8; 1];
    match r.read(&mut next) {
        Ok(0) => Ok(()),
        Ok(_) => bail!("data continues past the {count} {what} its count names: the count is wrong, or the file holds more than it declares"),
        Err(e) => Err(anyhow!("read error after the {count} {what}: {e}")),
    }
}

fn read_nul_terminated(r: &mut impl Read, what: &str) -> Result<String> {
    let mut bytes = Vec::new();
    loop {
        let [b] = read_array::<1>(r, what)?;
        if b == 0 {
            break;
        }
        if bytes.len() >= MAX_NAME_BYTES {
            bail!("image name in {what} is longer than {MAX_NAME_BYTES} bytes (corrupt file?)");
        }
        bytes.push(b);
    }
    String::from_utf8(bytes).map_err(|_| anyhow!("image name in {what} is not UTF-8"))
}

// ---------------------------------------------------------------------------------------
// Text reading

/// The trimmed contents of a line that carries data (not blank, not a `#` comment).
fn data_line(line: &str) -> Option<&str> {
    let t = line.trim();
    (!t.is_empty() && !t.starts_with('#')).then_some(t)
}

fn parse_num<T: std::str::FromStr>(tok: &str, what: &str, line_no: usize) -> Result<T> {
    tok.parse()
        .map_err(|_| anyhow!("line {line_no}: cannot parse {what} from '{tok}'"))
}

/// Parses cameras.txt (`CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`) from any reader.
pub fn read_cameras_txt_from(r: &mut impl BufRead) -> Result<Vec<ColmapCamera>> {
    let mut cams = Vec::new();
    for (i, line) in r.lines().enumerate() {
        let line_no = i + 1;
        let line = line.with_context(|| format!("line {line_no}: read error"))?;
        let Some(data) = data_line(&line) else {
            continue;
        };
        let toks: Vec<&str> = data.split_whitespace().collect();
        if toks.len() < 4 {
            bail!("line {line_no}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got '{data}'");
        }
        let id = parse_num(toks[0], "CAMERA_ID", line_no)?;
        let model = toks[1];
        let (_, n) = model_by_name(model)
            .ok_or_else(|| anyhow!("line {line_no}: unknown camera model '{model}'"))?;
        let width = parse_num(toks[2], "WIDTH", line_no)?;
        let height = parse_num(toks[3], "HEIGHT", line_no)?;
        if toks.len() != 4 + n {
            bail!(
                "line {line_no}: model {model} needs {n} parameters, got {}",
                toks.len() - 4
            );
        }
        let params = toks[4..]
            .iter()
            .map(|t| parse_num(t, "a parameter", line_no))
            .collect::<Result<Vec<f64>>>()?;
        cams.push(ColmapCamera {
            id,
            model: model.to_owned(),
            width,
            height,
            params,
        });
    }
    Ok(cams)
}

/// Parses images.txt from any reader: per image a pose line
/// `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`, usually followed by a 2D-points line of
/// `X Y POINT3D_ID` triples (skipped). Writers differ on that second line: COLMAP writes it
/// (empty when there are no points), some pycolmap exports leave it out entirely. Taking
/// "the line after a pose line" blindly would swallow every other image of the latter, so
/// each line is recognised by its shape instead: a points line holds only numbers, in
/// triples whose third is an integer; anything else must be a pose line.
pub fn read_images_txt_from(r: &mut impl BufRead) -> Result<Vec<ColmapImage>> {
    let mut images = Vec::new();
    // A points line may only follow a pose line.
    let mut after_pose = false;
    for (i, line) in r.lines().enumerate() {
        let line_no = i + 1;
        let line = line.with_context(|| format!("line {line_no}: read error"))?;
        let Some(data) = data_line(&line) else {
            continue;
        };
        let toks: Vec<&str> = data.split_whitespace().collect();
        if after_pose && is_points_line(&toks) {
            after_pose = false;
            continue;
        }
        images.push(parse_pose_line(&toks, data, line_no)?);
        after_pose = true;
    }
    Ok(images)
}

/// True for a 2D-points line: `X Y POINT3D_ID` triples (POINT3D_ID is -1 when unmatched).
fn is_points_line(toks: &[&str]) -> bool {
    toks.len().is_multiple_of(3)
        && toks.chunks(3).all(|t| {
            t[0].parse::<f64>().is_ok()
                && t[1].parse::<f64>().is_ok()
                && t[2].parse::<i64>().is_ok()
        })
}

/// One `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME` line (the name may hold spaces and
/// subfolders, e.g. `cam0/0001.jpg` in a rig).
fn parse_pose_line(toks: &[&str], data: &str, line_no: usize) -> Result<ColmapImage> {
    if toks.len() < 10 {
        bail!(
            "line {line_no}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (or a 2D-points \
             line of X Y POINT3D_ID triples after it), got '{}'",
            truncate_for_error(data)
        );
    }
    let id = parse_num(toks[0], "IMAGE_ID", line_no)?;
    let mut qvec = [0.0; 4];
    for (k, v) in qvec.iter_mut().enumerate() {
        *v = parse_num(toks[1 + k], "the quaternion", line_no)?;
    }
    let mut tvec = [0.0; 3];
    for (k, v) in tvec.iter_mut().enumerate() {
        *v = parse_num(toks[5 + k], "the translation", line_no)?;
    }
    let camera_id = parse_num(toks[8], "CAMERA_ID", line_no)?;
    // The name is the rest of the line as written: joining its words would turn "a  b.png"
    // or a tab into one space, naming a file that is not there.
    let name_at = toks[9].as_ptr() as usize - data.as_ptr() as usize;
    Ok(ColmapImage {
        id,
        qvec,
        tvec,
        camera_id,
        name: data[name_at..].to_owned(),
    })
}

fn truncate_for_error(s: &str) -> String {
    s.chars().take(120).collect()
}

// ---------------------------------------------------------------------------------------
// Writing

/// Writes `cameras`, `images` and an empty `points3D` in `dir` (created if needed). One
/// PINHOLE camera is written per distinct intrinsics; image names are
/// `<camera.name>.<image_ext>` (or the bare name when `image_ext` is empty).
pub fn write_colmap_model(
    dir: &Path,
    cameras: &[Camera],
    format: ColmapFormat,
    image_ext: &str,
) -> Result<()> {
    validate_cameras(cameras)
        .with_context(|| format!("refusing to write COLMAP model {}", dir.display()))?;
    let (intrinsics, cam_of_image) = dedupe_intrinsics(cameras);
    let images: Vec<ImageEntry> = cameras
        .iter()
        .zip(&cam_of_image)
        .map(|(camera, &intrinsics_index)| ImageEntry {
            camera,
            intrinsics_index,
            name: if image_ext.is_empty() {
                camera.name.clone()
            } else {
                format!("{}.{}", camera.name, image_ext.trim_start_matches('.'))
            },
        })
        .collect();
    let ext = format.ext();
    let cam_path = dir.join(format!("cameras.{ext}"));
    let img_path = dir.join(format!("images.{ext}"));
    let pts_path = dir.join(format!("points3D.{ext}"));
    match format {
        ColmapFormat::Binary => {
            write_atomic(&cam_path, |w| write_cameras_bin(w, &intrinsics))?;
            write_atomic(&img_path, |w| write_images_bin(w, &images))?;
            write_bytes_atomic(&pts_path, &0u64.to_le_bytes())?;
        }
        ColmapFormat::Text => {
            write_bytes_atomic(&cam_path, cameras_txt(&intrinsics).as_bytes())?;
            write_bytes_atomic(&img_path, images_txt(&images).as_bytes())?;
            write_bytes_atomic(
                &pts_path,
                b"# 3D point list with one line of data per point:\n\
                  #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n\
                  # Number of points: 0, mean track length: 0\n",
            )?;
        }
    }
    Ok(())
}

/// One image to write: its camera, the index of its intrinsics (0-based; COLMAP ids are
/// 1-based) and its file name.
struct ImageEntry<'a> {
    camera: &'a Camera,
    intrinsics_index: usize,
    name: String,
}

/// cameras.bin: one PINHOLE camera per distinct intrinsics.
fn write_cameras_bin(w: &mut impl Write, intrinsics: &[&Camera]) -> Result<()> {
    w.write_all(&(intrinsics.len() as u64).to_le_bytes())?;
    for (i, c) in intrinsics.iter().enumerate() {
        w.write_all(&(i as u32 + 1).to_le_bytes())?;
        w.write_all(&1i32.to_le_bytes())?; // PINHOLE
        w.write_all(&(c.width as u64).to_le_bytes())?;
        w.write_all(&(c.height as u64).to_le_bytes())?;
        for v in [c.fx, c.fy, c.cx, c.cy] {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    Ok(())
}

/// images.bin: pose, camera id and name per image, without 2D points.
fn write_images_bin(w: &mut impl Write, images: &[ImageEntry]) -> Result<()> {
    w.write_all(&(images.len() as u64).to_le_bytes())?;
    for (i, image) in images.iter().enumerate() {
        w.write_all(&(i as u32 + 1).to_le_bytes())?;
        for v in qvec_from_rotation(image.camera.rotation) {
            w.write_all(&v.to_le_bytes())?;
        }
        for v in image.camera.translation.to_array() {
            w.write_all(&v.to_le_bytes())?;
        }
        w.write_all(&(image.intrinsics_index as u32 + 1).to_le_bytes())?;
        w.write_all(image.name.as_bytes())?;
        w.write_all(&[0])?;
        w.write_all(&0u64.to_le_bytes())?; // no 2D points
    }
    Ok(())
}

/// cameras.txt: one PINHOLE camera per distinct intrinsics.
fn cameras_txt(intrinsics: &[&Camera]) -> String {
    let mut text = String::from(
        "# Camera list with one line of data per camera:\n\
         #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let _ = writeln!(text, "# Number of cameras: {}", intrinsics.len());
    for (i, c) in intrinsics.iter().enumerate() {
        let _ = writeln!(
            text,
            "{} PINHOLE {} {} {} {} {} {}",
            i + 1,
            c.width,
            c.height,
            c.fx,
            c.fy,
            c.cx,
            c.cy
        );
    }
    text
}

/// images.txt: a pose line per image, each followed by an empty 2D-points line.
fn images_txt(images: &[ImageEntry]) -> String {
    let mut text = String::from(
        "# Image list with two lines of data per image:\n\
         #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
         #   POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    let _ = writeln!(
        text,
        "# Number of images: {}, mean observations per image: 0",
        images.len()
    );
    for (i, image) in images.iter().enumerate() {
        let [qw, qx, qy, qz] = qvec_from_rotation(image.camera.rotation);
        let [tx, ty, tz] = image.camera.translation.to_array();
        let _ = writeln!(
            text,
            "{} {qw} {qx} {qy} {qz} {tx} {ty} {tz} {} {}\n",
            i + 1,
            image.intrinsics_index + 1,
            image.name
        );
    }
    text
}

/// Distinct intrinsics (first appearance order) and, per camera, the index of its intrinsics.
fn dedupe_intrinsics(cameras: &[Camera]) -> (Vec<&Camera>, Vec<usize>) {
    let mut index: BTreeMap<(u32, u32, [u64; 4]), usize> = BTreeMap::new();
    let mut distinct = Vec::new();
    let mut of_image = Vec::with_capacity(cameras.len());
    for c in cameras {
        let key = (
            c.width,
            c.height,
            [
                c.fx.to_bits(),
                c.fy.to_bits(),
                c.cx.to_bits(),
                c.cy.to_bits(),
            ],
        );
        let next = distinct.len();
        let i = *index.entry(key).or_insert(next);
        if i == next {
            distinct.push(c);
        }
        of_image.push(i);
    }
    (distinct, of_image)
}
