//! Shared test fixture: one Vulkan device per test binary, with the Khronos validation
//! layer on. Every GPU test calls `check_validation` at its end: any warning or error from
//! the layer fails it.
#![allow(dead_code)]

use std::sync::OnceLock;

use semsplat::gpu::{Gpu, GpuOptions};

pub fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        Gpu::with_options(GpuOptions {
            validation: true,
            device: None,
        })
        .unwrap_or_else(|e| panic!("tests need a Vulkan device with validation layers: {e}"))
    })
}

pub fn check_validation(gpu: &Gpu) {
    assert!(
        gpu.validation_enabled(),
        "validation layer must be on in tests"
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
