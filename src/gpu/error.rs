//! Errors from the Vulkan layer. Environment problems (no loader, no device, missing
//! features) carry a message that says what is missing and how to get lavapipe.

use ash::vk;
use thiserror::Error;

pub const SETUP_HINT: &str =
    "install a Vulkan driver; on a machine without a GPU, `sudo bash tools/setup.sh` installs lavapipe (Mesa's CPU Vulkan driver)";

/// What to change when a buffer does not fit: said by every allocation error.
pub const TOO_LARGE_HINT: &str =
    "the input is too large for this device: use smaller images or fewer Gaussians (fuse: or fewer classes per pass, --mem-budget)";

/// A byte count for people: 1536 -> "1.5 KiB".
pub fn human_bytes(bytes: &u64) -> String {
    let units = ["bytes", "KiB", "MiB", "GiB", "TiB"];
    let mut value = *bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} bytes")
    } else {
        format!("{value:.1} {}", units[unit])
    }
}

/// The remedy after an allocation error, when it allocated something (not the allocator).
fn too_large_hint(size: &u64) -> String {
    if *size == 0 {
        String::new()
    } else {
        format!("; {TOO_LARGE_HINT}")
    }
}

#[derive(Debug, Error)]
pub enum GpuError {
    #[error("cannot load the Vulkan loader (libvulkan.so.1): {0}; {SETUP_HINT}")]
    NoLoader(String),
    #[error("no Vulkan device found; {SETUP_HINT}")]
    NoDevice,
    #[error("no usable Vulkan device:\n{0}\n{SETUP_HINT}")]
    NoSuitableDevice(String),
    #[error("SEMSPLAT_DEVICE={wanted:?} matches no device; devices are:\n{available}")]
    DeviceNotFound { wanted: String, available: String },
    #[error("the Vulkan validation layer (VK_LAYER_KHRONOS_validation) was requested but is not installed; {SETUP_HINT}")]
    NoValidationLayer,
    #[error("{what} failed: {result}")]
    Vulkan {
        what: &'static str,
        result: vk::Result,
    },
    #[error("GPU buffer '{name}' of {size} bytes ({}) could not be created ({what}: {result}); {TOO_LARGE_HINT}", human_bytes(.size))]
    Buffer {
        name: String,
        size: u64,
        what: &'static str,
        result: vk::Result,
    },
    #[error("GPU memory allocation of {size} bytes ({}) for '{name}' failed: {source}{}", human_bytes(.size), too_large_hint(.size))]
    Allocation {
        name: String,
        size: u64,
        #[source]
        source: gpu_allocator::AllocationError,
    },
    #[error("{0}")]
    Limit(String),
    /// One buffer range larger than a descriptor may address. Kept apart from `Limit` so a
    /// command that knows a better remedy (fuse: a tiled method) can say it instead.
    #[error("{}: {BINDING_REMEDY}", binding_fact(.kernel, .buffer, *.bytes, *.max))]
    BindingRange {
        kernel: String,
        buffer: String,
        bytes: u64,
        max: u64,
    },
}

/// What helps when a binding is too large, said where the caller knows nothing better.
pub const BINDING_REMEDY: &str = "use a smaller image, fewer classes or fewer Gaussians";

impl GpuError {
    /// A `BindingRange` error's fact alone, without the generic remedy; for any other error,
    /// its message.
    pub fn fact(&self) -> String {
        match self {
            GpuError::BindingRange {
                kernel,
                buffer,
                bytes,
                max,
            } => binding_fact(kernel, buffer, *bytes, *max),
            other => other.to_string(),
        }
    }
}

fn binding_fact(kernel: &str, buffer: &str, bytes: u64, max: u64) -> String {
    format!(
        "{kernel}: buffer '{buffer}' needs a {bytes}-byte binding, over the device's {max}-byte \
         binding limit (maxStorageBufferRange)"
    )
}

pub type GpuResult<T> = Result<T, GpuError>;

/// Attaches a description to a raw Vulkan result.
pub(crate) trait VkContext<T> {
    fn vk(self, what: &'static str) -> GpuResult<T>;
}

impl<T> VkContext<T> for Result<T, vk::Result> {
    fn vk(self, what: &'static str) -> GpuResult<T> {
        self.map_err(|result| GpuError::Vulkan { what, result })
    }
}
