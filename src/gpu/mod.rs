//! The Vulkan compute layer: device context, buffers, kernels from the reflected table,
//! command recording with timestamp timers, and the radix sort and prefix scan.

pub mod buffer;
pub mod caps;
pub mod context;
pub mod count;
pub mod error;
pub mod kernel;
pub mod kernel_table;
pub mod recorder;
pub mod scan;
pub mod sort;
pub mod staging;
pub mod timings;
mod validation;

pub use buffer::Buffer;
pub use caps::DeviceCaps;
pub use context::{list_devices, Gpu, GpuOptions};
pub use count::GpuCount;
pub use error::{GpuError, GpuResult};
pub use kernel_table::{ids, KernelId, KERNELS};
pub use recorder::{BufferRange, Recorder, Submission};
pub use scan::PrefixScan;
pub use sort::RadixSort;
pub use staging::Staging;
pub use timings::{Mark, Timings};
