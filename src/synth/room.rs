//! A built room: the shell (floor, ceiling, four walls) and the objects' primitives, each with
//! its class, instance and material; ray casting against all of them; surface colors; and the
//! occupancy queries that surface sampling and camera placement need.

use anyhow::{bail, ensure, Result};
use glam::{DVec2, DVec3};

use super::bvh::Bvh;
use super::confusion::ConfusionTable;
use super::materials::Material;
use super::palette::class_color;
use super::primitives::{Aabb, Face, Quad, Shape};
use super::room_spec::{RoomSpec, STRUCTURE_NAMES};
use super::shading::shade;
use crate::scene::{ClassInfo, ClassTable};

/// A surface closer than this along its outward normal to another solid counts as covered.
const COVER_EPS: f64 = 1e-3;
/// A surface point this deep inside another solid is buried (touching is not).
const BURIED_EPS: f64 = 1e-6;
/// Most classes a room may have: label id 255 is the 8-bit ignore value.
pub const MAX_CLASSES: usize = 255;

/// One object (or shell surface) of the room.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Instance {
    pub id: u32,
    pub name: String,
    pub class_id: u32,
    /// Floor, ceiling and walls.
    pub structural: bool,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Primitive {
    pub shape: Shape,
    pub material: Material,
    pub instance: u32,
    pub class_id: u32,
    /// Decorrelates the textures of parts that share a material.
    pub texture_salt: u64,
}

/// The first surface a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    pub t: f64,
    pub point: DVec3,
    pub normal: DVec3,
    /// Index into `Room::primitives`.
    pub primitive: usize,
    pub face: Face,
}

#[derive(Clone, Debug)]
pub struct Room {
    /// The description this room was built from (written back as room.json).
    pub spec: RoomSpec,
    pub classes: ClassTable,
    pub confusions: ConfusionTable,
    pub instances: Vec<Instance>,
    /// The six shell quads first (see `STRUCTURE_NAMES`), then the objects' parts.
    pub primitives: Vec<Primitive>,
    /// Over `primitives[SHELL..]`.
    objects_bvh: Bvh,
}

const SHELL: usize = STRUCTURE_NAMES.len();

impl Room {
    pub fn build(spec: RoomSpec) -> Result<Room> {
        spec.validate()?;
        let classes = class_table(&spec)?;
        let class_id = |name: &str| -> Result<u32> {
            match classes.classes.iter().find(|c| c.name == name) {
                Some(c) => Ok(c.id),
                None => bail!("class '{name}' is not in the room's class list"),
            }
        };
        let size = spec.size();
        let mut instances = Vec::new();
        let mut primitives = Vec::new();
        for (i, (name, quad, material)) in shell_quads(&spec, size).into_iter().enumerate() {
            let class = class_id(shell_class(name))?;
            instances.push(Instance {
                id: i as u32,
                name: name.to_string(),
                class_id: class,
                structural: true,
            });
            primitives.push(Primitive {
                shape: Shape::Quad(quad),
                material,
                instance: i as u32,
                class_id: class,
                texture_salt: texture_salt(i, 0),
            });
        }
        for object in &spec.objects {
            let id = instances.len() as u32;
            let class = class_id(&object.class)?;
            instances.push(Instance {
                id,
                name: object.name.clone(),
                class_id: class,
                structural: false,
            });
            for (j, part) in object.parts.iter().enumerate() {
                primitives.push(Primitive {
                    shape: part.shape.to_shape()?,
                    material: part.material.clone(),
                    instance: id,
                    class_id: class,
                    texture_salt: texture_salt(id as usize, j),
                });
            }
        }
        // Instance ids are 16-bit in the instance maps (65535: no instance), the room's
        // shell (floor, walls, ceiling) among them.
        ensure!(
            instances.len() < u16::MAX as usize,
            "too many objects ({}; with the room's {} shell instances at most {} objects: \
             instance maps hold 16-bit ids)",
            spec.objects.len(),
            instances.len() - spec.objects.len(),
            u16::MAX as usize - 1 - (instances.len() - spec.objects.len())
        );
        let confusions = ConfusionTable::new(&classes, &spec.confusions)?;
        let bounds: Vec<Aabb> = primitives[SHELL..].iter().map(|p| p.shape.aabb()).collect();
        Ok(Room {
            spec,
            classes,
            confusions,
            instances,
            primitives,
            objects_bvh: Bvh::build(&bounds),
        })
    }

    pub fn size(&self) -> DVec3 {
        self.spec.size()
    }

    /// Whether `p` is inside the room interior, at least `margin` from floor, walls and ceiling.
    pub fn interior_contains(&self, p: DVec3, margin: f64) -> bool {
        p.cmpge(DVec3::splat(margin)).all() && p.cmple(self.size() - margin).all()
    }

    /// The first surface along `dir` from `origin` (exact, analytic). `t` is in units of |dir|.
    pub fn cast(&self, origin: DVec3, dir: DVec3) -> Option<SurfaceHit> {
        const T_MIN: f64 = 1e-9;
        let mut best: Option<(f64, usize, Face, DVec3)> = None;
        let mut t_max = f64::INFINITY;
        for (i, p) in self.primitives[..SHELL].iter().enumerate() {
            if let Some(h) = p.shape.intersect(origin, dir, T_MIN, t_max) {
                t_max = h.t;
                best = Some((h.t, i, h.face, h.normal));
            }
        }
        self.objects_bvh.visit_ray(origin, dir, t_max, |k, t_max| {
            let i = SHELL + k;
            let h = self.primitives[i]
                .shape
                .intersect(origin, dir, T_MIN, t_max)?;
            best = Some((h.t, i, h.face, h.normal));
            Some(h.t)
        });
        let (t, primitive, face, normal) = best?;
        Some(SurfaceHit {
            t,
            point: origin + t * dir,
            normal,
            primitive,
            face,
        })
    }

    /// Reflectance of a primitive's surface at `point` on `face`.
    pub fn albedo_at(&self, primitive: usize, point: DVec3, face: Face) -> DVec3 {
        let p = &self.primitives[primitive];
        let uv: DVec2 = p.shape.surface_uv(point, face);
        p.material
            .albedo(uv, p.shape.local_point(point), p.texture_salt)
    }

    /// The lit, view-independent color of a surface point (what images show and Gaussians carry).
    pub fn color_at(&self, primitive: usize, point: DVec3, face: Face) -> DVec3 {
        let normal = self.primitives[primitive].shape.normal(point, face);
        shade(self.albedo_at(primitive, point, face), normal)
    }

    /// Whether the surface of `primitive` at `point` (outward `normal`) is hidden because another
    /// solid or the outside of the room touches or encloses it (a box bottom on the floor, a leg
    /// inside a seat, a picture's back against a wall).
    pub fn is_covered(&self, primitive: usize, point: DVec3, normal: DVec3) -> bool {
        let q = point + COVER_EPS * normal;
        if !self.interior_contains(q, 0.0) {
            return true;
        }
        let mut covered = false;
        // The point itself may be buried too (where two solids' surfaces cross at an angle).
        self.objects_bvh.visit_point(q, 2.0 * COVER_EPS, |k| {
            let i = SHELL + k;
            if i != primitive {
                let shape = &self.primitives[i].shape;
                covered |= shape.sdf(q) < 0.0 || shape.sdf(point) < -BURIED_EPS;
            }
        });
        covered
    }

    /// Whether `p` is at least `margin` away from every object and inside the shell by `margin`.
    pub fn is_free(&self, p: DVec3, margin: f64) -> bool {
        if !self.interior_contains(p, margin) {
            return false;
        }
        let mut free = true;
        self.objects_bvh.visit_point(p, margin, |k| {
            free &= self.primitives[SHELL + k].shape.sdf(p) >= margin;
        });
        free
    }

    /// Bounds of all parts of an instance.
    pub fn instance_bounds(&self, instance: u32) -> Aabb {
        self.primitives
            .iter()
            .filter(|p| p.instance == instance)
            .fold(Aabb::EMPTY, |acc, p| acc.union(p.shape.aabb()))
    }

    pub fn class_name(&self, class_id: u32) -> &str {
        self.classes
            .classes
            .iter()
            .find(|c| c.id == class_id)
            .map(|c| c.name.as_str())
            .unwrap_or("?")
    }
}

fn shell_class(instance_name: &str) -> &'static str {
    match instance_name {
        "floor" => "floor",
        "ceiling" => "ceiling",
        _ => "wall",
    }
}

/// Shell quads with inward normals; wall quads keep u horizontal and v up (for patterns).
fn shell_quads(spec: &RoomSpec, s: DVec3) -> Vec<(&'static str, Quad, Material)> {
    let quad = |center: DVec3, u: DVec3, v: DVec3, hu: f64, hv: f64| Quad {
        center,
        u,
        v,
        half: DVec2::new(hu, hv),
    };
    let (hx, hy, hz) = (0.5 * s.x, 0.5 * s.y, 0.5 * s.z);
    let names = STRUCTURE_NAMES;
    vec![
        (
            names[0],
            quad(DVec3::new(hx, hy, 0.0), DVec3::X, DVec3::Y, hx, hy),
            spec.floor.clone(),
        ),
        (
            names[1],
            quad(DVec3::new(hx, hy, s.z), DVec3::Y, DVec3::X, hy, hx),
            spec.ceiling.clone(),
        ),
        (
            names[2],
            quad(DVec3::new(0.0, hy, hz), DVec3::Y, DVec3::Z, hy, hz),
            spec.walls.clone(),
        ),
        (
            names[3],
            quad(DVec3::new(s.x, hy, hz), DVec3::NEG_Y, DVec3::Z, hy, hz),
            spec.walls.clone(),
        ),
        (
            names[4],
            quad(DVec3::new(hx, 0.0, hz), DVec3::NEG_X, DVec3::Z, hx, hz),
            spec.walls.clone(),
        ),
        (
            names[5],
            quad(DVec3::new(hx, s.y, hz), DVec3::X, DVec3::Z, hx, hz),
            spec.walls.clone(),
        ),
    ]
}

fn texture_salt(instance: usize, part: usize) -> u64 {
    ((instance as u64) << 24) ^ (part as u64) ^ 0xA076_1D64_78BD_642F
}

/// Ids are positions in the explicit class list, or floor, wall, ceiling, then first use.
fn class_table(spec: &RoomSpec) -> Result<ClassTable> {
    let mut names: Vec<(String, Option<[u8; 3]>)> = spec
        .classes
        .iter()
        .map(|c| (c.name.clone(), c.color))
        .collect();
    let explicit = !names.is_empty();
    let used = ["floor", "wall", "ceiling"]
        .into_iter()
        .chain(spec.objects.iter().map(|o| o.class.as_str()));
    for name in used {
        if !names.iter().any(|(n, _)| n == name) {
            if explicit {
                bail!("class '{name}' is used but missing from the room's class list");
            }
            names.push((name.to_string(), None));
        }
    }
    ensure!(
        names.len() <= MAX_CLASSES,
        "a room may have at most {MAX_CLASSES} classes, got {}",
        names.len()
    );
    let classes = names
        .into_iter()
        .enumerate()
        .map(|(i, (name, color))| ClassInfo {
            id: i as u32,
            color: color.unwrap_or_else(|| class_color(&name, i)),
            name,
        })
        .collect();
    Ok(ClassTable { classes })
}
