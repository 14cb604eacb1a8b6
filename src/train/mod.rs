//! Joint optimization (Gaussian Semantics): losses, Adam, densification, and the training loop.

pub mod adam;
pub mod config;
pub mod densify;
pub mod loss;
pub mod loss_entropy;
pub mod loss_values;
mod tensors;
pub mod trainer;
pub mod views;
