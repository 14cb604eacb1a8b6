//! Building a camera from a position, a target and a field of view.

use glam::{DMat3, DVec3};

use super::camera::{Camera, Split};

impl Camera {
    /// A pinhole camera at `eye` looking at `target`, with the world's `up` pointing up in
    /// the image (our convention: x right, y down, z forward), principal point at the image
    /// center and the given horizontal field of view in degrees.
    pub fn look_at(
        name: &str,
        eye: DVec3,
        target: DVec3,
        up: DVec3,
        width: u32,
        height: u32,
        hfov_deg: f64,
    ) -> Camera {
        let z = (target - eye).normalize();
        // Looking straight along `up` leaves the roll undefined: any right vector works.
        let x = z.cross(up).try_normalize().unwrap_or(DVec3::X);
        let y = z.cross(x);
        // Rows of the world-to-camera rotation are the camera axes in world coordinates.
        let rotation = DMat3::from_cols(x, y, z).transpose();
        let fx = 0.5 * width as f64 / (0.5 * hfov_deg.to_radians()).tan();
        Camera {
            name: name.to_string(),
            width,
            height,
            fx,
            fy: fx,
            cx: 0.5 * width as f64,
            cy: 0.5 * height as f64,
            rotation,
            translation: -(rotation * eye),
            split: Split::Train,
        }
    }
}
