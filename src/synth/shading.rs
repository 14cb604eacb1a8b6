//! Fixed, view-independent lighting: ambient plus a sky term plus one directional light,
//! Lambertian only (no specular), so SH degree 0 Gaussians can reproduce the images exactly.

use glam::DVec3;

const AMBIENT: f64 = 0.45;
/// Brightens surfaces facing up, darkens ceilings a little less than a pure key light would.
const SKY: f64 = 0.15;
const KEY: f64 = 0.4;

fn key_direction() -> DVec3 {
    DVec3::new(0.35, 0.6, 0.72).normalize()
}

/// Shaded color of a surface with reflectance `albedo` and outward unit `normal`.
pub fn shade(albedo: DVec3, normal: DVec3) -> DVec3 {
    let light = AMBIENT + SKY * (0.5 + 0.5 * normal.z) + KEY * normal.dot(key_direction()).max(0.0);
    (albedo * light).clamp(DVec3::ZERO, DVec3::ONE)
}

/// Quantizes a [0, 1] color to 8-bit sRGB values.
pub fn to_rgb8(c: DVec3) -> [u8; 3] {
    let q = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    [q(c.x), q(c.y), q(c.z)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lighting_stays_in_range_and_favors_lit_faces() {
        let white = DVec3::ONE;
        let up = shade(white, DVec3::Z);
        let down = shade(white, DVec3::NEG_Z);
        assert!(up.x <= 1.0 && down.x > 0.3 && up.x > down.x);
        assert_eq!(to_rgb8(DVec3::new(0.0, 0.5, 1.0)), [0, 128, 255]);
    }
}
