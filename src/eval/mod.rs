//! Evaluation: segmentation metrics, image quality, label maps rendered from lifted scenes,
//! and (with the `charts` feature) charts and image strips.

#[cfg(feature = "charts")]
pub mod chart;
pub mod image_quality;
pub mod label_render;
pub mod metrics;
#[cfg(feature = "charts")]
pub mod strip;
