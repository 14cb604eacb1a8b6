//! The Vulkan compute layer: device context, buffers, kernels from the reflected table,
//! command recording with timestamp timers, and the radix sort and prefix scan.

pub mod kernel_table;
