//! A posed pinhole camera. The one place our coordinate conventions live in code:
//! world-to-camera rigid transform, camera looks down +z, x right, y down (OpenCV/COLMAP),
//! pixel centers at +0.5, u = fx * x / z + cx. See `docs/CONVENTIONS.md`.

use glam::{DMat3, DVec3};

/// Whether a view is used for lifting/training or held out for evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    #[default]
    Train,
    Test,
}

/// Most pixels a view may have: the kernels index a frame's pixels in 32 bits.
pub const MAX_PIXELS: u64 = u32::MAX as u64;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Image name without extension (the stem), or for images whose stems repeat (multi-camera
    /// rigs) the relative image path without extension (`cam0/00001`); label maps and images
    /// are matched by it. See [`check_camera_name`].
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// World-to-camera rotation.
    pub rotation: DMat3,
    /// World-to-camera translation: x_cam = rotation * x_world + translation.
    pub translation: DVec3,
    /// Formats without splits (COLMAP, INRIA) load every view as `Train`.
    pub split: Split,
}

impl Camera {
    /// Camera center in world coordinates.
    pub fn center(&self) -> DVec3 {
        -(self.rotation.transpose() * self.translation)
    }

    pub fn world_to_camera(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    /// Projects a camera-space point to pixel coordinates (no culling).
    pub fn project_camera_point(&self, pc: DVec3) -> (f64, f64) {
        (
            self.fx * pc.x / pc.z + self.cx,
            self.fy * pc.y / pc.z + self.cy,
        )
    }

    /// The same view at `width` x `height` pixels: the intrinsics scaled per axis (pixel
    /// centers stay at +0.5 of the new grid's pixels).
    pub fn scaled_to(&self, width: u32, height: u32) -> Camera {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        Camera {
            fx: self.fx * sx,
            cx: self.cx * sx,
            fy: self.fy * sy,
            cy: self.cy * sy,
            width,
            height,
            ..self.clone()
        }
    }
}

/// How far `R^T R` may stray from the identity (per element) before a rotation is refused:
/// loose enough for poses stored as float32 text, tight enough to catch scaled or
/// transposed-by-mistake matrices.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

/// Camera names become file names (`render` writes `<out>/<name>.png`, `train --images`
/// reads `<images>/<name>.png`), so a name must be a plain file name, or, for multi-camera
/// rigs, a relative path of plain names joined by `/` (`cam0/00001`, written as
/// `<out>/cam0/00001.png`). Every component must be a plain name: not empty (so no leading
/// `/` and no `//`), not `.` or `..`, no `\`, no NUL or other control character, no drive
/// prefix (`C:`). So a name can never lead outside the folder it is joined to. Every camera
/// source validates its cameras, so this one check covers them all.
pub fn check_camera_name(name: &str) -> anyhow::Result<()> {
    let problem = if name.is_empty() {
        Some("it is empty")
    } else if name.starts_with('/') {
        Some("it is an absolute path")
    } else {
        name.split('/').find_map(name_component_problem)
    };
    match problem {
        Some(why) => anyhow::bail!(
            "camera name {name:?} cannot be used as a file name ({why}): names must be plain \
             file names, or relative paths of plain names joined by '/' (cam0/00001), because \
             outputs are written to <out>/<name>.png"
        ),
        None => Ok(()),
    }
}

/// Why one `/`-separated component of a camera name is unsafe as a path component.
fn name_component_problem(part: &str) -> Option<&'static str> {
    if part.is_empty() {
        Some("it has an empty path component")
    } else if part == "." || part == ".." {
        Some("it names a folder ('.' or '..')")
    } else if part.contains('\\') {
        Some("it contains a backslash")
    } else if part.chars().any(char::is_control) {
        Some("it contains a NUL or control character")
    } else if part.len() >= 2
        && part.as_bytes()[1] == b':'
        && part.as_bytes()[0].is_ascii_alphabetic()
    {
        Some("it starts with a drive prefix")
    } else {
        None
    }
}

impl Camera {
    /// Checks the name (see [`check_camera_name`]), positive sizes and focal lengths, finite
    /// values and a proper rotation (orthonormal, determinant +1). The error names the camera.
    pub fn validate(&self) -> anyhow::Result<()> {
        let name = &self.name;
        check_camera_name(name)?;
        if self.width == 0 || self.height == 0 {
            anyhow::bail!(
                "camera '{name}' has size {}x{}; both must be positive",
                self.width,
                self.height
            );
        }
        if self.width as u64 * self.height as u64 > MAX_PIXELS {
            anyhow::bail!(
                "camera '{name}' has size {}x{}: more than {MAX_PIXELS} pixels, which the \
                 kernels' 32-bit pixel indices cannot address",
                self.width,
                self.height
            );
        }
        for (what, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                anyhow::bail!(
                    "camera '{name}' has {what} = {v}; focal lengths must be positive and finite"
                );
            }
        }
        for (what, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                anyhow::bail!("camera '{name}' has non-finite {what} = {v}");
            }
        }
        let r = self.rotation.to_cols_array();
        let t = self.translation.to_array();
        if r.iter().chain(t.iter()).any(|v| !v.is_finite()) {
            anyhow::bail!("camera '{name}' has a non-finite rotation or translation");
        }
        let err = (self.rotation.transpose() * self.rotation - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        if err > ROTATION_TOLERANCE {
            anyhow::bail!(
                "camera '{name}' has a rotation that is not orthonormal (|R^T R - I| = {err:.2e}, \
                 over the {ROTATION_TOLERANCE:.0e} allowed): write the poses with more digits (a \
                 rotation rounded to 3 decimals is off by about 1e-3), or replace R by the nearest \
                 rotation (U V^T from its SVD U S V^T)"
            );
        }
        if self.rotation.determinant() < 0.0 {
            anyhow::bail!("camera '{name}' has a reflection (det R < 0), not a rotation");
        }
        Ok(())
    }
}

#[cfg(test)]
mod scaled_tests {
    use super::*;

    /// A point seen at (u, v) in the original image is seen at (u sx, v sy) in the scaled one:
    /// the image's edges (0 and width) stay the image's edges.
    #[test]
    fn a_scaled_camera_sees_every_point_at_the_scaled_position() {
        let cam = Camera {
            name: "c".into(),
            width: 96,
            height: 54,
            fx: 80.0,
            fy: 81.0,
            cx: 47.0,
            cy: 28.5,
            rotation: DMat3::from_rotation_y(0.3),
            translation: DVec3::new(0.1, -0.2, 0.5),
            split: Split::Train,
        };
        let big = cam.scaled_to(1920, 1080);
        assert_eq!((big.width, big.height), (1920, 1080));
        for p in [DVec3::new(0.3, 0.2, 3.0), DVec3::new(-1.0, 0.5, 5.0)] {
            let (u, v) = cam.project_camera_point(cam.world_to_camera(p));
            let (bu, bv) = big.project_camera_point(big.world_to_camera(p));
            assert!((bu - u * 20.0).abs() < 1e-9 && (bv - v * 20.0).abs() < 1e-9);
        }
    }
}
