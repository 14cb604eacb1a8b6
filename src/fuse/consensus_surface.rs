//! Segment consensus, the surfaces: which neighbour pairs lie along one surface and which
//! across a crease, from the Gaussians' shapes. The clustering takes the joins along a
//! surface before those across a crease (src/fuse/consensus_cluster.rs).
//!
//! Why: the views' regions cannot tell a strip of ceiling that only views calling the
//! ceiling wall saw from the wall (every view that saw both put them in one region), and
//! such a strip's pairs with the wall are as strong as its pairs with the rest of the
//! ceiling. Taken in the order of evidence alone, the wall took it, strip by strip (12-14%
//! of the office's ceiling on two of three flicker runs, docs/robustness-log.md, "Joins along a
//! surface first"). The shapes say the strip continues the ceiling: a flat
//! Gaussian's shortest axis is its surface's normal, and a ceiling's normals turn by 90
//! degrees at the wall. Joined to the ceiling first, the strip is then tested as part of
//! the ceiling against the wall, on every view that saw both.

use glam::{Quat, Vec3};

use super::consensus_decide::ConsensusParams;
use super::consensus_order::SpatialOrder;
use crate::scene::Gaussians;
use crate::util::map_in_blocks;

/// The Gaussians' shapes, as the scene lists them: what the consensus reads of the
/// geometry (centers for the neighbour graph, scales and rotations for the surfaces).
#[derive(Clone, Copy, Debug)]
pub struct GaussianShapes<'a> {
    pub means: &'a [[f32; 3]],
    pub log_scales: &'a [[f32; 3]],
    /// w x y z.
    pub quats: &'a [[f32; 4]],
}

impl<'a> GaussianShapes<'a> {
    pub fn of(g: &'a Gaussians) -> GaussianShapes<'a> {
        GaussianShapes {
            means: &g.means,
            log_scales: &g.log_scales,
            quats: &g.quats,
        }
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }
}

/// Per Gaussian (numbered in space), the normal of the surface it lies on where it is flat
/// (its middle scale at least `flat_ratio` times its smallest), else none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceNormals {
    /// Unit normals; [0, 0, 0] for a Gaussian that is not flat. Empty: none known.
    normals: Vec<[f32; 3]>,
    /// Two normals further apart than this angle make a crease: |cos| under it.
    crease_cos: f32,
}

impl SurfaceNormals {
    /// None known: every pair lies along a surface (the order of evidence alone).
    pub fn none() -> SurfaceNormals {
        SurfaceNormals::default()
    }

    /// The normals of `shapes`' flat Gaussians, listed in `order`'s numbering.
    pub fn of(shapes: &GaussianShapes, order: &SpatialOrder, p: &ConsensusParams) -> Self {
        assert_eq!(order.len(), shapes.len(), "a number per Gaussian");
        const BLOCK: usize = 1 << 14;
        let normals = map_in_blocks(shapes.len(), BLOCK, |s| {
            let g = order.scene(s as u32) as usize;
            flat_normal(shapes.log_scales[g], shapes.quats[g], p.flat_ratio).unwrap_or([0.0; 3])
        });
        SurfaceNormals::from_normals(normals, p.crease_degrees)
    }

    /// From unit normals ([0, 0, 0]: not flat) by number; a crease angle of 90 degrees or
    /// more: no creases.
    pub fn from_normals(normals: Vec<[f32; 3]>, crease_degrees: f64) -> Self {
        let crease_cos = match crease_degrees < 90.0 {
            true => crease_degrees.to_radians().cos() as f32,
            false => -1.0, // |cos| is never under it
        };
        SurfaceNormals {
            normals,
            crease_cos,
        }
    }

    /// The normal of Gaussian `s` (by number), where it is flat.
    pub fn normal(&self, s: usize) -> Option<[f32; 3]> {
        self.normals.get(s).copied().filter(|n| n != &[0.0; 3])
    }

    /// Whether Gaussians `g` and `h` lie along one surface: not both flat with normals more
    /// than the crease angle apart (a Gaussian that is not flat has no normal to differ by).
    pub fn along(&self, g: usize, h: usize) -> bool {
        let (Some(a), Some(b)) = (self.normals.get(g), self.normals.get(h)) else {
            return true;
        };
        let cos = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs();
        let flat = |n: &[f32; 3]| n != &[0.0; 3];
        !(flat(a) && flat(b) && cos < self.crease_cos)
    }
}

/// The unit normal of a Gaussian (its shortest axis in the world) where its middle scale
/// is at least `flat_ratio` times its shortest, else none (a round or needle-like Gaussian
/// has no one surface direction). A zero quaternion: none.
pub fn flat_normal(log_scales: [f32; 3], quat: [f32; 4], flat_ratio: f64) -> Option<[f32; 3]> {
    let mut axes = [0usize, 1, 2];
    axes.sort_by(|&i, &j| log_scales[i].total_cmp(&log_scales[j]));
    let spread = (log_scales[axes[1]] - log_scales[axes[0]]) as f64;
    if spread.is_nan() || spread < flat_ratio.ln() {
        return None;
    }
    let [w, x, y, z] = quat;
    let rotation = Quat::from_xyzw(x, y, z, w);
    let length = rotation.length();
    if length.is_nan() || length <= 0.0 {
        return None;
    }
    // That local axis in the world.
    Some((rotation / length).mul_vec3(Vec3::AXES[axes[0]]).to_array())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quaternion rotating by `angle` about the unit `axis`.
    fn about(axis: [f32; 3], angle: f32) -> [f32; 4] {
        let (s, c) = (angle / 2.0).sin_cos();
        [c, axis[0] * s, axis[1] * s, axis[2] * s]
    }

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        (0..3).all(|i| (a[i] - b[i]).abs() < 1e-6)
    }

    #[test]
    fn the_normal_is_the_shortest_axis_rotated() {
        let flat_z = [0.0, 0.0, -3.0];
        assert!(close(
            flat_normal(flat_z, [1.0, 0.0, 0.0, 0.0], 2.0).unwrap(),
            [0.0, 0.0, 1.0]
        ));
        // A quarter turn about x takes z to -y; about z, x to y.
        let quarter = std::f32::consts::FRAC_PI_2;
        let n = flat_normal(flat_z, about([1.0, 0.0, 0.0], quarter), 2.0).unwrap();
        assert!(close(n, [0.0, -1.0, 0.0]), "{n:?}");
        let flat_x = [-3.0, 0.0, 0.0];
        let n = flat_normal(flat_x, about([0.0, 0.0, 1.0], quarter), 2.0).unwrap();
        assert!(close(n, [0.0, 1.0, 0.0]), "{n:?}");
        // Unnormalized quaternions are normalized.
        let n = flat_normal(flat_z, [2.0, 0.0, 0.0, 0.0], 2.0).unwrap();
        assert!(close(n, [0.0, 0.0, 1.0]));
    }

    #[test]
    fn only_flat_gaussians_have_a_normal() {
        let q = [1.0, 0.0, 0.0, 0.0];
        assert!(flat_normal([0.0, 0.0, 0.0], q, 2.0).is_none(), "round");
        // Middle scale 1.9x the smallest: not flat at 2, flat at 1.5.
        let ln = 1.9f32.ln();
        assert!(flat_normal([ln, ln, 0.0], q, 2.0).is_none());
        assert!(flat_normal([ln, ln, 0.0], q, 1.5).is_some());
        // A needle (one long axis, two short) is not flat.
        assert!(flat_normal([3.0, 0.0, 0.0], q, 2.0).is_none());
        assert!(
            flat_normal([0.0, 0.0, -3.0], [0.0; 4], 2.0).is_none(),
            "zero rotation"
        );
    }

    #[test]
    fn creases_need_two_flat_gaussians_at_an_angle() {
        let ceiling = [0.0, 0.0, 1.0];
        let wall = [1.0, 0.0, 0.0];
        let tilted = [0.0, (40f32).to_radians().sin(), (40f32).to_radians().cos()];
        let normals = vec![ceiling, wall, tilted, [0.0; 3], [0.0, 0.0, -1.0]];
        let s = SurfaceNormals::from_normals(normals, 60.0);
        assert!(!s.along(0, 1), "90 degrees");
        assert!(s.along(0, 2), "40 degrees");
        assert!(s.along(0, 3) && s.along(3, 1), "a round Gaussian");
        assert!(s.along(0, 4), "the other side of the same plane");
        assert!(SurfaceNormals::none().along(0, 1));
        let off = SurfaceNormals::from_normals(vec![ceiling, wall], 90.0);
        assert!(off.along(0, 1), "no creases at 90 degrees");
    }
}
