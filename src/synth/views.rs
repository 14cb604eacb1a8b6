//! Camera placement: views stand inside the room at eye-level heights, clear of objects and
//! walls, and look at a point on some object (classes chosen evenly, so a shelf full of books
//! does not take every view). Each view draws from its own random stream, so train views do
//! not change when the number of test views does.

use anyhow::{bail, Result};
use glam::DVec3;

use super::primitives::Aabb;
use super::room::Room;
use crate::scene::{Camera, Split};
use crate::util::Rng;

#[derive(Clone, Debug, PartialEq)]
pub struct ViewConfig {
    pub width: u32,
    pub height: u32,
    pub hfov_deg: f64,
    pub train: usize,
    pub test: usize,
}

const MIN_HEIGHT: f64 = 0.8;
const MAX_HEIGHT: f64 = 1.8;
const MIN_TARGET_DISTANCE: f64 = 0.8;
const ATTEMPTS: usize = 300;

/// Image name of a view; labels and images share it.
pub fn view_name(split: Split, index: usize) -> String {
    match split {
        Split::Train => format!("train_{index:04}"),
        Split::Test => format!("test_{index:04}"),
    }
}

/// Whether `file` (a file name) is a view's PNG as synth names them: `train_0003.png`,
/// `test_0012.png` (four digits or more). A rerun removes only such files: a user's own
/// images beside them stay.
pub fn is_view_png(file: &str) -> bool {
    let Some(stem) = file.strip_suffix(".png") else {
        return false;
    };
    let index = stem
        .strip_prefix("train_")
        .or_else(|| stem.strip_prefix("test_"));
    index.is_some_and(|i| i.len() >= 4 && i.bytes().all(|b| b.is_ascii_digit()))
}

/// `cfg.train` train views, then `cfg.test` test views.
pub fn place_cameras(room: &Room, cfg: &ViewConfig, rng: &Rng) -> Result<Vec<Camera>> {
    let targets = Targets::new(room);
    let mut cameras = Vec::with_capacity(cfg.train + cfg.test);
    for (split, count, stream) in [
        (Split::Train, cfg.train, 1u64),
        (Split::Test, cfg.test, 2u64),
    ] {
        for i in 0..count {
            let mut view_rng = rng.fork((stream << 32) | i as u64);
            let (center, target) = choose_pose(room, &targets, &mut view_rng)?;
            cameras.push(look_at(view_name(split, i), split, cfg, center, target));
        }
    }
    Ok(cameras)
}

/// A pinhole camera at `center` looking at `target` with the world's +z up in the image.
pub fn look_at(
    name: String,
    split: Split,
    cfg: &ViewConfig,
    center: DVec3,
    target: DVec3,
) -> Camera {
    let mut cam = Camera::look_at(
        &name,
        center,
        target,
        DVec3::Z,
        cfg.width,
        cfg.height,
        cfg.hfov_deg,
    );
    cam.split = split;
    cam
}

/// Objects grouped by class, with their bounds.
struct Targets {
    by_class: Vec<Vec<(u32, Aabb)>>,
}

impl Targets {
    fn new(room: &Room) -> Self {
        let mut by_class: Vec<Vec<(u32, Aabb)>> = vec![Vec::new(); room.classes.classes.len()];
        for inst in room.instances.iter().filter(|i| !i.structural) {
            by_class[inst.class_id as usize].push((inst.id, room.instance_bounds(inst.id)));
        }
        by_class.retain(|v| !v.is_empty());
        Targets { by_class }
    }

    /// An instance and a point inside its bounds (the middle 60%), or a random wall point.
    fn pick(&self, room: &Room, rng: &mut Rng) -> (Option<u32>, DVec3) {
        if self.by_class.is_empty() {
            let s = room.size();
            let p = DVec3::new(
                rng.range_f64(0.0, s.x),
                rng.range_f64(0.0, s.y),
                rng.range_f64(0.2, 0.8) * s.z,
            );
            return (None, p);
        }
        let class = &self.by_class[rng.below(self.by_class.len() as u64) as usize];
        let (id, b) = class[rng.below(class.len() as u64) as usize];
        let t = DVec3::new(
            rng.range_f64(0.2, 0.8),
            rng.range_f64(0.2, 0.8),
            rng.range_f64(0.2, 0.8),
        );
        (Some(id), b.min + t * (b.max - b.min))
    }
}

/// A camera center and look-at target; prefers targets visible from the center.
fn choose_pose(room: &Room, targets: &Targets, rng: &mut Rng) -> Result<(DVec3, DVec3)> {
    let s = room.size();
    let top = (s.z - 0.3).min(MAX_HEIGHT).max(MIN_HEIGHT.min(0.5 * s.z));
    let bottom = MIN_HEIGHT.min(top);
    // Small rooms cannot keep the usual distance to what a view looks at.
    let min_distance = MIN_TARGET_DISTANCE.min(0.4 * s.x.min(s.y));
    let mut fallback = None;
    for attempt in 0..ATTEMPTS {
        // Cluttered rooms relax the clearance before giving up.
        let clearance = if attempt < ATTEMPTS / 2 { 0.35 } else { 0.12 };
        let center = DVec3::new(
            rng.range_f64(0.0, s.x),
            rng.range_f64(0.0, s.y),
            if top > bottom {
                rng.range_f64(bottom, top)
            } else {
                bottom
            },
        );
        let (instance, target) = targets.pick(room, rng);
        if !room.is_free(center, clearance) {
            continue;
        }
        let to_target = target - center;
        if to_target.length() < min_distance || to_target.normalize().z.abs() > 0.9 {
            continue;
        }
        let visible = match (instance, room.cast(center, to_target)) {
            (Some(id), Some(hit)) => room.primitives[hit.primitive].instance == id,
            (None, _) => true,
            (Some(_), None) => false,
        };
        if visible {
            return Ok((center, target));
        }
        fallback.get_or_insert((center, target));
    }
    match fallback {
        Some(pose) => Ok(pose),
        None => bail!(
            "could not place a camera: no free spot found in the room (too small or too cluttered)"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::presets::preset;

    /// Only the names synth gives views are its own.
    #[test]
    fn view_pngs_are_the_names_synth_gives() {
        for ours in [
            "train_0000.png",
            "test_0012.png",
            "train_12345.png",
            &view_name(Split::Test, 3),
        ] {
            let name = if ours.ends_with(".png") {
                ours.to_string()
            } else {
                format!("{ours}.png")
            };
            assert!(is_view_png(&name), "{name}");
        }
        for theirs in [
            "IMG_0001.png",
            "train_01.png",
            "train_0001.jpg",
            "train_000a.png",
            "photo.png",
        ] {
            assert!(!is_view_png(theirs), "{theirs}");
        }
    }

    #[test]
    fn look_at_centers_the_target_with_z_up() {
        let cfg = ViewConfig {
            width: 64,
            height: 48,
            hfov_deg: 60.0,
            train: 1,
            test: 0,
        };
        let cam = look_at(
            "v".into(),
            Split::Train,
            &cfg,
            DVec3::new(1.0, 1.0, 1.5),
            DVec3::new(3.0, 1.0, 1.5),
        );
        let pc = cam.world_to_camera(DVec3::new(3.0, 1.0, 1.5));
        assert!((pc.z - 2.0).abs() < 1e-12 && pc.x.abs() < 1e-12 && pc.y.abs() < 1e-12);
        // A point above the target appears above the image center (smaller v).
        let (_, v) = cam.project_camera_point(cam.world_to_camera(DVec3::new(3.0, 1.0, 2.0)));
        assert!(v < cam.cy);
        // A point to the left (looking along +x, left is +y) has smaller u.
        let (u, _) = cam.project_camera_point(cam.world_to_camera(DVec3::new(3.0, 1.5, 1.5)));
        assert!(u < cam.cx);
        assert!((cam.rotation.determinant() - 1.0).abs() < 1e-12);
        assert!((cam.center() - DVec3::new(1.0, 1.0, 1.5)).length() < 1e-12);
    }

    #[test]
    fn cameras_are_free_inside_and_deterministic() {
        let room = Room::build(preset("living", 2).unwrap()).unwrap();
        let cfg = ViewConfig {
            width: 64,
            height: 48,
            hfov_deg: 65.0,
            train: 12,
            test: 4,
        };
        let cams = place_cameras(&room, &cfg, &Rng::new(7)).unwrap();
        assert_eq!(cams.len(), 16);
        assert_eq!(cams.iter().filter(|c| c.split == Split::Test).count(), 4);
        for c in &cams {
            assert!(
                room.is_free(c.center(), 0.1),
                "{} at {}",
                c.name,
                c.center()
            );
            let z = c.center().z;
            assert!((MIN_HEIGHT..=MAX_HEIGHT).contains(&z));
        }
        assert_eq!(cams, place_cameras(&room, &cfg, &Rng::new(7)).unwrap());
        let more_tests = ViewConfig {
            test: 6,
            ..cfg.clone()
        };
        assert_eq!(
            cams[..12],
            place_cameras(&room, &more_tests, &Rng::new(7)).unwrap()[..12]
        );
    }
}
