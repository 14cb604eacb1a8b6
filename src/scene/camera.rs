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

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Image name without extension; label maps and images are matched by this stem.
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
        (self.fx * pc.x / pc.z + self.cx, self.fy * pc.y / pc.z + self.cy)
    }
}
