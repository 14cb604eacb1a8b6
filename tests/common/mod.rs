//! Shared test fixture: one Vulkan device per test binary, with the Khronos validation
//! layer and its synchronization validation on. Every GPU test calls `check_validation` at
//! its end: any warning, error or synchronization hazard from the layer fails it.
#![allow(dead_code)]

pub mod cli;
pub mod consensus;
pub mod regions;
pub mod spec_scene;

use std::sync::OnceLock;

use glam::DVec3;
use semsplat::gpu::{Gpu, GpuOptions};
use semsplat::scene::{Camera, Gaussians};

pub fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        Gpu::with_options(GpuOptions {
            validation: true,
            device: None,
            ..Default::default()
        })
        .unwrap_or_else(|e| panic!("tests need a Vulkan device with validation layers: {e}"))
    })
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
