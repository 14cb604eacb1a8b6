//! semsplat: lift 2D semantic labels into 3D Gaussian Splatting scenes on a Vulkan compute
//! backend. See README.md for the architecture.

pub mod bench;
pub mod contract;
pub mod dataset;
pub mod eval;
pub mod experiment;
pub mod fuse;
pub mod gpu;
pub mod render;
pub mod scene;
pub mod synth;
pub mod train;
pub mod util;
