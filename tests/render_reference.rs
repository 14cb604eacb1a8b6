//! Tests of the CPU reference renderer (`semsplat::render::reference`) against values
//! computed by hand, independent formulations (glam matrices, associated Legendre
//! polynomials, a tile-free brute-force compositor) and invariants.

// Channel loops index several parallel arrays at once, like the formulas they check.
#![allow(clippy::needless_range_loop)]

mod common;

use common::spec_scene::{scene, Spec};

use std::collections::BTreeSet;

use glam::{DMat3, DQuat, DVec3};
use semsplat::render::reference::*;
use semsplat::scene::{Camera, Gaussians, Split};
use semsplat::util::Rng;

// ---------------------------------------------------------------- helpers

fn camera(width: u32, height: u32, f: f64, cx: f64, cy: f64) -> Camera {
    Camera {
        name: "test".into(),
        width,
        height,
        fx: f,
        fy: f,
        cx,
        cy,
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        split: Split::Train,
    }
}

/// An isotropic, unrotated, degree-0 Gaussian.
fn iso(mean: [f32; 3], log_scale: f32, logit: f32, dc: [f32; 3]) -> Spec {
    Spec {
        mean,
        log_scale: [log_scale; 3],
        quat: [1.0, 0.0, 0.0, 0.0],
        logit,
        sh: vec![dc],
        logits: vec![],
    }
}

fn sigmoid(x: f32) -> f64 {
    1.0 / (1.0 + (-f64::from(x)).exp())
}

fn dc_color(dc: [f32; 3]) -> [f64; 3] {
    dc.map(|v| (SH_C0 * f64::from(v) + 0.5).max(0.0))
}

/// Alpha of a projected Gaussian at a pixel, written out from the spec (not the crate's).
fn hand_alpha(p: &ProjectedGaussian, px: u32, py: u32) -> Option<f64> {
    let dx = p.mean2d.x - (f64::from(px) + 0.5);
    let dy = p.mean2d.y - (f64::from(py) + 0.5);
    let sigma = 0.5 * (p.conic[0] * dx * dx + p.conic[2] * dy * dy) + p.conic[1] * dx * dy;
    let alpha = (p.opacity * (-sigma).exp()).min(0.999);
    (sigma >= 0.0 && alpha >= 1.0 / 255.0).then_some(alpha)
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

fn assert_close(a: f64, b: f64, tol: f64, what: &str) {
    assert!(close(a, b, tol), "{what}: {a} vs {b} (tol {tol})");
}

/// A random scene seen by a posed camera: means placed around (and beyond) the image at
/// depths 0.3..8, random rotations and anisotropic scales, opacities from invisible to
/// nearly opaque, degree-3 SH and `channels` semantic logits.
fn random_scene(
    rng: &mut Rng,
    n: usize,
    cam: &Camera,
    log_scale_range: (f64, f64),
    channels: usize,
) -> Gaussians {
    let mut specs = Vec::with_capacity(n);
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    for _ in 0..n {
        let u = rng.range_f64(-0.25 * w, 1.25 * w);
        let v = rng.range_f64(-0.25 * h, 1.25 * h);
        let z = rng.range_f64(0.3, 8.0);
        let pc = DVec3::new((u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z);
        let pw = cam.rotation.transpose() * (pc - cam.translation);
        let ls = [(); 3].map(|_| rng.range_f64(log_scale_range.0, log_scale_range.1) as f32);
        let quat = [(); 4].map(|_| rng.normal() as f32);
        let logit = rng.range_f64(-7.0, 7.0) as f32;
        let sh = (0..16)
            .map(|_| [(); 3].map(|_| (0.4 * rng.normal()) as f32))
            .collect();
        let logits = (0..channels).map(|_| (2.0 * rng.normal()) as f32).collect();
        specs.push(Spec {
            mean: pw.as_vec3().to_array(),
            log_scale: ls,
            quat,
            logit,
            sh,
            logits,
        });
    }
    scene(&specs)
}

fn posed_camera(width: u32, height: u32) -> Camera {
    let mut cam = camera(
        width,
        height,
        70.0,
        0.45 * f64::from(width),
        0.55 * f64::from(height),
    );
    cam.fy = 66.0;
    cam.rotation = DMat3::from_quat(DQuat::from_euler(glam::EulerRot::YXZ, 0.4, -0.3, 0.2));
    cam.translation = DVec3::new(0.3, -0.2, 0.5);
    cam
}

// ---------------------------------------------------------------- projection by hand

#[test]
fn isotropic_gaussian_at_center_by_hand() {
    let cam = camera(64, 48, 50.0, 32.0, 24.0);
    let logit = 4.0f32.ln();
    let dc = [1.0f32, 0.0, -1.0];
    let g = scene(&[iso([0.0, 0.0, 2.0], -2.0, logit, dc)]);
    let settings = RenderSettings::default();
    let p = project_one(&g, 0, &cam, &settings).unwrap();

    // J = diag(fx/z, fy/z) = diag(25, 25) on the axis; cov = 625 e^-4 I; + 0.3 dilation.
    let a = 625.0 * (-4.0f64).exp() + 0.3;
    assert_eq!(p.mean2d.to_array(), [32.0, 24.0]);
    assert_close(p.depth, 2.0, 1e-15, "depth");
    assert_close(p.cov2d[0], a, 1e-13, "cov xx");
    assert_eq!(p.cov2d[1], 0.0);
    assert_close(p.cov2d[2], a, 1e-13, "cov yy");
    assert_close(p.conic[0], 1.0 / a, 1e-13, "conic A");
    assert_eq!(p.conic[1], 0.0);
    assert_close(p.conic[2], 1.0 / a, 1e-13, "conic C");
    let o = sigmoid(logit);
    assert_close(o, 0.8, 1e-7, "opacity");
    assert_close(p.opacity, o, 1e-15, "opacity");

    // Extent: r = sqrt(2 ln(255 o)), ex = r sqrt(a) ~ 11.18: columns 21..=42, rows 13..=34.
    let r = (2.0 * (255.0 * o).ln()).sqrt();
    assert_close(p.extent_sigma, r, 1e-14, "extent sigma");
    assert_eq!(p.px_range, [21, 42]);
    assert_eq!(p.py_range, [13, 34]);
    assert_eq!(
        p.tile_range,
        TileRange {
            x_min: 1,
            x_max: 2,
            y_min: 0,
            y_max: 2
        }
    );

    let img = render(&g, &cam, &settings);
    // Pixel (31, 23): center (31.5, 23.5), d = (0.5, 0.5).
    let alpha_center = o * (-(0.5 * (0.25 + 0.25) / a)).exp();
    // Pixel (35, 23): center (35.5, 23.5), d = (-3.5, 0.5).
    let alpha_offset = o * (-(0.5 * (12.25 + 0.25) / a)).exp();
    assert_close(img.alpha_at(31, 23), alpha_center, 1e-13, "alpha center");
    assert_close(img.alpha_at(35, 23), alpha_offset, 1e-13, "alpha offset");
    assert_close(eval_alpha(&p, 35, 23).unwrap(), alpha_offset, 1e-13, "eval");
    let color = dc_color(dc);
    for ch in 0..3 {
        assert_close(
            img.rgb_at(35, 23)[ch],
            alpha_offset * color[ch],
            1e-13,
            "rgb",
        );
    }
    assert_close(img.depth[img.index(35, 23)], 2.0, 1e-13, "expected depth");
    assert_close(
        img.depth_sum[img.index(35, 23)],
        2.0 * alpha_offset,
        1e-13,
        "depth sum",
    );
    assert_eq!(img.n_contrib[img.index(35, 23)], 1);
    assert_eq!(img.last_contributor_id[img.index(35, 23)], Some(0));
    assert_eq!(img.last_contributor_pos[img.index(35, 23)], Some(0));
    // Outside the extent: nothing.
    assert_eq!(img.alpha_at(5, 5), 0.0);
    assert_eq!(img.n_contrib[img.index(5, 5)], 0);
}

#[test]
fn jacobian_off_axis_and_clamped_by_hand() {
    // cx = 20: lim_x_pos = 44/50 + 0.3 * 0.64 = 1.072, lim_x_neg = 20/50 + 0.192 = 0.592;
    // lim_y_pos = 24/50 + 0.3 * 0.48 = 0.624. Unit scales: cov_cam = I.
    let cam = camera(64, 48, 50.0, 20.0, 24.0);
    let settings = RenderSettings::default();
    let cases: [([f32; 3], [f64; 3]); 3] = [
        // x/z = 0.2, y/z = 0.3 (unclamped): J = [[25, 0, -5], [0, 25, -7.5]].
        ([0.4, 0.6, 2.0], [625.0 + 25.0, 37.5, 625.0 + 56.25]),
        // x/z = -1 clamped to -0.592: tx = -1.184, J02 = 50 * 1.184 / 4 = 14.8.
        ([-2.0, 0.0, 2.0], [625.0 + 14.8 * 14.8, 0.0, 625.0]),
        // x/z = 1.5 clamped to 1.072: J02 = -50 * 2.144 / 4 = -26.8; y/z = 0.5.
        (
            [3.0, 1.0, 2.0],
            [625.0 + 26.8 * 26.8, 26.8 * 12.5, 625.0 + 12.5 * 12.5],
        ),
    ];
    for (mean, cov) in cases {
        let g = scene(&[iso(mean, 0.0, 3.0, [0.0; 3])]);
        let p = project_one(&g, 0, &cam, &settings).unwrap();
        assert_close(p.cov2d[0], cov[0] + 0.3, 1e-6, "xx");
        assert_close(p.cov2d[1], cov[1], 1e-6, "xy");
        assert_close(p.cov2d[2], cov[2] + 0.3, 1e-6, "yy");
        // The mean itself is not clamped.
        let m = mean.map(f64::from);
        assert_close(p.mean2d.x, 50.0 * m[0] / m[2] + 20.0, 1e-12, "u");
        assert_close(p.mean2d.y, 50.0 * m[1] / m[2] + 24.0, 1e-12, "v");
        // conic * cov = I.
        let [a, b, c] = p.cov2d;
        let [ca, cb, cc] = p.conic;
        assert_close(a * ca + b * cb, 1.0, 1e-12, "inverse 00");
        assert!((a * cb + b * cc).abs() < 1e-12, "inverse 01");
        assert_close(b * cb + c * cc, 1.0, 1e-12, "inverse 11");
    }
}

#[test]
fn rotated_anisotropic_gaussian_by_hand() {
    // Scales (e^-1, e^-2, e^-2) rotated 90 degrees about z: the long axis lies along y.
    let cam = camera(64, 48, 50.0, 32.0, 24.0);
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let mut s = iso([0.0, 0.0, 2.0], -2.0, 2.0, [0.0; 3]);
    s.log_scale = [-1.0, -2.0, -2.0];
    s.quat = [h, 0.0, 0.0, h];
    let g = scene(&[s]);
    let p = project_one(&g, 0, &cam, &RenderSettings::default()).unwrap();
    assert_close(p.cov2d[0], 625.0 * (-4.0f64).exp() + 0.3, 1e-7, "xx");
    assert!(p.cov2d[1].abs() < 1e-6, "xy {}", p.cov2d[1]);
    assert_close(p.cov2d[2], 625.0 * (-2.0f64).exp() + 0.3, 1e-7, "yy");
    // A non-unit quaternion is normalized first: same result.
    let mut s2 = iso([0.0, 0.0, 2.0], -2.0, 2.0, [0.0; 3]);
    s2.log_scale = [-1.0, -2.0, -2.0];
    s2.quat = [3.0, 0.0, 0.0, 3.0];
    let p2 = project_one(&scene(&[s2]), 0, &cam, &RenderSettings::default()).unwrap();
    for k in 0..3 {
        assert_close(p2.cov2d[k], p.cov2d[k], 1e-7, "normalized quat");
    }
}

#[test]
fn posed_camera_projection_and_view_direction_by_hand() {
    // Camera at world (-3, 0, 0) looking down world +x: rows of R are the camera axes.
    let mut cam = camera(64, 48, 50.0, 32.0, 24.0);
    cam.rotation = DMat3::from_cols(
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::new(0.0, 1.0, 0.0),
        DVec3::new(-1.0, 0.0, 0.0),
    );
    cam.translation = DVec3::new(0.0, 0.0, 3.0);
    assert!((cam.center() - DVec3::new(-3.0, 0.0, 0.0)).length() < 1e-15);
    // World (0, 0.5, 1) -> camera (-1, 0.5, 3).
    let mut s = iso([0.0, 0.5, 1.0], -3.0, 2.0, [0.2, 0.0, 0.0]);
    s.sh = vec![[0.2, 0.0, 0.0], [0.0; 3], [0.0; 3], [1.0, 0.0, 0.0]];
    let g = scene(&[s]);
    let p = project_one(&g, 0, &cam, &RenderSettings::default()).unwrap();
    assert_close(p.depth, 3.0, 1e-15, "depth");
    assert_close(p.mean2d.x, 50.0 * (-1.0 / 3.0) + 32.0, 1e-13, "u");
    assert_close(p.mean2d.y, 50.0 * (0.5 / 3.0) + 24.0, 1e-13, "v");
    // dir = normalize(mean - center) = (3, 0.5, 1) / |.|, in world space; coefficient 3
    // multiplies -C1 x.
    let dir = DVec3::new(3.0, 0.5, 1.0).normalize();
    let red = SH_C0 * f64::from(0.2f32) - SH_C1 * dir.x + 0.5;
    assert_close(p.color[0], red, 1e-13, "red");
    assert_eq!(p.color[1], 0.5);
    assert_eq!(p.color[2], 0.5);
}

// ---------------------------------------------------------------- compositing

#[test]
fn nearer_gaussian_blends_first() {
    // cx, cy at pixel (32, 24)'s center, so on-axis Gaussians have sigma = 0 there and
    // alpha = opacity exactly.
    let cam = camera(64, 48, 50.0, 32.5, 24.5);
    let far_dc = [-1.0f32, 1.5, -1.0];
    let near_dc = [1.5f32, -1.0, -1.0];
    // Index 0 is the farther one: order must come from depth, not index.
    let g = scene(&[
        iso([0.0, 0.0, 4.0], -2.0, 0.0, far_dc),
        iso([0.0, 0.0, 2.0], -2.0, 1.0, near_dc),
    ]);
    let bg = [0.1, 0.2, 0.3];
    let settings = RenderSettings {
        background: bg,
        ..Default::default()
    };
    let img = render(&g, &cam, &settings);
    let (o_far, o_near) = (0.5, sigmoid(1.0));
    let w_near = o_near;
    let w_far = o_far * (1.0 - o_near);
    let t = (1.0 - o_near) * (1.0 - o_far);
    let (c_far, c_near) = (dc_color(far_dc), dc_color(near_dc));
    let i = img.index(32, 24);
    for ch in 0..3 {
        let want = w_near * c_near[ch] + w_far * c_far[ch] + t * bg[ch];
        assert_close(img.rgb[i][ch], want, 1e-14, "rgb");
    }
    assert_close(img.alpha[i], 1.0 - t, 1e-15, "alpha");
    assert_close(img.final_t[i], t, 1e-15, "T");
    assert_close(
        img.depth[i],
        (2.0 * w_near + 4.0 * w_far) / (1.0 - t),
        1e-14,
        "depth",
    );
    assert_eq!(img.n_contrib[i], 2);
    assert_eq!(img.last_contributor_id[i], Some(0));
    assert_eq!(img.last_contributor_pos[i], Some(1));

    // Contribution weights in blending order.
    let mut seen = Vec::new();
    for_each_contribution(&g, &cam, &settings, |px, py, id, w| {
        if (px, py) == (32, 24) {
            seen.push((id, w));
        }
    });
    assert_eq!(seen.len(), 2);
    assert_eq!(seen[0].0, 1);
    assert_close(seen[0].1, w_near, 1e-15, "w near");
    assert_eq!(seen[1].0, 0);
    assert_close(seen[1].1, w_far, 1e-15, "w far");
}

#[test]
fn equal_depths_blend_in_index_order() {
    let cam = camera(64, 48, 50.0, 32.5, 24.5);
    let a = [1.5f32, -1.0, -1.0];
    let b = [-1.0f32, -1.0, 1.5];
    let g = scene(&[
        iso([0.0, 0.0, 2.0], -2.0, 0.0, a),
        iso([0.0, 0.0, 2.0], -1.5, 0.0, b),
    ]);
    let settings = RenderSettings::default();
    let proj = project(&g, &cam, &settings);
    let isect = tile_intersections(&proj, &cam);
    // Pixel (32, 24) lies in tile (2, 1) of a 4-wide grid.
    let (tx, ty, tiles_x) = (32 / 16, 24 / 16, 4);
    let tile = ty * tiles_x + tx;
    let in_tile: Vec<u32> = isect
        .iter()
        .filter(|(t, _)| *t == tile)
        .map(|&(_, id)| id)
        .collect();
    assert_eq!(in_tile, vec![0, 1]);
    let img = render(&g, &cam, &settings);
    let (ca, cb) = (dc_color(a), dc_color(b));
    for ch in 0..3 {
        let want = 0.5 * ca[ch] + 0.25 * cb[ch];
        assert_close(img.rgb_at(32, 24)[ch], want, 1e-15, "rgb");
    }
}

#[test]
fn transmittance_stop_rule() {
    // 20 Gaussians on the axis, alpha exactly 0.5 at pixel (32, 24) (logit 0, sigma 0).
    // T after k blends is 2^-k: 2^-13 = 1.2e-4 > 1e-4 but 2^-14 = 6.1e-5 <= 1e-4, so the
    // 14th Gaussian stops the pixel without being blended. Ids run far-to-near.
    let cam = camera(64, 48, 50.0, 32.5, 24.5);
    let n = 20;
    let specs: Vec<Spec> = (0..n)
        .map(|k| {
            let z = 10.0 - 0.4 * k as f32;
            let dc = [(k as f32) * 0.1 - 1.0, 1.0 - (k as f32) * 0.05, 0.3];
            iso([0.0, 0.0, z], -2.0, 0.0, dc)
        })
        .collect();
    let g = scene(&specs);
    let bg = [0.9, 0.8, 0.7];
    let settings = RenderSettings {
        background: bg,
        ..Default::default()
    };
    let img = render(&g, &cam, &settings);
    let i = img.index(32, 24);
    assert_eq!(img.n_contrib[i], 13);
    assert_eq!(img.final_t[i], 0.5f64.powi(13));
    assert_eq!(img.alpha[i], 1.0 - 0.5f64.powi(13));
    // Front to back is id 19, 18, ...; the 13th blended is id 7 at list position 12.
    assert_eq!(img.last_contributor_id[i], Some(7));
    assert_eq!(img.last_contributor_pos[i], Some(12));
    let mut want = [0.0; 3];
    for j in 0..13 {
        let c = dc_color(specs[n - 1 - j].sh[0]);
        let w = 0.5f64.powi(j as i32 + 1);
        for ch in 0..3 {
            want[ch] += w * c[ch];
        }
    }
    for ch in 0..3 {
        want[ch] += 0.5f64.powi(13) * bg[ch];
        assert_close(img.rgb[i][ch], want[ch], 1e-15, "rgb");
    }
    let mut ids = Vec::new();
    for_each_contribution(&g, &cam, &settings, |px, py, id, _| {
        if (px, py) == (32, 24) {
            ids.push(id);
        }
    });
    assert_eq!(ids, (7..20).rev().collect::<Vec<u32>>());

    // Alpha clamps at 0.999: the second opaque Gaussian would leave T = 1e-6, so it stops.
    let g = scene(&[
        iso([0.0, 0.0, 2.0], -2.0, 20.0, [1.0; 3]),
        iso([0.0, 0.0, 3.0], -2.0, 20.0, [-1.0; 3]),
    ]);
    let img = render(&g, &cam, &RenderSettings::default());
    let i = img.index(32, 24);
    assert_eq!(img.n_contrib[i], 1);
    assert_eq!(img.alpha[i], 0.999);
    assert_eq!(img.final_t[i], 1.0 - 0.999);
    assert_close(img.rgb[i][0], 0.999 * dc_color([1.0; 3])[0], 1e-15, "rgb");
}

#[test]
fn negative_sigma_and_faint_alpha_are_skipped() {
    // An indefinite conic (not produced by `project`, but the blend rule must hold): sigma
    // at d = (-1.5, 1.5) is 0.5 (2.25 + 2.25) - 2 * 2.25 = -2.25 < 0, so the pixel skips it.
    let p = ProjectedGaussian {
        id: 0,
        mean_cam: DVec3::new(0.0, 0.0, 1.0),
        mean2d: glam::DVec2::new(10.0, 10.0),
        cov2d: [1.0, 0.0, 1.0],
        conic: [1.0, 2.0, 1.0],
        depth: 1.0,
        opacity: 0.9,
        color: [1.0; 3],
        extent_sigma: 3.0,
        px_range: [0, 19],
        py_range: [0, 19],
        tile_range: TileRange {
            x_min: 0,
            x_max: 1,
            y_min: 0,
            y_max: 1,
        },
    };
    assert_eq!(eval_alpha(&p, 11, 8), None);
    // d = (-1.5, -1.5): sigma = 2.25 + 4.5 = 6.75, alpha = 0.9 e^-6.75 = 0.00105 < 1/255.
    assert_eq!(eval_alpha(&p, 11, 11), None);
    // d = (0.5, 0.5): sigma = 0.25 + 0.5 = 0.75.
    assert_close(
        eval_alpha(&p, 9, 9).unwrap(),
        0.9 * (-0.75f64).exp(),
        1e-15,
        "alpha",
    );
    let out = blend_pixel([&p], 11, 8, |_, _, _| panic!("must not blend"));
    assert_eq!(out.n_contrib, 0);
    assert_eq!(out.final_t, 1.0);
}

#[test]
fn background_shows_through_transmittance() {
    let cam = camera(64, 48, 50.0, 32.5, 24.5);
    let dc = [0.5f32, -0.5, 1.0];
    let g = scene(&[iso([0.0, 0.0, 2.0], -2.5, 0.5, dc)]);
    let bg = [0.2, 0.4, 0.6];
    let settings = RenderSettings {
        background: bg,
        ..Default::default()
    };
    let img = render(&g, &cam, &settings);
    let a = sigmoid(0.5);
    let c = dc_color(dc);
    for ch in 0..3 {
        assert_close(
            img.rgb_at(32, 24)[ch],
            a * c[ch] + (1.0 - a) * bg[ch],
            1e-15,
            "covered",
        );
    }
    // Far from the Gaussian: exactly the background, nothing accumulated.
    let i = img.index(0, 0);
    assert_eq!(img.rgb[i], bg);
    assert_eq!(img.alpha[i], 0.0);
    assert_eq!(img.final_t[i], 1.0);
    assert_eq!(img.depth[i], 0.0);
    assert_eq!(img.n_contrib[i], 0);
    assert_eq!(img.last_contributor_id[i], None);
    assert_eq!(img.last_contributor_pos[i], None);
    // Empty scene: background everywhere.
    let img = render(&Gaussians::default(), &cam, &settings);
    assert!(img.rgb.iter().all(|&p| p == bg));
    assert_eq!(img.channels, 0);
}

// ---------------------------------------------------------------- extent and tiles

#[test]
fn extent_covers_every_reachable_pixel_and_tiles_match() {
    let cam = posed_camera(80, 56);
    let mut rng = Rng::new(7);
    let g = random_scene(&mut rng, 400, &cam, (-4.5, -1.0), 0);
    let settings = RenderSettings::default();
    let (tiles_x, tiles_y) = tile_grid(&cam);
    assert_eq!((tiles_x, tiles_y), (5, 4));
    let projected = project(&g, &cam, &settings);
    assert!(projected.len() > 100, "only {} visible", projected.len());
    let isect = tile_intersections(&projected, &cam);

    let mut reached = 0usize;
    for p in &projected {
        // Brute force over the whole image.
        for py in 0..cam.height {
            for px in 0..cam.width {
                if hand_alpha(p, px, py).is_some() {
                    reached += 1;
                    assert!(
                        (p.px_range[0]..=p.px_range[1]).contains(&px)
                            && (p.py_range[0]..=p.py_range[1]).contains(&py),
                        "Gaussian {} reaches ({px}, {py}) outside {:?} x {:?}",
                        p.id,
                        p.px_range,
                        p.py_range
                    );
                }
            }
        }
        // Tiles listed = tiles touched by the pixel range.
        let mut want = BTreeSet::new();
        for py in p.py_range[0]..=p.py_range[1] {
            for px in p.px_range[0]..=p.px_range[1] {
                want.insert((py / 16) * tiles_x + px / 16);
            }
        }
        let got: BTreeSet<u32> = isect
            .iter()
            .filter(|(_, id)| *id == p.id)
            .map(|&(t, _)| t)
            .collect();
        assert_eq!(got, want, "tiles of Gaussian {}", p.id);
        assert_eq!(p.tile_range.count(), want.len());
    }
    assert!(reached > 1000);
    // No duplicates; sorted by (tile, depth, id).
    let total: usize = projected.iter().map(|p| p.tile_range.count()).sum();
    assert_eq!(isect.len(), total);
    let depth_of = |id: u32| {
        projected
            .iter()
            .find(|p| p.id == id)
            .map(|p| p.depth)
            .unwrap()
    };
    for pair in isect.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let key_a = (a.0, depth_of(a.1), a.1);
        let key_b = (b.0, depth_of(b.1), b.1);
        assert!(key_a < key_b, "{key_a:?} !< {key_b:?}");
        assert!(a.0 < tiles_x * tiles_y && b.0 < tiles_x * tiles_y);
    }
    let ranges = tile_ranges(&isect, tiles_x * tiles_y);
    for (tile, r) in ranges.iter().enumerate() {
        assert!(isect[r[0] as usize..r[1] as usize]
            .iter()
            .all(|&(t, _)| t == tile as u32));
    }
}

#[test]
fn projection_matches_an_independent_matrix_formulation() {
    let cam = posed_camera(80, 56);
    let mut rng = Rng::new(11);
    let g = random_scene(&mut rng, 300, &cam, (-4.0, -0.5), 0);
    let settings = RenderSettings::default();
    let mut checked = 0;
    for i in 0..g.len() {
        let Ok(p) = project_one(&g, i, &cam, &settings) else {
            continue;
        };
        checked += 1;
        let q = g.quats[i].map(f64::from);
        let rot = DMat3::from_quat(DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize());
        let s = DVec3::from(g.log_scales[i].map(|v| f64::from(v).exp()));
        let m = rot * DMat3::from_diagonal(s);
        let mean = DVec3::from(g.means[i].map(f64::from));
        let pc = cam.rotation * mean + cam.translation;
        let (w, h) = (f64::from(cam.width), f64::from(cam.height));
        let limx = (
            cam.cx / cam.fx + 0.3 * 0.5 * w / cam.fx,
            (w - cam.cx) / cam.fx + 0.3 * 0.5 * w / cam.fx,
        );
        let limy = (
            cam.cy / cam.fy + 0.3 * 0.5 * h / cam.fy,
            (h - cam.cy) / cam.fy + 0.3 * 0.5 * h / cam.fy,
        );
        let tx = pc.z * (pc.x / pc.z).clamp(-limx.0, limx.1);
        let ty = pc.z * (pc.y / pc.z).clamp(-limy.0, limy.1);
        // J as a 3x3 with a zero third row (glam takes columns).
        let j = DMat3::from_cols(
            DVec3::new(cam.fx / pc.z, 0.0, 0.0),
            DVec3::new(0.0, cam.fy / pc.z, 0.0),
            DVec3::new(
                -cam.fx * tx / (pc.z * pc.z),
                -cam.fy * ty / (pc.z * pc.z),
                0.0,
            ),
        );
        let t = j * cam.rotation * m;
        let cov = t * t.transpose();
        let want = [cov.x_axis.x + 0.3, cov.y_axis.x, cov.y_axis.y + 0.3];
        let scale = want[0].max(want[2]);
        for k in 0..3 {
            assert!(
                (p.cov2d[k] - want[k]).abs() <= 1e-10 * scale,
                "Gaussian {i} cov2d[{k}]: {} vs {}",
                p.cov2d[k],
                want[k]
            );
        }
        assert_close(p.depth, pc.z, 1e-14, "depth");
        assert_close(p.mean2d.x, cam.fx * pc.x / pc.z + cam.cx, 1e-12, "u");
        assert_close(p.mean2d.y, cam.fy * pc.y / pc.z + cam.cy, 1e-12, "v");
    }
    assert!(checked > 100);
}

#[test]
fn tiled_render_equals_brute_force_over_all_gaussians() {
    let cam = posed_camera(80, 56);
    let mut rng = Rng::new(3);
    let g = random_scene(&mut rng, 400, &cam, (-3.5, -1.0), 0);
    let bg = [0.3, 0.1, 0.7];
    let settings = RenderSettings {
        background: bg,
        ..Default::default()
    };
    let img = render(&g, &cam, &settings);
    let mut order = project(&g, &cam, &settings);
    order.sort_by(|a, b| a.depth.total_cmp(&b.depth).then(a.id.cmp(&b.id)));
    let mut stopped_early = 0;
    for py in 0..cam.height {
        for px in 0..cam.width {
            let (mut t, mut rgb, mut n, mut stopped) = (1.0f64, [0.0f64; 3], 0u32, false);
            for p in &order {
                let Some(alpha) = hand_alpha(p, px, py) else {
                    continue;
                };
                let next_t = t * (1.0 - alpha);
                if next_t <= 1e-4 {
                    stopped = true;
                    break;
                }
                for ch in 0..3 {
                    rgb[ch] += alpha * t * p.color[ch];
                }
                t = next_t;
                n += 1;
            }
            stopped_early += usize::from(stopped);
            let i = img.index(px, py);
            assert_eq!(img.n_contrib[i], n, "pixel ({px}, {py})");
            assert_close(img.final_t[i], t, 1e-13, "T");
            for ch in 0..3 {
                assert_close(img.rgb[i][ch], rgb[ch] + t * bg[ch], 1e-13, "rgb");
            }
        }
    }
    assert!(
        stopped_early > 50,
        "the stop rule was exercised {stopped_early} times"
    );
}

// ---------------------------------------------------------------- culling

#[test]
fn culling() {
    let cam = camera(64, 48, 50.0, 32.0, 24.0);
    let settings = RenderSettings::default();
    let cull = |s: Spec, settings: &RenderSettings| project_one(&scene(&[s]), 0, &cam, settings);
    let base = |mean: [f32; 3]| iso(mean, -2.0, 2.0, [0.0; 3]);

    assert!(cull(base([0.0, 0.0, 2.0]), &settings).is_ok());
    assert_eq!(cull(base([0.0, 0.0, -2.0]), &settings), Err(Culled::Depth));
    assert_eq!(cull(base([0.0, 0.0, 0.005]), &settings), Err(Culled::Depth));
    assert_eq!(cull(base([0.0, 0.0, 0.0]), &settings), Err(Culled::Depth));
    // Exactly at near and far (values exact in f32).
    let clip = RenderSettings {
        near: 0.5,
        far: 64.0,
        ..Default::default()
    };
    assert_eq!(cull(base([0.0, 0.0, 0.5]), &clip), Err(Culled::Depth));
    assert!(cull(base([0.0, 0.0, 0.5001]), &clip).is_ok());
    assert_eq!(cull(base([0.0, 0.0, 64.0]), &clip), Err(Culled::Depth));
    assert!(cull(base([0.0, 0.0, 63.9]), &clip).is_ok());

    let mut zero_q = base([0.0, 0.0, 2.0]);
    zero_q.quat = [0.0; 4];
    assert_eq!(cull(zero_q, &settings), Err(Culled::ZeroQuaternion));

    // sigmoid(-6) = 0.00247 < 1/255 = 0.00392 < sigmoid(-5) = 0.0067.
    let mut faint = base([0.0, 0.0, 2.0]);
    faint.logit = -6.0;
    assert_eq!(cull(faint.clone(), &settings), Err(Culled::Opacity));
    faint.logit = -5.0;
    assert!(cull(faint, &settings).is_ok());

    // Off-screen: u = 50 * 5 + 32 = 282, far beyond the extent of a small Gaussian.
    assert_eq!(
        cull(base([10.0, 0.0, 2.0]), &settings),
        Err(Culled::OffScreen)
    );
    assert_eq!(
        cull(base([0.0, -4.0, 2.0]), &settings),
        Err(Culled::OffScreen)
    );
    // Center off-screen, extent reaching in: visible, range clamped to the image.
    let p = cull(iso([-1.4, 0.0, 2.0], -1.0, 2.0, [0.0; 3]), &settings).unwrap();
    assert!(p.mean2d.x < 0.0);
    assert_eq!(p.px_range[0], 0);

    let mut nan = base([0.0, 0.0, 2.0]);
    nan.mean[0] = f32::NAN;
    assert_eq!(cull(nan, &settings), Err(Culled::NonFinite));

    // `project` keeps only the visible ones, in id order.
    let g = scene(&[
        base([0.0, 0.0, -1.0]),
        base([0.1, 0.0, 2.0]),
        base([10.0, 0.0, 2.0]),
        base([0.0, 0.1, 3.0]),
    ]);
    let ids: Vec<u32> = project(&g, &cam, &settings).iter().map(|p| p.id).collect();
    assert_eq!(ids, vec![1, 3]);
}

// ---------------------------------------------------------------- spherical harmonics

fn factorial(n: i32) -> f64 {
    (1..=n).map(f64::from).product()
}

/// Associated Legendre P_l^m(x) with the Condon-Shortley phase, m >= 0, by the standard
/// recurrences.
fn legendre(l: i32, m: i32, x: f64) -> f64 {
    let mut pmm = 1.0;
    let s = (1.0 - x * x).max(0.0).sqrt();
    for k in 1..=m {
        pmm *= -(2.0 * f64::from(k) - 1.0) * s;
    }
    if l == m {
        return pmm;
    }
    let mut pmmp1 = x * (2.0 * f64::from(m) + 1.0) * pmm;
    for ll in (m + 2)..=l {
        let pll = (x * (2.0 * f64::from(ll) - 1.0) * pmmp1 - f64::from(ll + m - 1) * pmm)
            / f64::from(ll - m);
        pmm = pmmp1;
        pmmp1 = pll;
    }
    pmmp1
}

/// Real spherical harmonic Y_l^m in the 3DGS convention (Condon-Shortley phase kept).
fn real_sh(l: i32, m: i32, dir: DVec3) -> f64 {
    let theta_cos = dir.z;
    let phi = dir.y.atan2(dir.x);
    let am = m.abs();
    let k = ((2.0 * f64::from(l) + 1.0) / (4.0 * std::f64::consts::PI) * factorial(l - am)
        / factorial(l + am))
    .sqrt();
    let p = legendre(l, am, theta_cos);
    match m.cmp(&0) {
        std::cmp::Ordering::Equal => k * p,
        std::cmp::Ordering::Greater => {
            std::f64::consts::SQRT_2 * k * (f64::from(m) * phi).cos() * p
        }
        std::cmp::Ordering::Less => std::f64::consts::SQRT_2 * k * (f64::from(am) * phi).sin() * p,
    }
}

fn random_dir(rng: &mut Rng) -> DVec3 {
    DVec3::new(rng.normal(), rng.normal(), rng.normal()).normalize()
}

#[test]
fn sh_degree_zero_through_the_pipeline() {
    let cam = camera(64, 48, 50.0, 32.0, 24.0);
    let dc = [0.7f32, -0.3, -3.0];
    let g = scene(&[iso([0.2, -0.1, 2.0], -2.0, 2.0, dc)]);
    let p = project_one(&g, 0, &cam, &RenderSettings::default()).unwrap();
    for ch in 0..3 {
        let want = (0.282_094_791_773_878_14 * f64::from(dc[ch]) + 0.5).max(0.0);
        assert_eq!(p.color[ch], want);
    }
    assert_eq!(p.color[2], 0.0, "negative colors clamp to 0");
}

#[test]
fn sh_basis_matches_associated_legendre() {
    let mut rng = Rng::new(5);
    for _ in 0..200 {
        let d = random_dir(&mut rng);
        let ours = sh_basis(d);
        for l in 0..=3 {
            for m in -l..=l {
                let k = (l * l + l + m) as usize;
                let want = real_sh(l, m, d);
                assert!(
                    (ours[k] - want).abs() < 1e-12,
                    "l={l} m={m} at {d:?}: {} vs {want}",
                    ours[k]
                );
            }
        }
        // eval_sh with a one-hot coefficient picks out that basis function, per channel,
        // at every degree that includes it.
        for degree in 0..=3u32 {
            let n = ((degree + 1) * (degree + 1)) as usize;
            for k in 0..n {
                let mut coeffs = vec![[0.0; 3]; n];
                coeffs[k] = [1.0, -2.0, 0.5];
                let v = eval_sh(degree, &coeffs, d);
                assert!((v[0] - ours[k]).abs() < 1e-15);
                assert!((v[1] + 2.0 * ours[k]).abs() < 1e-15);
                assert!((v[2] - 0.5 * ours[k]).abs() < 1e-15);
            }
        }
    }
}

#[test]
fn sh_basis_is_orthonormal_by_quadrature() {
    // Gauss-Legendre in cos(theta) (exact for the polynomials in cos(theta) that survive
    // the phi integral) times a uniform rule in phi (exact for trigonometric polynomials
    // of degree < np): the Gram matrix must be the identity to rounding.
    let (nt, np) = (10, 16);
    let mut nodes = Vec::new();
    for i in 0..nt {
        let mut x = (std::f64::consts::PI * (f64::from(i) + 0.75) / (f64::from(nt) + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let p = legendre(nt, 0, x);
            let p1 = legendre(nt - 1, 0, x);
            dp = f64::from(nt) * (x * p - p1) / (x * x - 1.0);
            let dx = p / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        nodes.push((x, 2.0 / ((1.0 - x * x) * dp * dp)));
    }
    let wsum: f64 = nodes.iter().map(|n| n.1).sum();
    assert!((wsum - 2.0).abs() < 1e-13);
    let mut gram = [[0.0f64; 16]; 16];
    for &(ct, wt) in &nodes {
        let st = (1.0 - ct * ct).sqrt();
        for j in 0..np {
            let phi = (f64::from(j) + 0.5) * 2.0 * std::f64::consts::PI / f64::from(np);
            let d = DVec3::new(st * phi.cos(), st * phi.sin(), ct);
            let b = sh_basis(d);
            let w = wt * (2.0 * std::f64::consts::PI / f64::from(np));
            for a in 0..16 {
                for c in 0..16 {
                    gram[a][c] += w * b[a] * b[c];
                }
            }
        }
    }
    for (a, row) in gram.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            let want = if a == c { 1.0 } else { 0.0 };
            assert!((v - want).abs() < 1e-12, "<Y{a}, Y{c}> = {v}");
        }
    }
}

#[test]
fn sh_odd_bands_flip_under_opposite_direction() {
    let mut rng = Rng::new(9);
    for _ in 0..50 {
        let d = random_dir(&mut rng);
        let coeffs: Vec<[f64; 3]> = (0..16)
            .map(|_| [rng.normal(), rng.normal(), rng.normal()])
            .collect();
        let band = |k: usize| (k as f64).sqrt().floor() as usize;
        let odd: Vec<[f64; 3]> = (0..16)
            .map(|k| {
                if band(k) % 2 == 1 {
                    coeffs[k]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let even: Vec<[f64; 3]> = (0..16)
            .map(|k| {
                if band(k) % 2 == 0 {
                    coeffs[k]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let (o1, o2) = (eval_sh(3, &odd, d), eval_sh(3, &odd, -d));
        let (e1, e2) = (eval_sh(3, &even, d), eval_sh(3, &even, -d));
        let full = eval_sh(3, &coeffs, d);
        for ch in 0..3 {
            assert!((o1[ch] + o2[ch]).abs() < 1e-13);
            assert!((e1[ch] - e2[ch]).abs() < 1e-13);
            assert!((full[ch] - o1[ch] - e1[ch]).abs() < 1e-13);
            assert!(o1[ch].abs() > 1e-6 || e1[ch].abs() > 1e-6);
        }
    }
}

#[test]
fn sh_degree_setting_caps_evaluation() {
    let cam = camera(64, 48, 50.0, 32.0, 24.0);
    let mut s = iso([0.3, 0.2, 2.0], -2.0, 2.0, [0.1, 0.2, 0.3]);
    s.sh = (0..16).map(|k| [0.05 * k as f32, -0.03, 0.02]).collect();
    let g = scene(&[s.clone()]);
    assert_eq!(g.sh_degree, 3);
    let dir = DVec3::new(f64::from(0.3f32), f64::from(0.2f32), 2.0).normalize();
    let coeffs: Vec<[f64; 3]> = s.sh.iter().map(|c| c.map(f64::from)).collect();
    for degree in 0..=3u32 {
        let settings = RenderSettings {
            sh_degree: Some(degree),
            ..Default::default()
        };
        let p = project_one(&g, 0, &cam, &settings).unwrap();
        let raw = eval_sh(degree, &coeffs, dir);
        for ch in 0..3 {
            assert_close(p.color[ch], (raw[ch] + 0.5).max(0.0), 1e-14, "color");
        }
    }
    let p_none = project_one(&g, 0, &cam, &RenderSettings::default()).unwrap();
    let raw = eval_sh(3, &coeffs, dir);
    assert_close(
        p_none.color[0],
        (raw[0] + 0.5).max(0.0),
        1e-14,
        "full degree",
    );
}

// ---------------------------------------------------------------- semantics (Gaussian Semantics Eq. 2)

fn softmax(v: &[f32]) -> Vec<f64> {
    let e: Vec<f64> = v.iter().map(|&x| f64::from(x).exp()).collect();
    let s: f64 = e.iter().sum();
    e.iter().map(|x| x / s).collect()
}

#[test]
fn eq2_normalization_of_a_single_gaussian() {
    let cam = camera(64, 48, 50.0, 32.0, 24.0);
    let logits = vec![2.0f32, -1.0, 0.5, 0.0];
    let mut s = iso([0.0, 0.0, 2.0], -2.0, 1.0, [0.0; 3]);
    s.logits = logits.clone();
    let g = scene(&[s]);
    for mode in [SemanticMode::RawLogits, SemanticMode::Softmax] {
        let settings = RenderSettings {
            semantic_mode: mode,
            ..Default::default()
        };
        let img = render(&g, &cam, &settings);
        assert_eq!(img.channels, 4);
        assert_eq!(img.sem.len(), 64 * 48 * 4);
        let want: Vec<f64> = match mode {
            SemanticMode::RawLogits => logits.iter().map(|&v| f64::from(v)).collect(),
            SemanticMode::Softmax => softmax(&logits),
        };
        let mut covered = 0;
        for py in 0..cam.height {
            for px in 0..cam.width {
                let a = img.alpha_at(px, py);
                if a == 0.0 {
                    assert!(img.sem_norm_at(px, py).iter().all(|&v| v == 0.0));
                    assert!(img.sem_at(px, py).iter().all(|&v| v == 0.0));
                    continue;
                }
                covered += 1;
                for c in 0..4 {
                    assert_close(img.sem_norm_at(px, py)[c], want[c], 1e-12, "sem_norm");
                    assert_close(img.sem_at(px, py)[c], a * want[c], 1e-13, "sem");
                }
            }
        }
        assert!(covered > 100);
    }
    // RGB only.
    let img = render(
        &g,
        &cam,
        &RenderSettings {
            semantics: false,
            ..Default::default()
        },
    );
    assert_eq!(img.channels, 0);
    assert!(img.sem.is_empty() && img.sem_norm.is_empty());
}

#[test]
fn weights_sum_to_one_minus_final_t() {
    let cam = posed_camera(80, 56);
    let mut rng = Rng::new(21);
    let channels = 3;
    let g = random_scene(&mut rng, 400, &cam, (-3.5, -1.0), channels);
    let bg = [0.25, 0.5, 0.75];
    let settings = RenderSettings {
        background: bg,
        semantic_mode: SemanticMode::Softmax,
        ..Default::default()
    };
    let img = render(&g, &cam, &settings);
    let projected = project(&g, &cam, &settings);
    let by_id = |id: u32| projected.iter().find(|p| p.id == id).unwrap();
    let npix = (cam.width * cam.height) as usize;
    let mut wsum = vec![0.0f64; npix];
    let mut count = vec![0u32; npix];
    let mut rgb = vec![[0.0f64; 3]; npix];
    let mut sem = vec![0.0f64; npix * channels];
    let mut last_depth = vec![f64::NEG_INFINITY; npix];
    let sem_logits = &g.semantics.as_ref().unwrap().logits;
    for_each_contribution(&g, &cam, &settings, |px, py, id, w| {
        let i = (py * cam.width + px) as usize;
        let p = by_id(id);
        assert!(w > 0.0 && w <= 0.999);
        assert!(p.depth >= last_depth[i], "front to back");
        last_depth[i] = p.depth;
        wsum[i] += w;
        count[i] += 1;
        for ch in 0..3 {
            rgb[i][ch] += w * p.color[ch];
        }
        let s = softmax(&sem_logits[id as usize * channels..(id as usize + 1) * channels]);
        for c in 0..channels {
            sem[i * channels + c] += w * s[c];
        }
    });
    let mut covered = 0;
    for i in 0..npix {
        assert_close(wsum[i], 1.0 - img.final_t[i], 1e-12, "sum of weights");
        assert_close(wsum[i], img.alpha[i], 1e-12, "alpha");
        assert_eq!(count[i], img.n_contrib[i]);
        for ch in 0..3 {
            assert_close(
                rgb[i][ch] + img.final_t[i] * bg[ch],
                img.rgb[i][ch],
                1e-12,
                "rgb",
            );
        }
        for c in 0..channels {
            assert_close(
                sem[i * channels + c],
                img.sem[i * channels + c],
                1e-12,
                "sem",
            );
        }
        if img.alpha[i] > 0.0 {
            covered += 1;
            // Softmax channels normalized by 1 - T sum to one.
            let total: f64 = img.sem_norm[i * channels..(i + 1) * channels].iter().sum();
            assert_close(total, 1.0, 1e-12, "normalized softmax sums to 1");
        }
    }
    assert!(covered > npix / 2);
}

// ---------------------------------------------------------------- speed

#[test]
fn renders_20k_gaussians_quickly() {
    let cam = posed_camera(128, 96);
    let mut rng = Rng::new(1);
    let g = random_scene(&mut rng, 20_000, &cam, (-5.0, -2.5), 8);
    let start = std::time::Instant::now();
    let img = render(&g, &cam, &RenderSettings::default());
    let secs = start.elapsed().as_secs_f64();
    eprintln!("reference render: 20k Gaussians at 128x96 in {secs:.3} s");
    assert!(img.alpha.iter().any(|&a| a > 0.5));
    if !cfg!(debug_assertions) {
        assert!(secs < 1.0, "took {secs:.3} s");
    }
}
