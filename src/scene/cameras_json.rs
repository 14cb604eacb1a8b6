//! Camera JSON: the INRIA cameras.json and semsplat's own camera JSON.
//!
//! INRIA (written by 3DGS training): a list of `{id, img_name, width, height, position,
//! rotation, fx, fy}` where `position` is the camera center in world space and `rotation` the
//! camera-to-world rotation as a list of rows; the principal point is the image center unless
//! `cx`/`cy` are present. semsplat: `{"format": "semsplat-cameras", "version": 1, "cameras":
//! [...]}` with full intrinsics, a 4x4 world-to-camera matrix (rows) and a split. The two are
//! told apart by their top-level shape (list vs object).

use std::io::Write;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::camera::{Camera, Split};
use super::cameras::{name_by_image_paths, validate_cameras};
use super::classes::ClassTable;
use crate::util::write_atomic;

/// The `format` value of semsplat camera files.
pub const SEMSPLAT_CAMERAS_FORMAT: &str = "semsplat-cameras";
/// The `version` this code reads and writes.
pub const SEMSPLAT_CAMERAS_VERSION: u32 = 1;

/// Which camera JSON a file was.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraJsonKind {
    Inria,
    Semsplat,
    /// nerfstudio / instant-ngp `transforms.json` (see `scene::nerfstudio`).
    Nerfstudio,
}

#[derive(Serialize, Deserialize)]
struct InriaCamera {
    #[serde(default)]
    id: Option<i64>,
    img_name: String,
    width: u32,
    height: u32,
    /// Camera center in world coordinates.
    position: [f64; 3],
    /// Camera-to-world rotation, rows.
    rotation: [[f64; 3]; 3],
    fx: f64,
    fy: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cx: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cy: Option<f64>,
}

#[derive(Serialize, Deserialize)]
struct SemsplatCamera {
    name: String,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    /// 4x4 world-to-camera matrix, rows; last row 0 0 0 1.
    world_to_camera: [[f64; 4]; 4],
    #[serde(default)]
    split: Split,
}

#[derive(Serialize)]
struct SemsplatCamerasFile<'a> {
    format: &'a str,
    version: u32,
    cameras: Vec<SemsplatCamera>,
}

/// Reads an INRIA or semsplat camera JSON (detected from its shape); cameras are validated.
pub fn read_cameras_json(path: &Path) -> Result<Vec<Camera>> {
    Ok(read_cameras_json_kind(path)?.1)
}

/// Like [`read_cameras_json`], also telling which format the file was.
pub fn read_cameras_json_kind(path: &Path) -> Result<(CameraJsonKind, Vec<Camera>)> {
    let bytes =
        std::fs::read(path).with_context(|| format!("reading camera JSON {}", path.display()))?;
    parse_cameras_json(&bytes).with_context(|| format!("camera JSON {}", path.display()))
}

/// Parses camera JSON from memory (the entry point the fuzzer uses).
pub fn parse_cameras_json(bytes: &[u8]) -> Result<(CameraJsonKind, Vec<Camera>)> {
    let value: Value = serde_json::from_slice(bytes).map_err(|e| anyhow!("invalid JSON: {e}"))?;
    let (kind, mut cameras) = match &value {
        Value::Array(entries) => (CameraJsonKind::Inria, parse_inria(entries)?),
        Value::Object(obj) => match obj.get("format").and_then(Value::as_str) {
            Some(SEMSPLAT_CAMERAS_FORMAT) => (CameraJsonKind::Semsplat, parse_semsplat(&value)?),
            Some(other) => {
                bail!("unknown camera format '{other}' (expected '{SEMSPLAT_CAMERAS_FORMAT}')")
            }
            None if obj.contains_key("frames") => (
                CameraJsonKind::Nerfstudio,
                super::nerfstudio::parse_transforms(obj)?,
            ),
            None if ClassTable::json_has_shape(&value) => {
                bail!("this is a class table, not cameras")
            }
            None => bail!(
                "unrecognized camera JSON: expected a list (INRIA cameras.json) or an object \
                 with \"format\": \"{SEMSPLAT_CAMERAS_FORMAT}\""
            ),
        },
        _ => bail!("unrecognized camera JSON: the top level must be a list or an object"),
    };
    if cameras.is_empty() {
        bail!("the file lists no cameras");
    }
    // INRIA and nerfstudio list image paths; semsplat's own names are kept as written.
    if kind != CameraJsonKind::Semsplat {
        name_by_image_paths(&mut cameras);
    }
    validate_cameras(&cameras)?;
    Ok((kind, cameras))
}

/// Error context for entry `i`: its index and, when readable, its name.
fn entry_label(i: usize, v: &Value, name_key: &str) -> String {
    match v.get(name_key).and_then(Value::as_str) {
        Some(name) => format!("camera {i} ('{name}')"),
        None => format!("camera {i}"),
    }
}

fn parse_inria(entries: &[Value]) -> Result<Vec<Camera>> {
    entries
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let c = InriaCamera::deserialize(v)
                .map_err(|e| anyhow!("{}: {e}", entry_label(i, v, "img_name")))?;
            // The rows of camera-to-world are the columns of world-to-camera.
            let rotation = DMat3::from_cols_array_2d(&c.rotation);
            let translation = -(rotation * DVec3::from_array(c.position));
            Ok(Camera {
                name: c.img_name, // the image path until name_by_image_paths
                width: c.width,
                height: c.height,
                fx: c.fx,
                fy: c.fy,
                cx: c.cx.unwrap_or(c.width as f64 / 2.0),
                cy: c.cy.unwrap_or(c.height as f64 / 2.0),
                rotation,
                translation,
                split: Split::Train,
            })
        })
        .collect()
}

fn parse_semsplat(value: &Value) -> Result<Vec<Camera>> {
    let version = value.get("version").and_then(Value::as_u64);
    if version != Some(SEMSPLAT_CAMERAS_VERSION as u64) {
        bail!(
            "unsupported semsplat camera file version {} (this build reads version {SEMSPLAT_CAMERAS_VERSION})",
            value.get("version").map(Value::to_string).unwrap_or_else(|| "(missing)".into())
        );
    }
    let entries = value
        .get("cameras")
        .and_then(Value::as_array)
        .ok_or_else(|| anyhow!("missing \"cameras\" list"))?;
    entries
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let label = entry_label(i, v, "name");
            let c = SemsplatCamera::deserialize(v).map_err(|e| anyhow!("{label}: {e}"))?;
            let m = &c.world_to_camera;
            let last_row_ok = m[3]
                .iter()
                .zip([0.0, 0.0, 0.0, 1.0])
                .all(|(a, b)| (a - b).abs() <= 1e-9);
            if !last_row_ok {
                bail!(
                    "{label}: world_to_camera's last row must be [0, 0, 0, 1], got {:?}",
                    m[3]
                );
            }
            let rows = [
                [m[0][0], m[0][1], m[0][2]],
                [m[1][0], m[1][1], m[1][2]],
                [m[2][0], m[2][1], m[2][2]],
            ];
            Ok(Camera {
                name: c.name,
                width: c.width,
                height: c.height,
                fx: c.fx,
                fy: c.fy,
                cx: c.cx,
                cy: c.cy,
                rotation: DMat3::from_cols_array_2d(&rows).transpose(),
                translation: DVec3::new(m[0][3], m[1][3], m[2][3]),
                split: c.split,
            })
        })
        .collect()
}

/// Writes semsplat's camera JSON (atomically). The cameras are validated first.
pub fn write_semsplat_cameras(path: &Path, cams: &[Camera]) -> Result<()> {
    validate_cameras(cams)
        .with_context(|| format!("refusing to write camera JSON {}", path.display()))?;
    let cameras = cams
        .iter()
        .map(|c| {
            let r = c.rotation.transpose().to_cols_array_2d(); // rows of R
            let t = c.translation;
            SemsplatCamera {
                name: c.name.clone(),
                width: c.width,
                height: c.height,
                fx: c.fx,
                fy: c.fy,
                cx: c.cx,
                cy: c.cy,
                world_to_camera: [
                    [r[0][0], r[0][1], r[0][2], t.x],
                    [r[1][0], r[1][1], r[1][2], t.y],
                    [r[2][0], r[2][1], r[2][2], t.z],
                    [0.0, 0.0, 0.0, 1.0],
                ],
                split: c.split,
            }
        })
        .collect();
    let file = SemsplatCamerasFile {
        format: SEMSPLAT_CAMERAS_FORMAT,
        version: SEMSPLAT_CAMERAS_VERSION,
        cameras,
    };
    write_json(path, &file)
}

/// Writes an INRIA 3DGS `cameras.json` (atomically). `cx`/`cy` are written too (INRIA's
/// readers ignore them) so off-center principal points survive a round trip through us.
pub fn write_inria_cameras(path: &Path, cams: &[Camera]) -> Result<()> {
    validate_cameras(cams)
        .with_context(|| format!("refusing to write camera JSON {}", path.display()))?;
    let entries: Vec<InriaCamera> = cams
        .iter()
        .enumerate()
        .map(|(i, c)| InriaCamera {
            id: Some(i as i64),
            img_name: c.name.clone(),
            width: c.width,
            height: c.height,
            position: c.center().to_array(),
            // Rows of camera-to-world = columns of world-to-camera.
            rotation: c.rotation.to_cols_array_2d(),
            fx: c.fx,
            fy: c.fy,
            cx: Some(c.cx),
            cy: Some(c.cy),
        })
        .collect();
    write_json(path, &entries)
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, value)?;
        w.write_all(b"\n")?;
        Ok(())
    })
}
