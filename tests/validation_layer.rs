//! The validation harness itself: a deliberate misuse must be reported, so a silent layer
//! in the other tests means something. Runs on its own device (its own message log).

use semsplat::gpu::{Gpu, GpuOptions, Recorder};

#[test]
fn validation_layer_reports_misuse() {
    let gpu = Gpu::with_options(GpuOptions {
        validation: true,
        device: None,
    })
    .expect("Vulkan device");
    assert!(gpu.validation_enabled());
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
