//! Inputs of the consensus methods built from a synthetic room.

use semsplat::dataset::CompactClasses;
use semsplat::fuse::{ConsensusInput, GaussianShapes, LabelSource};
use semsplat::gpu::Gpu;
use semsplat::render::GpuScene;
use semsplat::synth::SynthScene;

/// The room's noisy label maps in compact class ids.
pub fn noisy_maps(s: &SynthScene, classes: &CompactClasses) -> Vec<Option<Vec<u32>>> {
    let maps = &s.noisy.as_ref().expect("a noisy room").maps;
    maps.iter()
        .map(|m| Some(classes.compact_labels(m)))
        .collect()
}

/// The room's train cameras and centers with `labels`, on `scene`.
pub fn input<'a>(
    gpu: &'a Gpu,
    scene: &'a GpuScene,
    s: &'a SynthScene,
    labels: &'a dyn LabelSource,
    classes: usize,
) -> ConsensusInput<'a> {
    ConsensusInput {
        gpu,
        scene,
        shapes: GaussianShapes::of(&s.gaussians),
        cams: &s.cameras,
        labels,
        classes,
    }
}
