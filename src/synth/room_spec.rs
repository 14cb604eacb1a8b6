//! The room description: the JSON format `--preset FILE.json` reads and every run writes back as
//! `room.json`. World frame: z up, the floor is z = 0, the room interior spans
//! `[0, size.x] x [0, size.y] x [0, size.z]` meters. Floor, ceiling and the four walls come
//! from `size`; everything else is an object (one instance of one class) made of parts.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, ensure, Context, Result};
use glam::{DMat3, DVec2, DVec3};
use serde::{Deserialize, Serialize};

use super::materials::{Material, Pattern};
use super::primitives::{frame_with_z_axis, Cylinder, OrientedBox, Quad, Shape, Sphere};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoomSpec {
    /// Interior size in meters: [x, y, height].
    pub size: [f64; 3],
    #[serde(default = "default_floor")]
    pub floor: Material,
    #[serde(default = "default_walls")]
    pub walls: Material,
    #[serde(default = "default_ceiling")]
    pub ceiling: Material,
    /// Class order and colors (ids are positions in this list). Empty: floor, wall, ceiling,
    /// then object classes in order of first use.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub classes: Vec<ClassSpec>,
    /// Overrides of the look-alike table the noise models use: class -> confused classes.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub confusions: BTreeMap<String, Vec<String>>,
    #[serde(default)]
    pub objects: Vec<ObjectSpec>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassSpec {
    pub name: String,
    /// Palette color; defaults to the built-in color for known names.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color: Option<[u8; 3]>,
}

/// One instance: a named object of one class built from analytic parts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    pub name: String,
    pub class: String,
    pub parts: Vec<PartSpec>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartSpec {
    pub shape: ShapeSpec,
    pub material: Material,
}

/// A part's geometry, e.g. `{"box": {"center": [1, 2, 0.4], "size": [1.2, 0.6, 0.05]}}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
    /// Full extents `size`, turned by `yaw_deg` about the vertical axis.
    Box {
        center: [f64; 3],
        size: [f64; 3],
        #[serde(default, skip_serializing_if = "is_zero")]
        yaw_deg: f64,
    },
    /// Capped cylinder centered at `center` along `axis` (default vertical).
    Cylinder {
        center: [f64; 3],
        radius: f64,
        height: f64,
        #[serde(default = "vertical", skip_serializing_if = "is_vertical")]
        axis: [f64; 3],
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
    },
    /// Rectangle `center + a * half_u + b * half_v`, |a|, |b| <= 1; normal along half_u x half_v.
    Quad {
        center: [f64; 3],
        half_u: [f64; 3],
        half_v: [f64; 3],
    },
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn vertical() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

fn is_vertical(a: &[f64; 3]) -> bool {
    *a == vertical()
}

fn default_floor() -> Material {
    Material::new([150, 112, 80], Pattern::Wood, 0.18).with_color2([118, 84, 58])
}

fn default_walls() -> Material {
    Material::new([214, 208, 196], Pattern::Noise, 0.6).with_color2([196, 188, 174])
}

fn default_ceiling() -> Material {
    Material::plain([236, 236, 230])
}

impl ShapeSpec {
    pub fn box_at(center: DVec3, size: DVec3, yaw_deg: f64) -> Self {
        ShapeSpec::Box {
            center: center.to_array(),
            size: size.to_array(),
            yaw_deg,
        }
    }

    pub fn vertical_cylinder(center: DVec3, radius: f64, height: f64) -> Self {
        ShapeSpec::Cylinder {
            center: center.to_array(),
            radius,
            height,
            axis: vertical(),
        }
    }

    pub fn cylinder_along(center: DVec3, radius: f64, height: f64, axis: DVec3) -> Self {
        ShapeSpec::Cylinder {
            center: center.to_array(),
            radius,
            height,
            axis: axis.to_array(),
        }
    }

    pub fn sphere(center: DVec3, radius: f64) -> Self {
        ShapeSpec::Sphere {
            center: center.to_array(),
            radius,
        }
    }

    /// Where the primitive is centered.
    fn center(&self) -> DVec3 {
        match *self {
            ShapeSpec::Box { center, .. }
            | ShapeSpec::Cylinder { center, .. }
            | ShapeSpec::Sphere { center, .. }
            | ShapeSpec::Quad { center, .. } => DVec3::from_array(center),
        }
    }

    /// The validated primitive.
    pub fn to_shape(&self) -> Result<Shape> {
        let vec = |name: &str, a: [f64; 3]| -> Result<DVec3> {
            ensure!(
                a.iter().all(|x| x.is_finite()),
                "{name} must be finite, got {a:?}"
            );
            Ok(DVec3::from_array(a))
        };
        let positive = |name: &str, x: f64| -> Result<f64> {
            ensure!(
                x.is_finite() && x > 0.0,
                "{name} must be a positive length, got {x}"
            );
            Ok(x)
        };
        Ok(match *self {
            ShapeSpec::Box {
                center,
                size,
                yaw_deg,
            } => {
                let size = vec("size", size)?;
                ensure!(
                    size.min_element() > 0.0,
                    "box size must be positive, got {size}"
                );
                ensure!(yaw_deg.is_finite(), "yaw_deg must be finite");
                Shape::Box(OrientedBox {
                    center: vec("center", center)?,
                    half: 0.5 * size,
                    rot: DMat3::from_rotation_z(yaw_deg.to_radians()),
                })
            }
            ShapeSpec::Cylinder {
                center,
                radius,
                height,
                axis,
            } => {
                let axis = vec("axis", axis)?;
                ensure!(axis.length() > 1e-9, "cylinder axis must be non-zero");
                Shape::Cylinder(Cylinder {
                    center: vec("center", center)?,
                    radius: positive("radius", radius)?,
                    half_height: 0.5 * positive("height", height)?,
                    rot: frame_with_z_axis(axis),
                })
            }
            ShapeSpec::Sphere { center, radius } => Shape::Sphere(Sphere {
                center: vec("center", center)?,
                radius: positive("radius", radius)?,
            }),
            ShapeSpec::Quad {
                center,
                half_u,
                half_v,
            } => {
                let (hu, hv) = (vec("half_u", half_u)?, vec("half_v", half_v)?);
                ensure!(
                    hu.length() > 1e-9 && hv.length() > 1e-9,
                    "quad half_u and half_v must be non-zero"
                );
                ensure!(
                    hu.normalize().dot(hv.normalize()).abs() < 1e-6,
                    "quad half_u and half_v must be perpendicular"
                );
                Shape::Quad(Quad {
                    center: vec("center", center)?,
                    u: hu.normalize(),
                    v: hv.normalize(),
                    half: DVec2::new(hu.length(), hv.length()),
                })
            }
        })
    }
}

impl RoomSpec {
    /// Reads a room JSON file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading room file {}", path.display()))?;
        let value: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("parsing room file {}", path.display()))?;
        ensure!(
            value.is_object(),
            "room file {} is not a room: a room is a JSON object with \"size\" and \
             \"objects\" (as the room.json of any synth output)",
            path.display()
        );
        serde_json::from_value(value)
            .with_context(|| format!("parsing room file {}", path.display()))
    }

    pub fn size(&self) -> DVec3 {
        DVec3::from_array(self.size)
    }

    /// Checks what the JSON types cannot: sizes, names, classes, materials.
    pub fn validate(&self) -> Result<()> {
        let size = self.size();
        ensure!(
            size.is_finite() && size.min_element() >= 0.5 && size.max_element() <= 200.0,
            "room size must be between 0.5 and 200 m per axis, got {:?}",
            self.size
        );
        for (what, m) in [
            ("floor", &self.floor),
            ("walls", &self.walls),
            ("ceiling", &self.ceiling),
        ] {
            validate_material(m).with_context(|| format!("{what} material"))?;
        }
        let mut names: Vec<&str> = STRUCTURE_NAMES.to_vec();
        for (i, object) in self.objects.iter().enumerate() {
            let what = || format!("object {i} ('{}')", object.name);
            ensure!(!object.name.trim().is_empty(), "object {i}: empty name");
            ensure!(!object.class.trim().is_empty(), "{}: empty class", what());
            if names.contains(&object.name.as_str()) {
                bail!(
                    "{}: the name is used twice (floor, ceiling and wall_* are reserved)",
                    what()
                );
            }
            names.push(&object.name);
            ensure!(!object.parts.is_empty(), "{}: no parts", what());
            for (j, part) in object.parts.iter().enumerate() {
                part.shape
                    .to_shape()
                    .with_context(|| format!("{}: part {j}", what()))?;
                // The cameras stand inside the room: a part centered outside it is seen by
                // none (or through a wall) and its class would be listed but never shown.
                let center = part.shape.center();
                let slack = DVec3::splat(ROOM_SLACK_M);
                ensure!(
                    center.cmpge(-slack).all() && center.cmple(size + slack).all(),
                    "{}: part {j} is centered at {:?}, outside the room (0..{:?} m on x, y, z)",
                    what(),
                    center.to_array(),
                    self.size
                );
                validate_material(&part.material)
                    .with_context(|| format!("{}: part {j}", what()))?;
            }
        }
        let mut seen: Vec<&str> = Vec::new();
        for class in &self.classes {
            ensure!(!class.name.trim().is_empty(), "classes: empty class name");
            ensure!(
                !seen.contains(&class.name.as_str()),
                "classes: '{}' listed twice",
                class.name
            );
            seen.push(&class.name);
        }
        Ok(())
    }
}

/// How far outside the room's box a part's center may lie (a frame or sill set into a
/// wall).
const ROOM_SLACK_M: f64 = 0.1;

/// Instance names of the shell, in instance-id order.
pub const STRUCTURE_NAMES: [&str; 6] = [
    "floor", "ceiling", "wall_x0", "wall_x1", "wall_y0", "wall_y1",
];

fn validate_material(m: &Material) -> Result<()> {
    ensure!(
        m.scale.is_finite() && m.scale > 0.0,
        "material scale must be positive, got {}",
        m.scale
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_round_trip_and_unknown_fields_rejected() {
        let json = r#"{"size": [4, 3, 2.5], "objects": [{"name": "b", "class": "box", "parts": [
            {"shape": {"box": {"center": [1, 1, 0.25], "size": [0.5, 0.5, 0.5]}}, "material": {"color": [200, 10, 10]}},
            {"shape": {"cylinder": {"center": [2, 1, 0.5], "radius": 0.1, "height": 1}}, "material": {"color": [1, 2, 3], "pattern": "wood"}}]}]}"#;
        let spec: RoomSpec = serde_json::from_str(json).unwrap();
        spec.validate().unwrap();
        let again: RoomSpec = serde_json::from_str(&serde_json::to_string(&spec).unwrap()).unwrap();
        assert_eq!(spec, again);
        let bad = json.replace("\"radius\": 0.1", "\"radius\": 0.1, \"radus\": 2");
        assert!(serde_json::from_str::<RoomSpec>(&bad).is_err());
    }

    #[test]
    fn invalid_geometry_is_an_error() {
        let mut spec: RoomSpec = serde_json::from_str(r#"{"size": [4, 3, 2.5]}"#).unwrap();
        spec.validate().unwrap();
        let material = Material::plain([1, 2, 3]);
        let part = |shape| PartSpec {
            shape,
            material: material.clone(),
        };
        spec.objects.push(ObjectSpec {
            name: "x".into(),
            class: "box".into(),
            parts: vec![part(ShapeSpec::sphere(DVec3::ONE, -1.0))],
        });
        assert!(spec.validate().is_err());
        spec.objects[0].parts = vec![part(ShapeSpec::Quad {
            center: [1.0; 3],
            half_u: [1.0, 0.0, 0.0],
            half_v: [1.0, 1.0, 0.0],
        })];
        assert!(spec.validate().is_err());
        spec.objects[0].parts = vec![part(ShapeSpec::sphere(DVec3::ONE, 0.2))];
        spec.validate().unwrap();
        // Centered outside the room (a sill set 5 cm into a wall is in).
        for (center, inside) in [([100.0, 1.0, 1.0], false), ([1.0, -0.05, 1.0], true)] {
            spec.objects[0].parts = vec![part(ShapeSpec::sphere(DVec3::from_array(center), 0.2))];
            assert_eq!(spec.validate().is_ok(), inside, "{center:?}");
        }
        spec.objects[0].name = "floor".into();
        assert!(spec.validate().is_err());
        spec.size = [0.0, 3.0, 2.0];
        assert!(spec.validate().is_err());
    }
}
