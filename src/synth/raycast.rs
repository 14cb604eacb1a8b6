//! Ground-truth images by exact ray casting: one ray through each pixel center, first surface
//! hit, its lit texture color, class and instance. Independent of any Gaussian renderer.

use std::sync::Mutex;

use glam::DVec3;

use super::room::{Room, SurfaceHit};
use super::shading::to_rgb8;
use super::Progress;
use crate::scene::Camera;
use crate::util::parallel_map;

/// Label/instance value of pixels that see no surface (the 16-bit ignore value).
pub const IGNORE: u16 = crate::scene::labels::LabelMap::IGNORE;

/// What one view sees, row-major, `width * height` pixels.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ViewTruth {
    pub width: u32,
    pub height: u32,
    /// RGB8, 3 bytes per pixel; black where nothing is hit.
    pub rgb: Vec<u8>,
    /// Class id per pixel, `IGNORE` where nothing is hit.
    pub labels: Vec<u16>,
    /// Instance id per pixel, `IGNORE` where nothing is hit.
    pub instances: Vec<u16>,
}

impl ViewTruth {
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The image as [H, W, 3] floats in [0, 1], as training and image metrics take it.
    pub fn rgb_unit(&self) -> Vec<f32> {
        self.rgb.iter().map(|&v| v as f32 / 255.0).collect()
    }
}

/// World-space origin and (unnormalized) direction of the ray through pixel `(px, py)`'s center.
pub fn pixel_ray(cam: &Camera, px: f64, py: f64) -> (DVec3, DVec3) {
    let d_cam = DVec3::new(
        (px + 0.5 - cam.cx) / cam.fx,
        (py + 0.5 - cam.cy) / cam.fy,
        1.0,
    );
    (cam.center(), cam.rotation.transpose() * d_cam)
}

/// The first surface seen through pixel `(px, py)`.
pub fn cast_pixel(room: &Room, cam: &Camera, px: u32, py: u32) -> Option<SurfaceHit> {
    let (origin, dir) = pixel_ray(cam, px as f64, py as f64);
    room.cast(origin, dir)
}

/// Renders one view on the calling thread.
pub fn render_view(room: &Room, cam: &Camera) -> ViewTruth {
    let n = cam.width as usize * cam.height as usize;
    let mut view = ViewTruth {
        width: cam.width,
        height: cam.height,
        rgb: vec![0; 3 * n],
        labels: vec![IGNORE; n],
        instances: vec![IGNORE; n],
    };
    let origin = cam.center();
    let to_world = cam.rotation.transpose();
    for py in 0..cam.height {
        let y = (py as f64 + 0.5 - cam.cy) / cam.fy;
        for px in 0..cam.width {
            let x = (px as f64 + 0.5 - cam.cx) / cam.fx;
            let Some(hit) = room.cast(origin, to_world * DVec3::new(x, y, 1.0)) else {
                continue;
            };
            let i = py as usize * cam.width as usize + px as usize;
            let prim = &room.primitives[hit.primitive];
            view.labels[i] = prim.class_id as u16;
            view.instances[i] = prim.instance as u16;
            view.rgb[3 * i..3 * i + 3].copy_from_slice(&to_rgb8(room.color_at(
                hit.primitive,
                hit.point,
                hit.face,
            )));
        }
    }
    view
}

/// Renders all views, several at a time, in camera order; calls `progress(done, total)`
/// once per finished view.
pub fn render_views(room: &Room, cameras: &[Camera], progress: Progress) -> Vec<ViewTruth> {
    // Counted under a lock so the calls see `done` rising, whichever thread finishes first.
    let done = Mutex::new(0);
    parallel_map(cameras.len(), |i| {
        let view = render_view(room, &cameras[i]);
        if let Ok(mut done) = done.lock() {
            *done += 1;
            progress(*done, cameras.len());
        }
        view
    })
}
