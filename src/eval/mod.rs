//! Evaluation: segmentation metrics, label maps rendered from lifted scenes, the method
//! benchmark on synthetic scenes with exact truth, and charts.

pub mod benchmark;
pub mod chart;
pub mod image_quality;
pub mod label_render;
pub mod metrics;
pub mod strip;
