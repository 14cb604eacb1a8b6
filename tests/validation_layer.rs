//! The validation harness itself: a deliberate misuse must be reported, so a silent layer
//! in the other tests means something. Each test runs on its own device (its own message
//! log).

use semsplat::gpu::{Gpu, GpuOptions, Recorder};

fn validated_gpu() -> Gpu {
    let gpu = Gpu::with_options(GpuOptions {
        validation: true,
        device: None,
        ..Default::default()
    })
    .expect("Vulkan device");
    assert!(gpu.validation_enabled());
    gpu
}

#[test]
fn validation_layer_reports_misuse() {
    let gpu = validated_gpu();
    let buf = gpu.buffer("b", 64).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    // vkCmdFillBuffer's size must be a multiple of 4: the layer must flag this.
    rec.fill(&buf, 0, 6, 0);
    rec.submit_and_wait().unwrap();
    let messages = gpu.validation_messages();
    assert!(
        messages.iter().any(|m| m.contains("vkCmdFillBuffer")),
        "expected a vkCmdFillBuffer validation error, got: {messages:?}"
    );
}

#[test]
fn sync_validation_reports_hazards() {
    let gpu = validated_gpu();
    assert!(
        gpu.sync_validation_enabled(),
        "the validation layer must run its synchronization validation"
    );
    let buf = gpu.buffer("b", 64).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    // Two writes of the same range with no barrier between: a write-after-write race on a
    // GPU that overlaps commands, which only the synchronization validation sees.
    rec.fill(&buf, 0, 64, 0);
    rec.fill(&buf, 0, 64, 1);
    rec.submit_and_wait().unwrap();
    let messages = gpu.validation_messages();
    assert!(
        messages
            .iter()
            .any(|m| m.contains("SYNC-HAZARD-WRITE-AFTER-WRITE")),
        "expected a SYNC-HAZARD-WRITE-AFTER-WRITE report, got: {messages:?}"
    );
}

#[test]
fn sync_validation_accepts_barrier() {
    let gpu = validated_gpu();
    let buf = gpu.buffer("b", 64).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    // The same two writes with `barrier()` between are ordered: nothing to report.
    rec.fill(&buf, 0, 64, 0);
    rec.barrier();
    rec.fill(&buf, 0, 64, 1);
    rec.submit_and_wait().unwrap();
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "unexpected reports: {messages:?}");
}
