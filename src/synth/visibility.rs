//! Which surface samples some camera sees. A trained 3DGS keeps only Gaussians its views
//! see: one the views never reach gets no gradient, and 3DGS's opacity reset and pruning
//! remove it. A synthetic sheet of Gaussians behind every surface would not render (the
//! surface in front hides it) but would leak into fusion through the little transmittance left
//! behind that surface, so the generator leaves such Gaussians out.

use glam::DVec3;

use super::room::Room;
use super::surface_sampling::SurfaceSample;
use crate::scene::Camera;
use crate::util::map_in_blocks;

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
    map_in_blocks(samples.len(), CHUNK, |i| {
        sample_seen(room, cameras, &samples[i])
    })
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
