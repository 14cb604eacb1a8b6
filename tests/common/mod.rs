//! Shared test fixture: one Vulkan device per test binary, with the Khronos validation
//! layer and its synchronization validation on. Every GPU test calls `check_validation` at
//! its end: any warning, error or synchronization hazard from the layer fails it.
#![allow(dead_code)]

pub mod cli;
pub mod consensus;
pub mod npy;
pub mod regions;
pub mod spec_scene;

use std::sync::OnceLock;

use glam::DVec3;
use semsplat::gpu::{Gpu, GpuOptions};
use semsplat::scene::{Camera, Gaussians};

pub fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| open_validated(GpuOptions::default()))
}

/// A second and third device handle with the work that has a CPU drivers' form in one form
/// each (`wide`: the CPU forms, `DeviceCaps::cpu_forms`, the default on CPU devices: the
/// `*_wide` kernels, the sort's runs of keys, label regions on the host; else the GPU
/// forms), for tests that run both forms on one machine.
pub fn gpu_with_cpu_forms(wide: bool) -> &'static Gpu {
    static FORMS: [OnceLock<Gpu>; 2] = [OnceLock::new(), OnceLock::new()];
    FORMS[wide as usize].get_or_init(|| {
        open_validated(GpuOptions {
            cpu_forms: Some(wide),
            ..Default::default()
        })
    })
}

/// Device handles with 64-bit integer atomics left off (`GpuOptions::without_int64_atomics`),
/// in each form (`gpu_with_cpu_forms`), for the paths of devices without them.
pub fn gpu_without_int64_atomics(wide: bool) -> &'static Gpu {
    static FORMS: [OnceLock<Gpu>; 2] = [OnceLock::new(), OnceLock::new()];
    FORMS[wide as usize].get_or_init(|| {
        open_validated(GpuOptions {
            cpu_forms: Some(wide),
            without_int64_atomics: true,
            ..Default::default()
        })
    })
}

/// The device `options` ask for, with the validation layer on.
fn open_validated(options: GpuOptions) -> Gpu {
    Gpu::with_options(GpuOptions {
        validation: true,
        ..options
    })
    .unwrap_or_else(|e| panic!("tests need a Vulkan device with validation layers: {e}"))
}

pub fn check_validation(gpu: &Gpu) {
    assert!(
        gpu.validation_enabled(),
        "validation layer must be on in tests"
    );
    assert!(
        gpu.sync_validation_enabled(),
        "synchronization validation must be on in tests"
    );
    let messages = gpu.validation_messages();
    assert!(
        messages.is_empty(),
        "validation layer reported:\n{}",
        messages.join("\n")
    );
}

/// One 16x16 view whose single tile lists `n` faint Gaussians, each covering about one
/// pixel, in front of one bright Gaussian (index `n`) that sits last in depth order: a
/// per-tile walk cut off by lavapipe's loop cap (65,535 iterations) misses the bright one.
pub fn long_tile(n: usize) -> (Gaussians, Camera) {
    let cam = Camera::look_at("tile", DVec3::ZERO, DVec3::Z, -DVec3::Y, 16, 16, 60.0);
    let mut rng = semsplat::util::Rng::new(5);
    let mut g = Gaussians::default();
    for i in 0..=n {
        let (z, px, py, logit, scale) = if i < n {
            (
                2.0 + i as f64 * 1e-5,
                rng.below(16) as f64 + 0.5,
                rng.below(16) as f64 + 0.5,
                -5.3,
                1e-4,
            )
        } else {
            (10.0, 8.0, 8.0, 3.0, 5.0)
        };
        let x = (px - cam.cx) / cam.fx * z;
        let y = (py - cam.cy) / cam.fy * z;
        g.means.push([x as f32, y as f32, z as f32]);
        g.log_scales.push([(scale as f32).ln(); 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity_logits.push(logit as f32);
        let dc = if i < n { -1.0 } else { 3.0 };
        g.sh.extend([dc, -1.0, -1.0]);
    }
    (g, cam)
}

/// Deterministic pseudo-random u32s.
pub fn random_u32(n: usize, seed: u64) -> Vec<u32> {
    let mut rng = semsplat::util::Rng::new(seed);
    (0..n).map(|_| rng.next_u32()).collect()
}

/// Moves apart Gaussians whose depths in this view are closer than float32 can order:
/// the GPU sorts by f32 depth (then index), the reference by f64 depth, so a near-tie may
/// order differently, which is not what these tests are about. Nudges along the view axis
/// by a few ulps of depth; every other Gaussian is untouched.
pub fn separate_depth_ties(g: &Gaussians, cam: &Camera) -> Gaussians {
    let mut g = g.clone();
    let forward = cam.rotation.transpose() * DVec3::Z;
    let depth = |m: [f32; 3]| {
        cam.world_to_camera(DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64))
            .z
    };
    let mut order: Vec<usize> = (0..g.len()).collect();
    order.sort_by(|&a, &b| depth(g.means[a]).total_cmp(&depth(g.means[b])));
    let mut prev = f64::NEG_INFINITY;
    for &i in &order {
        let z = depth(g.means[i]);
        let gap = 2e-6 * z.abs().max(1e-3);
        if z - prev < gap {
            let shift = forward * (prev + 2.0 * gap - z);
            let m = &mut g.means[i];
            *m = [
                m[0] + shift.x as f32,
                m[1] + shift.y as f32,
                m[2] + shift.z as f32,
            ];
        }
        prev = depth(g.means[i]);
    }
    g
}

/// Per pixel of `cam`, the median depth written plainly from the f64 reference's
/// contributions: the camera-space depth of the Gaussian that takes the pixel's
/// transmittance below one half, 0 where none does. None where a step lands within 1e-5 of
/// one half, where float32 may take the neighbouring Gaussian.
pub fn reference_median_depth(g: &Gaussians, cam: &Camera) -> Vec<Option<f64>> {
    reference_depth_below(g, cam, 0.5)
}

/// Per pixel of `cam`, the camera-space depth of the Gaussian that takes the pixel's
/// transmittance below `threshold`, written plainly from the f64 reference's steps (a
/// Gaussian that saturates the pixel counts), 0 where none does; None where a step lands
/// within 1e-5 of the threshold, where float32 may take the neighbouring Gaussian.
pub fn reference_depth_below(g: &Gaussians, cam: &Camera, threshold: f64) -> Vec<Option<f64>> {
    use semsplat::render::reference::{for_each_step, RenderSettings};
    let pixels = (cam.width * cam.height) as usize;
    let mut found = vec![false; pixels];
    let mut depth = vec![Some(0.0); pixels];
    let settings = RenderSettings {
        semantics: false,
        ..Default::default()
    };
    for_each_step(g, cam, &settings, |px, py, id, t, alpha| {
        let i = (py * cam.width + px) as usize;
        if found[i] {
            return;
        }
        let next = t * (1.0 - alpha);
        if (next - threshold).abs() < 1e-5 {
            depth[i] = None;
        }
        if next < threshold {
            found[i] = true;
            let m = g.means[id as usize];
            let z = cam
                .world_to_camera(DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64))
                .z;
            depth[i] = depth[i].map(|_| z);
        }
    });
    depth
}
