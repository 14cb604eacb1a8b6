//! Furniture-like objects assembled from primitives. Each builder works in the object's local
//! frame (origin on the floor or on the supporting surface, x = width, y = depth with the
//! front facing -y, z up) and places the result with a yaw about the vertical axis.

use glam::{DMat3, DVec3};

use super::materials::{Material, Pattern};
use super::room_spec::{ObjectSpec, PartSpec, ShapeSpec};

/// Where an object stands: its local origin in the world and its yaw in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub origin: DVec3,
    pub yaw_deg: f64,
}

impl Placement {
    pub fn new(origin: DVec3, yaw_deg: f64) -> Self {
        Placement { origin, yaw_deg }
    }

    pub fn at(x: f64, y: f64, z: f64, yaw_deg: f64) -> Self {
        Placement::new(DVec3::new(x, y, z), yaw_deg)
    }

    fn rotation(&self) -> DMat3 {
        DMat3::from_rotation_z(self.yaw_deg.to_radians())
    }

    /// A world point from a local one.
    pub fn point(&self, local: DVec3) -> DVec3 {
        self.origin + self.rotation() * local
    }

    /// A placement relative to this one (e.g. a monitor on a desk).
    pub fn child(&self, local: DVec3, extra_yaw_deg: f64) -> Placement {
        Placement::new(self.point(local), self.yaw_deg + extra_yaw_deg)
    }
}

/// Which wall an object hangs on or stands against; the local front (-y) faces into the room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wall {
    X0,
    X1,
    Y0,
    Y1,
}

impl Wall {
    /// Placement on the wall at horizontal position `along` (x for Y walls, y for X walls) and
    /// height `z`, pushed `depth / 2` into the room so an object of that depth touches the wall.
    pub fn placement(self, room_size: DVec3, along: f64, z: f64, depth: f64) -> Placement {
        let h = 0.5 * depth;
        match self {
            Wall::X0 => Placement::at(h, along, z, 90.0),
            Wall::X1 => Placement::at(room_size.x - h, along, z, -90.0),
            Wall::Y0 => Placement::at(along, h, z, 180.0),
            Wall::Y1 => Placement::at(along, room_size.y - h, z, 0.0),
        }
    }
}

/// Collects the parts of one object in its local frame.
pub struct PartsBuilder {
    place: Placement,
    parts: Vec<PartSpec>,
}

impl PartsBuilder {
    pub fn new(place: Placement) -> Self {
        PartsBuilder {
            place,
            parts: Vec::new(),
        }
    }

    pub fn cuboid(&mut self, center: DVec3, size: DVec3, material: &Material) -> &mut Self {
        let shape = ShapeSpec::box_at(self.place.point(center), size, self.place.yaw_deg);
        self.push(shape, material)
    }

    /// A cuboid standing on local height `z0`.
    pub fn slab(&mut self, x: f64, y: f64, z0: f64, size: DVec3, material: &Material) -> &mut Self {
        self.cuboid(DVec3::new(x, y, z0 + 0.5 * size.z), size, material)
    }

    /// A vertical cylinder standing on local height `z0`.
    pub fn post(
        &mut self,
        x: f64,
        y: f64,
        z0: f64,
        radius: f64,
        height: f64,
        material: &Material,
    ) -> &mut Self {
        let shape = ShapeSpec::vertical_cylinder(
            self.place.point(DVec3::new(x, y, z0 + 0.5 * height)),
            radius,
            height,
        );
        self.push(shape, material)
    }

    /// A cylinder along a local axis (e.g. a clock face along -y).
    pub fn rod(
        &mut self,
        center: DVec3,
        radius: f64,
        length: f64,
        axis: DVec3,
        material: &Material,
    ) -> &mut Self {
        let axis = self.place.rotation() * axis;
        let shape = ShapeSpec::cylinder_along(self.place.point(center), radius, length, axis);
        self.push(shape, material)
    }

    pub fn ball(&mut self, center: DVec3, radius: f64, material: &Material) -> &mut Self {
        let shape = ShapeSpec::sphere(self.place.point(center), radius);
        self.push(shape, material)
    }

    fn push(&mut self, shape: ShapeSpec, material: &Material) -> &mut Self {
        self.parts.push(PartSpec {
            shape,
            material: material.clone(),
        });
        self
    }

    pub fn finish(&mut self, name: &str, class: &str) -> ObjectSpec {
        ObjectSpec {
            name: name.to_string(),
            class: class.to_string(),
            parts: std::mem::take(&mut self.parts),
        }
    }
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

/// A table or desk: top of `size` (width, depth, height) on four square legs.
pub fn table(
    name: &str,
    class: &str,
    place: Placement,
    size: DVec3,
    top: &Material,
    legs: &Material,
) -> ObjectSpec {
    let thick = 0.04;
    let leg = 0.05;
    let mut b = PartsBuilder::new(place);
    b.slab(0.0, 0.0, size.z - thick, v(size.x, size.y, thick), top);
    let (lx, ly) = (0.5 * size.x - leg, 0.5 * size.y - leg);
    for (x, y) in [(-lx, -ly), (lx, -ly), (-lx, ly), (lx, ly)] {
        b.slab(x, y, 0.0, v(leg, leg, size.z - thick), legs);
    }
    b.finish(name, class)
}

/// A desk: a table with a drawer block under one side.
pub fn desk(
    name: &str,
    place: Placement,
    size: DVec3,
    top: &Material,
    body: &Material,
) -> ObjectSpec {
    let mut object = table(name, "desk", place, size, top, body);
    let drawer = v(0.4, size.y - 0.1, size.z - 0.04);
    let mut b = PartsBuilder::new(place);
    b.slab(0.5 * size.x - 0.05 - 0.5 * drawer.x, 0.0, 0.0, drawer, body);
    object.parts.extend(b.finish(name, "desk").parts);
    object
}

/// A round table on a central post with a foot.
pub fn round_table(
    name: &str,
    class: &str,
    place: Placement,
    radius: f64,
    height: f64,
    top: &Material,
    post: &Material,
) -> ObjectSpec {
    let mut b = PartsBuilder::new(place);
    b.post(0.0, 0.0, height - 0.03, radius, 0.03, top);
    b.post(0.0, 0.0, 0.02, 0.035, height - 0.05, post);
    b.post(0.0, 0.0, 0.0, 0.6 * radius, 0.02, post);
    b.finish(name, class)
}

/// A chair: seat, backrest at +y, four round legs. The sitter faces -y.
pub fn chair(name: &str, place: Placement, seat: &Material, frame: &Material) -> ObjectSpec {
    let (w, d, h) = (0.46, 0.46, 0.46);
    let mut b = PartsBuilder::new(place);
    b.slab(0.0, 0.0, h - 0.05, v(w, d, 0.05), seat);
    b.slab(0.0, 0.5 * d - 0.025, h, v(w, 0.05, 0.45), seat);
    let (lx, ly) = (0.5 * w - 0.04, 0.5 * d - 0.04);
    for (x, y) in [(-lx, -ly), (lx, -ly), (-lx, ly), (lx, ly)] {
        b.post(x, y, 0.0, 0.02, h - 0.05, frame);
    }
    b.finish(name, "chair")
}

/// A sofa or armchair: seat block, backrest at +y, two arms; `width` along x.
pub fn sofa(name: &str, class: &str, place: Placement, width: f64, body: &Material) -> ObjectSpec {
    let (d, seat_h, arm_w) = (0.9, 0.42, 0.18);
    let mut b = PartsBuilder::new(place);
    b.slab(0.0, 0.0, 0.0, v(width, d, seat_h), body);
    b.slab(0.0, 0.5 * d - 0.1, seat_h, v(width, 0.2, 0.42), body);
    for x in [-1.0, 1.0] {
        b.slab(
            x * (0.5 * width - 0.5 * arm_w),
            -0.1,
            seat_h,
            v(arm_w, d - 0.2, 0.2),
            body,
        );
    }
    b.finish(name, class)
}

/// An open shelf of `size` with `levels` boards (bottom and top included) and a back panel.
/// Returns the object and the local heights of the boards' top surfaces (for placing items).
pub fn shelf(
    name: &str,
    class: &str,
    place: Placement,
    size: DVec3,
    levels: usize,
    wood: &Material,
) -> (ObjectSpec, Vec<f64>) {
    let t = 0.03;
    let mut b = PartsBuilder::new(place);
    for x in [-1.0, 1.0] {
        b.slab(
            x * (0.5 * size.x - 0.5 * t),
            0.0,
            0.0,
            v(t, size.y, size.z),
            wood,
        );
    }
    b.slab(
        0.0,
        0.5 * size.y - 0.005,
        0.0,
        v(size.x - 2.0 * t, 0.01, size.z),
        wood,
    );
    let levels = levels.max(2);
    let mut tops = Vec::new();
    for i in 0..levels {
        let z0 = (size.z - t) * i as f64 / (levels - 1) as f64;
        b.slab(0.0, -0.005, z0, v(size.x - 2.0 * t, size.y - 0.01, t), wood);
        tops.push(z0 + t);
    }
    (b.finish(name, class), tops)
}

/// A closed cabinet with two door handles on the front.
pub fn cabinet(
    name: &str,
    place: Placement,
    size: DVec3,
    body: &Material,
    handle: &Material,
) -> ObjectSpec {
    let mut b = PartsBuilder::new(place);
    b.slab(0.0, 0.0, 0.0, size, body);
    for x in [-0.06, 0.06] {
        b.slab(
            x,
            -0.5 * size.y - 0.01,
            0.55 * size.z,
            v(0.02, 0.02, 0.18),
            handle,
        );
    }
    b.finish(name, "cabinet")
}

/// A screen (monitor or tv) on a stand, facing -y: frame, dark panel, neck and foot.
pub fn screen(
    name: &str,
    class: &str,
    place: Placement,
    width: f64,
    height: f64,
    frame: &Material,
    panel: &Material,
) -> ObjectSpec {
    let lift = 0.12 * height.max(0.3);
    let mut b = PartsBuilder::new(place);
    b.slab(0.0, 0.0, 0.0, v(0.35 * width, 0.18, 0.02), frame);
    b.slab(0.0, 0.03, 0.02, v(0.05, 0.03, lift), frame);
    b.slab(0.0, 0.0, 0.02 + lift, v(width, 0.04, height), frame);
    b.slab(
        0.0,
        -0.025,
        0.02 + lift + 0.02,
        v(width - 0.04, 0.01, height - 0.04),
        panel,
    );
    b.finish(name, class)
}

/// A lamp: foot, pole and a cylindrical shade; `height` is the top of the shade.
pub fn lamp(
    name: &str,
    place: Placement,
    height: f64,
    shade_radius: f64,
    metal: &Material,
    shade: &Material,
) -> ObjectSpec {
    let shade_h = 1.4 * shade_radius;
    let mut b = PartsBuilder::new(place);
    b.post(0.0, 0.0, 0.0, 0.6 * shade_radius, 0.03, metal);
    b.post(0.0, 0.0, 0.03, 0.015, height - shade_h - 0.03 + 0.02, metal);
    b.post(0.0, 0.0, height - shade_h, shade_radius, shade_h, shade);
    b.finish(name, "lamp")
}

/// A potted plant: pot and a cluster of foliage spheres.
pub fn plant(
    name: &str,
    place: Placement,
    pot_radius: f64,
    height: f64,
    pot: &Material,
    leaves: &Material,
) -> ObjectSpec {
    let pot_h = 0.35 * height;
    let r = 0.3 * height;
    let mut b = PartsBuilder::new(place);
    b.post(0.0, 0.0, 0.0, pot_radius, pot_h, pot);
    b.ball(v(0.0, 0.0, pot_h + 0.6 * r), r, leaves);
    b.ball(v(0.45 * r, 0.2 * r, pot_h + 1.1 * r), 0.7 * r, leaves);
    b.ball(v(-0.35 * r, -0.3 * r, pot_h + 1.3 * r), 0.6 * r, leaves);
    b.finish(name, "plant")
}

/// A single cuboid standing on its origin (boxes, books, cushions, rugs, speakers).
pub fn block(
    name: &str,
    class: &str,
    place: Placement,
    size: DVec3,
    material: &Material,
) -> ObjectSpec {
    PartsBuilder::new(place)
        .slab(0.0, 0.0, 0.0, size, material)
        .finish(name, class)
}

/// A single vertical cylinder standing on its origin (cups, vases, bowls).
pub fn vessel(
    name: &str,
    class: &str,
    place: Placement,
    radius: f64,
    height: f64,
    material: &Material,
) -> ObjectSpec {
    PartsBuilder::new(place)
        .post(0.0, 0.0, 0.0, radius, height, material)
        .finish(name, class)
}

/// A ball resting on its origin.
pub fn ball(name: &str, place: Placement, radius: f64, material: &Material) -> ObjectSpec {
    PartsBuilder::new(place)
        .ball(v(0.0, 0.0, radius), radius, material)
        .finish(name, "ball")
}

/// A wall-hung frame with an inset canvas (pictures, windows); `place` from `Wall::placement`
/// with depth 0.04 and z at the bottom edge.
pub fn framed_panel(
    name: &str,
    class: &str,
    place: Placement,
    width: f64,
    height: f64,
    frame: &Material,
    canvas: &Material,
) -> ObjectSpec {
    let mut b = PartsBuilder::new(place);
    b.slab(0.0, 0.0, 0.0, v(width, 0.04, height), frame);
    b.slab(
        0.0,
        -0.025,
        0.05,
        v(width - 0.1, 0.01, height - 0.1),
        canvas,
    );
    b.finish(name, class)
}

/// A door leaf with a round handle; `place` from `Wall::placement` with depth 0.05, z = 0.
pub fn door(
    name: &str,
    place: Placement,
    width: f64,
    height: f64,
    leaf: &Material,
    handle: &Material,
) -> ObjectSpec {
    let mut b = PartsBuilder::new(place);
    b.slab(0.0, 0.0, 0.0, v(width, 0.05, height), leaf);
    b.ball(v(0.38 * width, -0.05, 1.0), 0.03, handle);
    b.finish(name, "door")
}

/// A wall clock: a flat disc facing -y with a rim; `place` from `Wall::placement`, depth 0.04.
pub fn clock(
    name: &str,
    place: Placement,
    radius: f64,
    face: &Material,
    rim: &Material,
) -> ObjectSpec {
    let mut b = PartsBuilder::new(place);
    b.rod(v(0.0, 0.0, 0.0), radius, 0.04, DVec3::Y, rim);
    b.rod(v(0.0, -0.025, 0.0), 0.88 * radius, 0.01, DVec3::Y, face);
    b.finish(name, "clock")
}

/// Common materials, so presets read as layouts rather than color tables.
pub mod looks {
    use super::*;

    pub fn wood(color: [u8; 3]) -> Material {
        let dark = color.map(|c| (c as f64 * 0.78) as u8);
        Material::new(color, Pattern::Wood, 0.12).with_color2(dark)
    }

    pub fn fabric(color: [u8; 3]) -> Material {
        let dark = color.map(|c| (c as f64 * 0.8) as u8);
        Material::new(color, Pattern::Noise, 0.2).with_color2(dark)
    }

    pub fn plain(color: [u8; 3]) -> Material {
        Material::plain(color)
    }

    pub fn metal() -> Material {
        Material::plain([96, 98, 104])
    }

    pub fn screen_panel() -> Material {
        Material::new([24, 28, 40], Pattern::Noise, 0.25).with_color2([40, 52, 76])
    }

    pub fn leaves() -> Material {
        Material::new([58, 120, 52], Pattern::Noise, 0.12).with_color2([30, 80, 34])
    }

    pub fn glass() -> Material {
        Material::new([176, 212, 236], Pattern::Noise, 0.5).with_color2([214, 232, 246])
    }

    pub fn canvas(color: [u8; 3], color2: [u8; 3]) -> Material {
        Material::new(color, Pattern::Noise, 0.15).with_color2(color2)
    }

    pub fn stripes(color: [u8; 3], color2: [u8; 3], width: f64) -> Material {
        Material::new(color, Pattern::Stripes, width).with_color2(color2)
    }
}
