//! Which surface samples some camera sees. A trained 3DGS keeps only Gaussians its views
//! see: one the views never reach gets no gradient, and 3DGS's opacity reset and pruning
//! remove it. A synthetic sheet of Gaussians behind every surface would not render (the
//! surface in front hides it) but would leak into fusion through the ~1% transmittance left
//! behind that surface, so the generator leaves such Gaussians out.

use std::sync::Mutex;

use glam::DVec3;

use super::room::Room;
use super::surface_sampling::SurfaceSample;
use crate::scene::Camera;

/// Nearest depth a camera sees (meters).
const NEAR: f64 = 0.01;
/// A probe point counts as seen when the first surface on its ray is within this distance
/// of it (meters): ray casting against the analytic surface the point lies on.
const HIT_TOLERANCE: f64 = 0.005;
/// Samples per work item of the parallel loop.
const CHUNK: usize = 1024;

/// For each sample: whether some camera sees its center or a point one standard deviation
/// out along either in-plane axis (so a Gaussian half hidden behind an occluder stays).
pub fn seen_by_any(room: &Room, cameras: &[Camera], samples: &[SurfaceSample]) -> Vec<bool> {
    let mut seen = vec![false; samples.len()];
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    // A queue of chunks: hidden samples cost every camera and probe, so even splits would not balance.
    let queue = Mutex::new(seen.chunks_mut(CHUNK).enumerate().collect::<Vec<_>>());
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let item = queue.lock().unwrap_or_else(|e| e.into_inner()).pop();
                let Some((k, out)) = item else { break };
                for (j, flag) in out.iter_mut().enumerate() {
                    *flag = sample_seen(room, cameras, &samples[k * CHUNK + j]);
                }
            });
        }
    });
    seen
}

fn sample_seen(room: &Room, cameras: &[Camera], s: &SurfaceSample) -> bool {
    let (su, sv, _) = s.sigmas();
    let probes = [
        s.position,
        s.position + s.tangent_u * su,
        s.position - s.tangent_u * su,
        s.position + s.tangent_v * sv,
        s.position - s.tangent_v * sv,
    ];
    probes
        .iter()
        .any(|&p| cameras.iter().any(|cam| point_seen(room, cam, p)))
}

/// Whether `p` is in `cam`'s image and the first surface on the ray to it.
pub fn point_seen(room: &Room, cam: &Camera, p: DVec3) -> bool {
    let pc = cam.world_to_camera(p);
    if pc.z <= NEAR {
        return false;
    }
    let (u, v) = cam.project_camera_point(pc);
    if !(0.0..cam.width as f64).contains(&u) || !(0.0..cam.height as f64).contains(&v) {
        return false;
    }
    let origin = cam.center();
    let to_p = p - origin;
    let dist = to_p.length();
    room.cast(origin, to_p / dist)
        .is_some_and(|hit| hit.t > dist - HIT_TOLERANCE)
}
