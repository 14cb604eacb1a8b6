//! Procedural surface textures. A texture is a pure function of the surface point (its 2D
//! surface coordinates and object-local 3D position), so the ray-cast images and the Gaussians
//! sampled on the same surfaces agree exactly. Feature sizes stay well above the Gaussian
//! spacing so that a sampled scene can reproduce them.

use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pattern {
    /// `color` with a faint low-frequency variation.
    #[default]
    Plain,
    /// Smooth blotches blending `color` and `color2` (fabric, plaster, foliage).
    Noise,
    /// Tiles of size `scale` alternating `color` / `color2` (floors).
    Checker,
    /// Bands of width `scale` along the surface's u axis (books, curtains).
    Stripes,
    /// Planks of width `scale` with per-plank tint and grain (floors, tables, shelves).
    Wood,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// sRGB 0..255.
    pub color: [u8; 3],
    /// Second color of two-color patterns; defaults to a darker `color`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color2: Option<[u8; 3]>,
    #[serde(default)]
    pub pattern: Pattern,
    /// Feature size in meters (tile, band, plank width, blotch size).
    #[serde(default = "default_scale")]
    pub scale: f64,
}

fn default_scale() -> f64 {
    0.25
}

impl Material {
    pub fn new(color: [u8; 3], pattern: Pattern, scale: f64) -> Self {
        Material {
            color,
            color2: None,
            pattern,
            scale,
        }
    }

    pub fn plain(color: [u8; 3]) -> Self {
        Material::new(color, Pattern::Plain, default_scale())
    }

    pub fn with_color2(mut self, color2: [u8; 3]) -> Self {
        self.color2 = Some(color2);
        self
    }

    fn colors(&self) -> (DVec3, DVec3) {
        let c1 = to_unit(self.color);
        let c2 = self.color2.map(to_unit).unwrap_or(c1 * 0.72);
        (c1, c2)
    }

    /// Reflectance in [0, 1] at a surface point; `salt` decorrelates parts with equal materials.
    pub fn albedo(&self, uv: DVec2, local: DVec3, salt: u64) -> DVec3 {
        let (c1, c2) = self.colors();
        let s = self.scale.max(1e-3);
        let c = match self.pattern {
            Pattern::Plain => c1 * (0.94 + 0.12 * value_noise(local / 0.35, salt)),
            Pattern::Noise => {
                let n = fbm(local / s, salt);
                c1.lerp(c2, smoothstep(0.3, 0.7, n))
            }
            Pattern::Checker => {
                let cell = (uv / s).floor();
                let base = if (cell.x + cell.y).rem_euclid(2.0) < 0.5 {
                    c1
                } else {
                    c2
                };
                base * (0.95 + 0.1 * value_noise(local / 0.3, salt))
            }
            Pattern::Stripes => {
                let band = (uv.x / s).floor();
                let base = if band.rem_euclid(2.0) < 0.5 { c1 } else { c2 };
                base * (0.93 + 0.14 * hash01(band as i64, 7, 0, salt))
            }
            Pattern::Wood => {
                let plank = (uv.y / s).floor();
                let tint = hash01(plank as i64, 3, 0, salt);
                // Grain runs along the plank (u), wobbling with low-frequency noise.
                let phase = uv.y * std::f64::consts::TAU / s + 6.0 * value_noise(local / 0.4, salt);
                let grain = 0.5 + 0.5 * phase.sin();
                let base = c1.lerp(c2, 0.25 + 0.5 * tint);
                base * (0.9 + 0.12 * grain)
            }
        };
        c.clamp(DVec3::ZERO, DVec3::ONE)
    }
}

fn to_unit(c: [u8; 3]) -> DVec3 {
    DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) / 255.0
}

fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A fixed integer hash (not a random stream): textures must be pure functions of position.
fn hash01(x: i64, y: i64, z: i64, salt: u64) -> f64 {
    let mut h = salt ^ 0x9E37_79B9_7F4A_7C15;
    for v in [x as u64, y as u64, z as u64] {
        h ^= v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        h = (h ^ (h >> 31)).wrapping_mul(0x94D0_49BB_1331_11EB);
        h ^= h >> 29;
    }
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Trilinear value noise in [0, 1] with smooth interpolation.
pub fn value_noise(p: DVec3, salt: u64) -> f64 {
    let cell = p.floor();
    let f = p - cell;
    let w = f * f * (DVec3::splat(3.0) - 2.0 * f);
    let (ix, iy, iz) = (cell.x as i64, cell.y as i64, cell.z as i64);
    let mut acc = 0.0;
    for corner in 0..8 {
        let (dx, dy, dz) = (corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
        let weight = (if dx == 1 { w.x } else { 1.0 - w.x })
            * (if dy == 1 { w.y } else { 1.0 - w.y })
            * (if dz == 1 { w.z } else { 1.0 - w.z });
        acc += weight * hash01(ix + dx, iy + dy, iz + dz, salt);
    }
    acc
}

/// Two octaves: enough structure for blotches without detail finer than half the scale.
fn fbm(p: DVec3, salt: u64) -> f64 {
    (2.0 * value_noise(p, salt) + value_noise(p * 2.0 + 17.3, salt ^ 0x55)) / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn albedo_is_a_pure_function_in_range() {
        for pattern in [
            Pattern::Plain,
            Pattern::Noise,
            Pattern::Checker,
            Pattern::Stripes,
            Pattern::Wood,
        ] {
            let m = Material::new([200, 120, 40], pattern, 0.3);
            for i in 0..200 {
                let p = DVec3::new(
                    i as f64 * 0.037 - 3.0,
                    i as f64 * 0.011,
                    -(i as f64) * 0.023,
                );
                let a = m.albedo(p.truncate(), p, 5);
                assert_eq!(a, m.albedo(p.truncate(), p, 5));
                assert!(a.cmpge(DVec3::ZERO).all() && a.cmple(DVec3::ONE).all());
            }
        }
    }

    #[test]
    fn checker_alternates_between_tiles() {
        let m = Material::new([255, 255, 255], Pattern::Checker, 0.5).with_color2([0, 0, 0]);
        let a = m.albedo(DVec2::new(0.25, 0.25), DVec3::ZERO, 0);
        let b = m.albedo(DVec2::new(0.75, 0.25), DVec3::ZERO, 0);
        assert!(a.x > 0.8 && b.x < 0.1, "{a} {b}");
    }
}
