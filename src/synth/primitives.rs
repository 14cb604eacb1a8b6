//! Analytic primitives the rooms are built from: bounded planes (quads), oriented boxes,
//! capped cylinders and spheres. Each answers ray intersection (nearest hit, from outside or
//! inside), signed distance, bounds, and the surface frame/coordinates textures use, so ray-cast
//! ground truth and surface samples evaluate the very same functions.

use glam::{DMat3, DVec2, DVec3};

/// Which face of a primitive a point lies on; selects the outward normal and texture coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    Quad,
    /// Box face `2 * axis + (0 for +, 1 for -)` in the box's local frame.
    Box(u8),
    CylinderSide,
    CylinderTop,
    CylinderBottom,
    Sphere,
}

/// A ray-surface intersection: distance along the (unit) direction, face and outward normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeHit {
    pub t: f64,
    pub face: Face,
    /// Outward normal of the surface (for quads: the quad's own normal, whichever side is hit).
    pub normal: DVec3,
}

/// Axis-aligned bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: DVec3,
    pub max: DVec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: DVec3::INFINITY,
        max: DVec3::NEG_INFINITY,
    };

    pub fn union(self, other: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    pub fn center(&self) -> DVec3 {
        0.5 * (self.min + self.max)
    }

    pub fn contains(&self, p: DVec3, margin: f64) -> bool {
        p.cmpge(self.min - margin).all() && p.cmple(self.max + margin).all()
    }

    /// Entry distance of a ray (given `1 / dir`) if it meets the box within `[0, t_max]`.
    pub fn ray_entry(&self, origin: DVec3, inv_dir: DVec3, t_max: f64) -> Option<f64> {
        let t0 = (self.min - origin) * inv_dir;
        let t1 = (self.max - origin) * inv_dir;
        // min/max ignore the NaN of 0 * inf (a ray lying in a slab plane), treating it as no constraint.
        let near = t0.min(t1).max_element().max(0.0);
        let far = t0.max(t1).min_element().min(t_max);
        (near <= far).then_some(near)
    }
}

/// A rectangle: `center + a * u + b * v` for `|a| <= half.x`, `|b| <= half.y`; normal `u x v`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quad {
    pub center: DVec3,
    pub u: DVec3,
    pub v: DVec3,
    pub half: DVec2,
}

/// A box with half extents `half` along the columns of `rot` (local-to-world rotation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientedBox {
    pub center: DVec3,
    pub half: DVec3,
    pub rot: DMat3,
}

/// A capped cylinder around the local z axis (`rot`'s third column), centered at `center`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cylinder {
    pub center: DVec3,
    pub radius: f64,
    pub half_height: f64,
    pub rot: DMat3,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: DVec3,
    pub radius: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    Quad(Quad),
    Box(OrientedBox),
    Cylinder(Cylinder),
    Sphere(Sphere),
}

/// A rotation whose third column is `axis` (unit); the first column is horizontal when it can be.
pub fn frame_with_z_axis(axis: DVec3) -> DMat3 {
    let z = axis.normalize();
    let x = if z.z.abs() < 0.999 {
        DVec3::Z.cross(z).normalize()
    } else {
        DVec3::X
    };
    DMat3::from_cols(x, z.cross(x), z)
}

impl Quad {
    pub fn normal(&self) -> DVec3 {
        self.u.cross(self.v)
    }

    fn local(&self, p: DVec3) -> DVec3 {
        let d = p - self.center;
        DVec3::new(d.dot(self.u), d.dot(self.v), d.dot(self.normal()))
    }

    fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64, t_max: f64) -> Option<ShapeHit> {
        let n = self.normal();
        let denom = dir.dot(n);
        if denom.abs() < 1e-12 {
            return None;
        }
        let t = (self.center - origin).dot(n) / denom;
        if !(t > t_min && t < t_max) {
            return None;
        }
        let l = self.local(origin + t * dir);
        (l.x.abs() <= self.half.x && l.y.abs() <= self.half.y).then_some(ShapeHit {
            t,
            face: Face::Quad,
            normal: n,
        })
    }
}

impl OrientedBox {
    fn local(&self, p: DVec3) -> DVec3 {
        self.rot.transpose() * (p - self.center)
    }

    fn face_normal_local(face: u8) -> DVec3 {
        let axis = (face / 2) as usize;
        let mut n = DVec3::ZERO;
        n[axis] = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
        n
    }

    fn face_id(axis: usize, positive: bool) -> u8 {
        (2 * axis + usize::from(!positive)) as u8
    }

    fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64, t_max: f64) -> Option<ShapeHit> {
        let o = self.local(origin);
        let d = self.rot.transpose() * dir;
        let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
        let (mut near_axis, mut far_axis) = (0, 0);
        for a in 0..3 {
            let inv = 1.0 / d[a];
            let ta = (-self.half[a] - o[a]) * inv;
            let tb = (self.half[a] - o[a]) * inv;
            let (lo, hi) = if ta <= tb { (ta, tb) } else { (tb, ta) };
            if lo > near {
                near = lo;
                near_axis = a;
            }
            if hi < far {
                far = hi;
                far_axis = a;
            }
        }
        if near > far {
            return None;
        }
        // Entering face: the side the ray comes from; leaving face (origin inside): the side it goes to.
        let (t, face) = if near > t_min && near < t_max {
            (near, Self::face_id(near_axis, d[near_axis] < 0.0))
        } else if far > t_min && far < t_max {
            (far, Self::face_id(far_axis, d[far_axis] > 0.0))
        } else {
            return None;
        };
        Some(ShapeHit {
            t,
            face: Face::Box(face),
            normal: self.rot * Self::face_normal_local(face),
        })
    }

    fn sdf(&self, p: DVec3) -> f64 {
        let q = self.local(p).abs() - self.half;
        q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
    }
}

impl Cylinder {
    fn local(&self, p: DVec3) -> DVec3 {
        self.rot.transpose() * (p - self.center)
    }

    fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64, t_max: f64) -> Option<ShapeHit> {
        let o = self.local(origin);
        let d = self.rot.transpose() * dir;
        let mut best: Option<(f64, Face)> = None;
        let mut consider = |t: f64, face: Face| {
            if t > t_min && t < t_max && best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, face));
            }
        };
        let a = d.x * d.x + d.y * d.y;
        if a > 1e-18 {
            let b = o.x * d.x + o.y * d.y;
            let c = o.x * o.x + o.y * o.y - self.radius * self.radius;
            let disc = b * b - a * c;
            if disc >= 0.0 {
                let s = disc.sqrt();
                for t in [(-b - s) / a, (-b + s) / a] {
                    if (o.z + t * d.z).abs() <= self.half_height {
                        consider(t, Face::CylinderSide);
                    }
                }
            }
        }
        if d.z.abs() > 1e-18 {
            for (z, face) in [
                (self.half_height, Face::CylinderTop),
                (-self.half_height, Face::CylinderBottom),
            ] {
                let t = (z - o.z) / d.z;
                let (x, y) = (o.x + t * d.x, o.y + t * d.y);
                if x * x + y * y <= self.radius * self.radius {
                    consider(t, face);
                }
            }
        }
        let (t, face) = best?;
        let local_hit = o + t * d;
        Some(ShapeHit {
            t,
            face,
            normal: self.normal_local(local_hit, face),
        })
    }

    fn normal_local(&self, local: DVec3, face: Face) -> DVec3 {
        let n = match face {
            Face::CylinderTop => DVec3::Z,
            Face::CylinderBottom => DVec3::NEG_Z,
            _ => DVec3::new(local.x, local.y, 0.0)
                .try_normalize()
                .unwrap_or(DVec3::X),
        };
        self.rot * n
    }

    fn sdf(&self, p: DVec3) -> f64 {
        let l = self.local(p);
        let d = DVec2::new(
            l.truncate().length() - self.radius,
            l.z.abs() - self.half_height,
        );
        d.max_element().min(0.0) + d.max(DVec2::ZERO).length()
    }
}

impl Sphere {
    fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64, t_max: f64) -> Option<ShapeHit> {
        let oc = origin - self.center;
        let a = dir.length_squared();
        let b = oc.dot(dir);
        let c = oc.length_squared() - self.radius * self.radius;
        let disc = b * b - a * c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        let t = [(-b - s) / a, (-b + s) / a]
            .into_iter()
            .find(|&t| t > t_min && t < t_max)?;
        let normal = (origin + t * dir - self.center) / self.radius;
        Some(ShapeHit {
            t,
            face: Face::Sphere,
            normal,
        })
    }
}

impl Shape {
    /// Nearest intersection with `t` in `(t_min, t_max)`; from inside a solid, the exit point.
    pub fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64, t_max: f64) -> Option<ShapeHit> {
        match self {
            Shape::Quad(q) => q.intersect(origin, dir, t_min, t_max),
            Shape::Box(b) => b.intersect(origin, dir, t_min, t_max),
            Shape::Cylinder(c) => c.intersect(origin, dir, t_min, t_max),
            Shape::Sphere(s) => s.intersect(origin, dir, t_min, t_max),
        }
    }

    /// Signed distance to the surface, negative inside. Quads have no inside (always >= 0).
    pub fn sdf(&self, p: DVec3) -> f64 {
        match self {
            Shape::Quad(q) => {
                let l = q.local(p);
                let dx = (l.x.abs() - q.half.x).max(0.0);
                let dy = (l.y.abs() - q.half.y).max(0.0);
                (dx * dx + dy * dy + l.z * l.z).sqrt()
            }
            Shape::Box(b) => b.sdf(p),
            Shape::Cylinder(c) => c.sdf(p),
            Shape::Sphere(s) => (p - s.center).length() - s.radius,
        }
    }

    pub fn aabb(&self) -> Aabb {
        let (center, extent) = match self {
            Shape::Quad(q) => (q.center, q.u.abs() * q.half.x + q.v.abs() * q.half.y),
            Shape::Box(b) => {
                let abs =
                    DMat3::from_cols(b.rot.x_axis.abs(), b.rot.y_axis.abs(), b.rot.z_axis.abs());
                (b.center, abs * b.half)
            }
            Shape::Cylinder(c) => {
                let a = c.rot.z_axis;
                let radial = (DVec3::ONE - a * a)
                    .max(DVec3::ZERO)
                    .to_array()
                    .map(f64::sqrt);
                (
                    c.center,
                    a.abs() * c.half_height + DVec3::from_array(radial) * c.radius,
                )
            }
            Shape::Sphere(s) => (s.center, DVec3::splat(s.radius)),
        };
        Aabb {
            min: center - extent,
            max: center + extent,
        }
    }

    /// The point in the primitive's own frame (textures move with the object).
    pub fn local_point(&self, p: DVec3) -> DVec3 {
        match self {
            Shape::Quad(q) => q.local(p),
            Shape::Box(b) => b.local(p),
            Shape::Cylinder(c) => c.local(p),
            Shape::Sphere(s) => p - s.center,
        }
    }

    /// 2D surface coordinates (meters) on `face`, for patterns like tiles and planks.
    pub fn surface_uv(&self, p: DVec3, face: Face) -> DVec2 {
        let l = self.local_point(p);
        match (self, face) {
            // Vertical faces keep "up" as v so wall-like patterns run horizontally.
            (Shape::Box(_), Face::Box(f)) => match f / 2 {
                0 => DVec2::new(l.y, l.z),
                1 => DVec2::new(l.x, l.z),
                _ => DVec2::new(l.x, l.y),
            },
            (Shape::Cylinder(c), Face::CylinderSide) => DVec2::new(l.y.atan2(l.x) * c.radius, l.z),
            (Shape::Sphere(s), _) => DVec2::new(l.y.atan2(l.x) * s.radius, l.z),
            _ => l.truncate(),
        }
    }

    /// Outward unit normal on `face` at surface point `p`.
    pub fn normal(&self, p: DVec3, face: Face) -> DVec3 {
        match (self, face) {
            (Shape::Quad(q), _) => q.normal(),
            (Shape::Box(b), Face::Box(f)) => b.rot * OrientedBox::face_normal_local(f),
            (Shape::Cylinder(c), f) => c.normal_local(c.local(p), f),
            (Shape::Sphere(s), _) => (p - s.center).try_normalize().unwrap_or(DVec3::Z),
            (Shape::Box(b), _) => b.rot * OrientedBox::face_normal_local(nearest_box_face(b, p)),
        }
    }

    /// The face whose surface is nearest to `p` (for points sampled on the surface).
    pub fn nearest_face(&self, p: DVec3) -> Face {
        match self {
            Shape::Quad(_) => Face::Quad,
            Shape::Box(b) => Face::Box(nearest_box_face(b, p)),
            Shape::Cylinder(c) => {
                let l = c.local(p);
                let side = (l.truncate().length() - c.radius).abs();
                let cap = (l.z.abs() - c.half_height).abs();
                if side <= cap {
                    Face::CylinderSide
                } else if l.z > 0.0 {
                    Face::CylinderTop
                } else {
                    Face::CylinderBottom
                }
            }
            Shape::Sphere(_) => Face::Sphere,
        }
    }
}

fn nearest_box_face(b: &OrientedBox, p: DVec3) -> u8 {
    let l = b.local(p);
    let gap = (l.abs() - b.half).abs();
    let axis = if gap.x <= gap.y && gap.x <= gap.z {
        0
    } else if gap.y <= gap.z {
        1
    } else {
        2
    };
    OrientedBox::face_id(axis, l[axis] >= 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const EPS: f64 = 1e-9;

    fn yawed_box(center: DVec3, size: DVec3, yaw_deg: f64) -> Shape {
        Shape::Box(OrientedBox {
            center,
            half: 0.5 * size,
            rot: DMat3::from_rotation_z(yaw_deg.to_radians()),
        })
    }

    fn cylinder(center: DVec3, radius: f64, height: f64, axis: DVec3) -> Shape {
        Shape::Cylinder(Cylinder {
            center,
            radius,
            half_height: 0.5 * height,
            rot: frame_with_z_axis(axis),
        })
    }

    fn hit(shape: &Shape, origin: DVec3, dir: DVec3) -> Option<ShapeHit> {
        shape.intersect(origin, dir, EPS, f64::INFINITY)
    }

    #[test]
    fn quad_hits_inside_its_bounds_from_both_sides() {
        let q = Shape::Quad(Quad {
            center: DVec3::new(0.0, 0.0, 1.0),
            u: DVec3::X,
            v: DVec3::Y,
            half: DVec2::new(1.0, 0.5),
        });
        let h = hit(&q, DVec3::new(0.5, 0.2, 3.0), DVec3::NEG_Z).unwrap();
        assert!((h.t - 2.0).abs() < 1e-12 && h.normal == DVec3::Z && h.face == Face::Quad);
        let h = hit(&q, DVec3::new(0.5, 0.2, -1.0), DVec3::Z).unwrap();
        assert!((h.t - 2.0).abs() < 1e-12, "back side hits too");
        assert!(
            hit(&q, DVec3::new(0.5, 0.6, 3.0), DVec3::NEG_Z).is_none(),
            "outside v extent"
        );
        assert!(
            hit(&q, DVec3::new(0.0, 0.0, 3.0), DVec3::X).is_none(),
            "parallel ray"
        );
        assert!(
            hit(&q, DVec3::new(0.0, 0.0, 3.0), DVec3::Z).is_none(),
            "behind the origin"
        );
        assert!(
            q.intersect(DVec3::new(0.0, 0.0, 3.0), DVec3::NEG_Z, EPS, 1.5)
                .is_none(),
            "beyond t_max"
        );
    }

    #[test]
    fn box_entry_face_normal_and_exit_from_inside() {
        let b = yawed_box(DVec3::new(1.0, 2.0, 0.5), DVec3::new(2.0, 1.0, 1.0), 0.0);
        // From -x: enters the -x face at x = 0.
        let h = hit(&b, DVec3::new(-3.0, 2.2, 0.6), DVec3::X).unwrap();
        assert!((h.t - 3.0).abs() < 1e-12);
        assert_eq!(h.face, Face::Box(1));
        assert_eq!(h.normal, DVec3::NEG_X);
        // From above onto the top face.
        let h = hit(&b, DVec3::new(1.5, 2.1, 5.0), DVec3::NEG_Z).unwrap();
        assert!((h.t - 4.0).abs() < 1e-12 && h.normal == DVec3::Z);
        // From inside: the exit point, with the outward normal of the exit face.
        let h = hit(&b, DVec3::new(1.0, 2.0, 0.5), DVec3::Y).unwrap();
        assert!((h.t - 0.5).abs() < 1e-12 && h.normal == DVec3::Y);
        // Misses: beside the box, and pointing away.
        assert!(hit(&b, DVec3::new(-3.0, 3.0, 0.5), DVec3::X).is_none());
        assert!(hit(&b, DVec3::new(-3.0, 2.0, 0.5), DVec3::NEG_X).is_none());
        // Axis-parallel ray lying outside a slab: no NaN-induced hit.
        assert!(hit(&b, DVec3::new(-3.0, 2.5 + 1e-3, 0.5), DVec3::X).is_none());
    }

    #[test]
    fn rotated_box_uses_its_own_axes() {
        let b = yawed_box(DVec3::ZERO, DVec3::new(2.0, 0.2, 1.0), 90.0);
        // Turned 90 degrees: the long side now runs along y.
        assert!(hit(&b, DVec3::new(-5.0, 0.9, 0.0), DVec3::X).is_some());
        assert!(hit(&b, DVec3::new(0.5, -5.0, 0.0), DVec3::Y).is_none());
        let h = hit(&b, DVec3::new(-5.0, 0.0, 0.0), DVec3::X).unwrap();
        assert!((h.t - 4.9).abs() < 1e-9 && (h.normal - DVec3::NEG_X).length() < 1e-12);
        assert!((b.sdf(DVec3::new(0.0, 1.5, 0.0)) - 0.5).abs() < 1e-9);
        assert!(b.sdf(DVec3::ZERO) < 0.0);
    }

    #[test]
    fn cylinder_side_caps_inside_and_tilted_axis() {
        let c = cylinder(DVec3::new(0.0, 0.0, 1.0), 0.5, 2.0, DVec3::Z);
        let h = hit(&c, DVec3::new(-3.0, 0.0, 1.0), DVec3::X).unwrap();
        assert!(
            (h.t - 2.5).abs() < 1e-12
                && h.face == Face::CylinderSide
                && (h.normal - DVec3::NEG_X).length() < 1e-12
        );
        let h = hit(&c, DVec3::new(0.2, 0.1, 5.0), DVec3::NEG_Z).unwrap();
        assert!((h.t - 3.0).abs() < 1e-12 && h.face == Face::CylinderTop && h.normal == DVec3::Z);
        let h = hit(&c, DVec3::new(0.2, 0.1, -1.0), DVec3::Z).unwrap();
        assert!((h.t - 1.0).abs() < 1e-12 && h.face == Face::CylinderBottom);
        // Past the top edge: misses the side, and the cap too.
        assert!(hit(&c, DVec3::new(-3.0, 0.0, 2.1), DVec3::X).is_none());
        // Grazing outside the radius.
        assert!(hit(&c, DVec3::new(-3.0, 0.51, 1.0), DVec3::X).is_none());
        // From inside: exits through the side.
        let h = hit(&c, DVec3::new(0.0, 0.0, 1.0), DVec3::Y).unwrap();
        assert!((h.t - 0.5).abs() < 1e-12 && (h.normal - DVec3::Y).length() < 1e-12);
        // A horizontal cylinder along x: its caps face +-x.
        let rod = cylinder(DVec3::ZERO, 0.1, 2.0, DVec3::X);
        let h = hit(&rod, DVec3::new(-5.0, 0.0, 0.05), DVec3::X).unwrap();
        assert!((h.t - 4.0).abs() < 1e-12 && (h.normal - DVec3::NEG_X).length() < 1e-12);
        assert!(hit(&rod, DVec3::new(0.5, 0.0, 5.0), DVec3::NEG_Z)
            .is_some_and(|h| (h.t - 4.9).abs() < 1e-12));
        assert!((c.sdf(DVec3::new(1.5, 0.0, 1.0)) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn sphere_near_and_far_roots() {
        let s = Shape::Sphere(Sphere {
            center: DVec3::new(0.0, 0.0, 2.0),
            radius: 1.0,
        });
        let h = hit(&s, DVec3::ZERO, DVec3::Z).unwrap();
        assert!((h.t - 1.0).abs() < 1e-12 && (h.normal - DVec3::NEG_Z).length() < 1e-12);
        let h = hit(&s, DVec3::new(0.0, 0.0, 2.0), DVec3::X).unwrap();
        assert!(
            (h.t - 1.0).abs() < 1e-12 && (h.normal - DVec3::X).length() < 1e-12,
            "from inside"
        );
        assert!(hit(&s, DVec3::new(1.01, 0.0, 0.0), DVec3::Z).is_none());
        assert!(hit(&s, DVec3::ZERO, DVec3::NEG_Z).is_none());
        // Unnormalized directions give t in units of |dir|.
        assert!((hit(&s, DVec3::ZERO, DVec3::new(0.0, 0.0, 2.0)).unwrap().t - 0.5).abs() < 1e-12);
    }

    #[test]
    fn nearest_of_several_primitives_wins() {
        let shapes = [
            Shape::Sphere(Sphere {
                center: DVec3::new(5.0, 0.0, 0.0),
                radius: 1.0,
            }),
            yawed_box(DVec3::new(2.0, 0.0, 0.0), DVec3::ONE, 0.0),
            cylinder(DVec3::new(8.0, 0.0, 0.0), 0.5, 1.0, DVec3::Z),
        ];
        let (mut best, mut t_max) = (None, f64::INFINITY);
        for (i, s) in shapes.iter().enumerate() {
            if let Some(h) = s.intersect(DVec3::ZERO, DVec3::X, EPS, t_max) {
                t_max = h.t;
                best = Some(i);
            }
        }
        assert_eq!(best, Some(1));
        assert!((t_max - 1.5).abs() < 1e-12);
    }

    #[test]
    fn bounds_contain_the_surface_and_normals_match_faces() {
        let shapes = [
            yawed_box(DVec3::new(1.0, 1.0, 1.0), DVec3::new(1.0, 0.5, 0.3), 33.0),
            cylinder(
                DVec3::new(0.0, 1.0, 0.5),
                0.3,
                0.8,
                DVec3::new(1.0, 1.0, 0.5),
            ),
            Shape::Sphere(Sphere {
                center: DVec3::ONE,
                radius: 0.4,
            }),
        ];
        for s in &shapes {
            let b = s.aabb();
            // Rays from far away toward the center hit the surface inside the bounds.
            for k in 0..64 {
                let a = k as f64 * 0.7;
                let dir = DVec3::new(a.cos(), a.sin(), (k as f64 * 0.37).sin()).normalize();
                let origin = b.center() - 10.0 * dir;
                let h = hit(s, origin, dir).expect("aimed at the center");
                let p = origin + h.t * dir;
                assert!(b.contains(p, 1e-9), "{s:?} {p}");
                assert!(s.sdf(p).abs() < 1e-9);
                assert!((s.normal(p, h.face) - h.normal).length() < 1e-9);
                assert_eq!(s.nearest_face(p), h.face);
                assert!(h.normal.dot(dir) < 0.0, "outside rays meet front faces");
            }
        }
    }
}
