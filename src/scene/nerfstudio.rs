//! nerfstudio `transforms.json` cameras (the pinhole part).
//!
//! Layout (docs.nerf.studio, "Data conventions"): intrinsics `fl_x fl_y cx cy w h` at the top
//! level or per frame (a frame's own keys win), `camera_model` (`OPENCV` by default) with
//! distortion `k1 k2 k3 k4 p1 p2`, and `frames` of `{file_path, transform_matrix}` where
//! `transform_matrix` is the 4x4 **camera-to-world** matrix in nerfstudio's **OpenGL** camera
//! frame (x right, y up, z back). Our cameras are OpenCV (x right, y down, z forward,
//! docs/CONVENTIONS.md), so the camera's y and z axes are negated:
//! `R_c2w_cv = R_c2w_gl * diag(1, -1, -1)`, then `R = R_c2w_cv^T`, `t = -R * center`.
//! nerfstudio puts pixel centers at +0.5 like we do, so `cx cy` are taken as is.
//! Distorted models (`OPENCV` with a non-zero k/p coefficient, `OPENCV_FISHEYE`,
//! `EQUIRECTANGULAR`, ...) are refused as COLMAP's are: undistort first.
//! `applied_transform` (what ns-process-data applied to the COLMAP world) is not undone: the
//! cameras are in the file's world frame.

use anyhow::{anyhow, bail, Context, Result};
use glam::{DMat3, DVec3};
use serde_json::{Map, Value};

use super::camera::{Camera, Split};

const DISTORTION_KEYS: [&str; 6] = ["k1", "k2", "k3", "k4", "p1", "p2"];

/// A key of the frame, else of the top level.
fn key<'a>(
    frame: &'a Map<String, Value>,
    top: &'a Map<String, Value>,
    k: &str,
) -> Option<&'a Value> {
    frame.get(k).or_else(|| top.get(k))
}

fn number(frame: &Map<String, Value>, top: &Map<String, Value>, k: &str) -> Result<f64> {
    key(frame, top, k)
        .ok_or_else(|| anyhow!("'{k}' is missing (needed at the top level or in the frame)"))?
        .as_f64()
        .ok_or_else(|| anyhow!("'{k}' is not a number"))
}

/// Refuses distorted or non-pinhole camera models.
fn check_pinhole(frame: &Map<String, Value>, top: &Map<String, Value>) -> Result<()> {
    // null as absent (a writer's None).
    let model = match key(frame, top, "camera_model").filter(|v| !v.is_null()) {
        None => "OPENCV",
        Some(v) => v
            .as_str()
            .ok_or_else(|| anyhow!("camera_model {v} is not a model name (a string)"))?,
    };
    if !matches!(model, "OPENCV" | "PINHOLE" | "SIMPLE_PINHOLE") {
        bail!(
            "camera_model {model} is not supported: semsplat needs undistorted pinhole cameras \
             (PINHOLE, SIMPLE_PINHOLE, or OPENCV with zero distortion: undistort the images \
             first)"
        );
    }
    for k in DISTORTION_KEYS {
        if let Some(v) = key(frame, top, k).filter(|v| !v.is_null()) {
            // A coefficient that is not a number must not be read as no distortion.
            let v = v
                .as_f64()
                .ok_or_else(|| anyhow!("distortion {k} = {v} is not a number"))?;
            if v != 0.0 {
                bail!(
                    "distortion {k} = {v}: semsplat needs undistorted pinhole cameras; undistort \
                     the images first (e.g. `colmap image_undistorter`, then `ns-process-data` \
                     on the result) or pass the undistorted COLMAP model"
                );
            }
        }
    }
    Ok(())
}

/// World-to-camera rotation and translation (OpenCV) from an OpenGL camera-to-world matrix.
pub fn pose_from_opengl_c2w(m: &[[f64; 4]; 4]) -> Result<(DMat3, DVec3)> {
    if (m[3][0], m[3][1], m[3][2], m[3][3]) != (0.0, 0.0, 0.0, 1.0) {
        bail!(
            "transform_matrix's last row must be [0, 0, 0, 1], got {:?}",
            m[3]
        );
    }
    let rows = [
        [m[0][0], m[0][1], m[0][2]],
        [m[1][0], m[1][1], m[1][2]],
        [m[2][0], m[2][1], m[2][2]],
    ];
    let c2w_gl = DMat3::from_cols_array_2d(&rows).transpose();
    let c2w_cv = c2w_gl * DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0));
    let rotation = c2w_cv.transpose();
    let center = DVec3::new(m[0][3], m[1][3], m[2][3]);
    Ok((rotation, -(rotation * center)))
}

fn parse_frame(i: usize, v: &Value, top: &Map<String, Value>) -> Result<Camera> {
    let frame = v.as_object().ok_or_else(|| anyhow!("not an object"))?;
    let file_path = frame
        .get("file_path")
        .and_then(Value::as_str)
        .ok_or_else(|| anyhow!("'file_path' is missing"))?;
    let label = format!("frame {i} ('{file_path}')");
    check_pinhole(frame, top).with_context(|| label.clone())?;
    let matrix: [[f64; 4]; 4] = serde_json::from_value(
        frame
            .get("transform_matrix")
            .cloned()
            .ok_or_else(|| anyhow!("{label}: 'transform_matrix' is missing"))?,
    )
    .map_err(|e| anyhow!("{label}: transform_matrix is not a 4x4 list of numbers ({e})"))?;
    let (rotation, translation) = pose_from_opengl_c2w(&matrix).with_context(|| label.clone())?;
    if key(frame, top, "fl_x").is_none() && key(frame, top, "camera_angle_x").is_some() {
        bail!(
            "{label}: a Blender / instant-NGP transforms.json (camera_angle_x) is not read: its \
             image size is not in the file; give w, h, fl_x, fl_y, cx and cy (as nerfstudio's \
             ns-process-data writes them)"
        );
    }
    let num = |k: &str| number(frame, top, k).with_context(|| label.clone());
    let model = key(frame, top, "camera_model").and_then(Value::as_str);
    let simple = model == Some("SIMPLE_PINHOLE");
    let size = |k: &str| -> Result<u32> {
        let v = num(k)?;
        if v.fract() != 0.0 || !(1.0..=u32::MAX as f64).contains(&v) {
            bail!("{label}: '{k}' = {v} is not a positive whole number of pixels");
        }
        Ok(v as u32)
    };
    Ok(Camera {
        name: file_path.to_owned(), // named by cameras::name_by_image_paths
        width: size("w")?,
        height: size("h")?,
        fx: num("fl_x")?,
        // SIMPLE_PINHOLE: one focal length, written as fl_x alone.
        fy: match (key(frame, top, "fl_y"), simple) {
            (None, true) => num("fl_x")?,
            _ => num("fl_y")?,
        },
        cx: num("cx")?,
        cy: num("cy")?,
        rotation,
        translation,
        split: Split::Train,
    })
}

/// Cameras of a parsed transforms.json object (validated by the caller).
pub fn parse_transforms(top: &Map<String, Value>) -> Result<Vec<Camera>> {
    let frames = top
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| anyhow!("transforms.json: 'frames' is not a list"))?;
    if frames.is_empty() {
        bail!("the transforms.json lists no frames");
    }
    let mut cameras: Vec<Camera> = (frames.iter().enumerate())
        .map(|(i, v)| parse_frame(i, v, top))
        .collect::<Result<_>>()?;
    mark_held_out(&mut cameras, top)?;
    Ok(cameras)
}

/// nerfstudio's split lists: the frames `test_filenames` or `val_filenames` names are held
/// out (marked "test", as `--train-only` and `eval` read them); every other frame trains.
/// A list that names no frame is refused (its paths written otherwise than the frames').
fn mark_held_out(cameras: &mut [Camera], top: &Map<String, Value>) -> Result<()> {
    // "./images/a.png", "images/a.png" and "images/a" name one frame.
    let plain = |path: &str| -> String {
        let path = path.trim_start_matches("./");
        let cut = path.rfind('.').filter(|&dot| !path[dot..].contains('/'));
        cut.map_or(path, |dot| &path[..dot]).to_owned()
    };
    for list in ["test_filenames", "val_filenames"] {
        let Some(names) = top.get(list) else { continue };
        let names = (names.as_array())
            .and_then(|a| a.iter().map(Value::as_str).collect::<Option<Vec<&str>>>())
            .ok_or_else(|| anyhow!("transforms.json: '{list}' is not a list of paths"))?;
        let held: std::collections::HashSet<String> = names.iter().map(|n| plain(n)).collect();
        let mut marked = 0;
        for cam in cameras
            .iter_mut()
            .filter(|c| held.contains(&plain(&c.name)))
        {
            cam.split = Split::Test;
            marked += 1;
        }
        if marked == 0 && !held.is_empty() {
            bail!(
                "transforms.json: '{list}' names {} files, none a frame's file_path (e.g. {}): \
                 write them as the frames do",
                held.len(),
                names[0]
            );
        }
    }
    Ok(())
}
