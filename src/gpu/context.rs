//! The device context: instance (with the validation layer on request), device choice
//! (discrete > integrated > virtual > CPU, `SEMSPLAT_DEVICE` overrides), required features
//! checked up front, the queue, the memory allocator and the cache of built kernels.

use std::collections::HashMap;
use std::ffi::{c_void, CStr};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::caps::{binding_limit, cpu_forms, probe_device, DeviceCaps};
use super::error::{GpuError, GpuResult, VkContext};
use super::kernel::Pipeline;
use super::recorder::RecorderParts;
use super::validation::{debug_callback, ValidationLog};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// How to open the device.
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Enable VK_LAYER_KHRONOS_validation, with its synchronization validation, and collect
    /// its warnings and errors (also turned on by `SEMSPLAT_VALIDATION=1`).
    pub validation: bool,
    /// Device index or name substring; defaults to `SEMSPLAT_DEVICE`.
    pub device: Option<String>,
    /// Bytes one storage binding may hold, below the device's `maxStorageBufferRange`
    /// (defaults to `SEMSPLAT_MAX_BINDING`): tests set it so small scenes take the paths
    /// that split work across bindings, as scenes past the real limit do.
    pub max_binding: Option<u64>,
    /// The CPU drivers' forms of the work (`DeviceCaps::cpu_forms`: the `*_wide` kernels,
    /// label regions on the host), or the GPU forms (defaults to `SEMSPLAT_CPU_FORMS`, else
    /// the CPU forms on CPU devices): both give the same results, and tests run each form.
    pub cpu_forms: Option<bool>,
    /// Leave 64-bit integer atomics off even where the device has them, as on a device
    /// without them: the blend backward's fixed point then sums in two 32-bit halves
    /// (`fixed32x2`), and fixed-point fusion is refused. For tests of those paths.
    pub without_int64_atomics: bool,
}

pub(crate) struct Inner {
    pub(crate) _entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    /// With validation: names objects so the layer's messages say which buffer they mean.
    pub(crate) debug_names: Option<ash::ext::debug_utils::Device>,
    pub(crate) validation_log: Arc<ValidationLog>,
    sync_validation: bool,
    pub(crate) device: ash::Device,
    pub(crate) queue: Mutex<vk::Queue>,
    pub(crate) queue_family: u32,
    pub(crate) allocator: Mutex<Option<Allocator>>,
    pub(crate) push_descriptor: ash::khr::push_descriptor::Device,
    pub(crate) caps: DeviceCaps,
    pub(crate) kernels: Mutex<HashMap<usize, Arc<Pipeline>>>,
    /// Finished recorders' pools, reused by the next ones (see `recorder::RecorderParts`).
    pub(crate) recycled_recorders: Mutex<Vec<RecorderParts>>,
}

/// A shared handle to the Vulkan device. Cheap to clone; buffers keep it alive.
#[derive(Clone)]
pub struct Gpu {
    pub(crate) inner: Arc<Inner>,
}

/// A device the loader reports, with why it can or cannot be used.
#[derive(Clone, Debug)]
pub struct DeviceCandidate {
    pub index: usize,
    pub caps: DeviceCaps,
    /// Required features the device lacks (empty: usable).
    pub missing: Vec<String>,
}

fn load_entry() -> GpuResult<ash::Entry> {
    // SAFETY: loading the system Vulkan loader; its initialization has no preconditions.
    unsafe { ash::Entry::load() }.map_err(|e| GpuError::NoLoader(e.to_string()))
}

fn has_layer(entry: &ash::Entry, name: &CStr) -> GpuResult<bool> {
    // SAFETY: plain query.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }
        .vk("vkEnumerateInstanceLayerProperties")?;
    Ok(layers
        .iter()
        .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == name)))
}

/// Whether the validation layer offers VK_EXT_validation_features (how the synchronization
/// validation is switched on).
fn layer_has_validation_features(entry: &ash::Entry) -> GpuResult<bool> {
    // SAFETY: plain query of the layer's instance extensions.
    let exts = unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }
        .vk("vkEnumerateInstanceExtensionProperties")?;
    Ok(exts.iter().any(|e| {
        e.extension_name_as_c_str()
            .is_ok_and(|n| n == ash::ext::validation_features::NAME)
    }))
}

/// The instance; with `validation`, the Khronos layer and debug utils, and with `sync` also
/// the layer's synchronization validation (hazards between commands that lack a barrier).
fn create_instance(entry: &ash::Entry, validation: bool, sync: bool) -> GpuResult<ash::Instance> {
    let app = vk::ApplicationInfo::default()
        .application_name(c"semsplat")
        .engine_name(c"semsplat")
        .api_version(vk::API_VERSION_1_3);
    let layers = if validation {
        vec![VALIDATION_LAYER.as_ptr()]
    } else {
        vec![]
    };
    let mut exts = vec![];
    if validation {
        exts.push(ash::ext::debug_utils::NAME.as_ptr());
    }
    let sync = validation && sync;
    if sync {
        exts.push(ash::ext::validation_features::NAME.as_ptr());
    }
    let enables = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
    let mut features = vk::ValidationFeaturesEXT::default().enabled_validation_features(&enables);
    let mut info = vk::InstanceCreateInfo::default()
        .application_info(&app)
        .enabled_layer_names(&layers)
        .enabled_extension_names(&exts);
    if sync {
        info = info.push_next(&mut features);
    }
    // SAFETY: all pointers in `info` outlive the call.
    unsafe { entry.create_instance(&info, None) }.map_err(|result| match result {
        vk::Result::ERROR_INCOMPATIBLE_DRIVER => GpuError::NoDevice,
        result => GpuError::Vulkan {
            what: "vkCreateInstance",
            result,
        },
    })
}

/// Lists every device the loader reports, with capabilities and missing features.
pub fn list_devices() -> GpuResult<Vec<DeviceCandidate>> {
    let entry = load_entry()?;
    let instance = create_instance(&entry, false, false)?;
    let result = enumerate(&instance);
    // SAFETY: no objects created from this instance remain.
    unsafe { instance.destroy_instance(None) };
    result
}

fn enumerate(instance: &ash::Instance) -> GpuResult<Vec<DeviceCandidate>> {
    // SAFETY: plain query.
    let physicals =
        unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    Ok(physicals
        .iter()
        .enumerate()
        .map(|(index, &pd)| {
            let (caps, missing) = probe_device(instance, pd);
            DeviceCandidate {
                index,
                caps,
                missing,
            }
        })
        .collect())
}

fn type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

fn describe(cands: &[DeviceCandidate]) -> String {
    cands
        .iter()
        .map(|c| {
            let status = if c.missing.is_empty() {
                "usable".to_string()
            } else {
                format!("lacks {}", c.missing.join(", "))
            };
            format!(
                "  [{}] {} ({:?}): {status}",
                c.index, c.caps.name, c.caps.device_type
            )
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Picks the device: `wanted` (index or case-insensitive name substring) if given, else
/// the best usable one by type.
pub fn choose_device(cands: &[DeviceCandidate], wanted: Option<&str>) -> GpuResult<usize> {
    if cands.is_empty() {
        return Err(GpuError::NoDevice);
    }
    let chosen = match wanted.map(str::trim).filter(|w| !w.is_empty()) {
        Some(w) => {
            let found = match w.parse::<usize>() {
                Ok(i) => cands.iter().find(|c| c.index == i),
                Err(_) => {
                    let lw = w.to_lowercase();
                    cands
                        .iter()
                        .find(|c| c.caps.name.to_lowercase().contains(&lw))
                }
            };
            found.ok_or_else(|| GpuError::DeviceNotFound {
                wanted: w.to_string(),
                available: describe(cands),
            })?
        }
        None => cands
            .iter()
            .filter(|c| c.missing.is_empty())
            .min_by_key(|c| (type_rank(c.caps.device_type), c.index))
            .ok_or_else(|| GpuError::NoSuitableDevice(describe(cands)))?,
    };
    if !chosen.missing.is_empty() {
        return Err(GpuError::NoSuitableDevice(describe(std::slice::from_ref(
            chosen,
        ))));
    }
    Ok(chosen.index)
}

impl Gpu {
    /// Opens the device chosen by `SEMSPLAT_DEVICE` or the best usable one.
    pub fn new() -> GpuResult<Gpu> {
        Gpu::with_options(GpuOptions::default())
    }

    pub fn with_options(opts: GpuOptions) -> GpuResult<Gpu> {
        let validation =
            opts.validation || std::env::var("SEMSPLAT_VALIDATION").is_ok_and(|v| v == "1");
        let wanted = opts
            .device
            .or_else(|| std::env::var("SEMSPLAT_DEVICE").ok());
        let entry = load_entry()?;
        if validation && !has_layer(&entry, VALIDATION_LAYER)? {
            return Err(GpuError::NoValidationLayer);
        }
        let sync_validation = validation && layer_has_validation_features(&entry)?;
        let instance = create_instance(&entry, validation, sync_validation)?;
        let validation_log = Arc::new(ValidationLog::default());
        // On any error below, the partially built objects are destroyed by `guard`.
        let mut guard = InstanceGuard {
            instance: Some(instance.clone()),
            debug: None,
        };

        let debug = if validation {
            let debug = create_messenger(&entry, &instance, &validation_log)?;
            guard.debug = Some(debug.clone());
            Some(debug)
        } else {
            None
        };

        let (physical, mut caps) = pick_physical(&instance, wanted.as_deref())?;
        caps.max_storage_buffer_range =
            binding_limit(caps.max_storage_buffer_range, opts.max_binding);
        caps.cpu_forms = cpu_forms(caps.cpu_forms, opts.cpu_forms);
        caps.int64_atomics &= !opts.without_int64_atomics;
        let queue_family = caps
            .compute_queue_family
            .expect("usable device has a compute queue");

        let device = create_device(&instance, physical, &caps, queue_family)?;
        // SAFETY: queue 0 of a family we created the device with.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let allocator = create_allocator(&instance, &device, physical)?;
        let push_descriptor = ash::khr::push_descriptor::Device::new(&instance, &device);
        let debug_names = debug
            .as_ref()
            .map(|_| ash::ext::debug_utils::Device::new(&instance, &device));
        guard.disarm();

        Ok(Gpu {
            inner: Arc::new(Inner {
                _entry: entry,
                instance,
                debug,
                debug_names,
                validation_log,
                sync_validation,
                device,
                queue: Mutex::new(queue),
                queue_family,
                allocator: Mutex::new(Some(allocator)),
                push_descriptor,
                caps,
                kernels: Mutex::new(HashMap::new()),
                recycled_recorders: Mutex::new(Vec::new()),
            }),
        })
    }

    /// What the device is and supports.
    pub fn caps(&self) -> &DeviceCaps {
        &self.inner.caps
    }

    /// Validation-layer warnings and errors collected so far (empty without validation).
    pub fn validation_messages(&self) -> Vec<String> {
        self.inner.validation_log.messages()
    }

    /// Whether the validation layer is on.
    pub fn validation_enabled(&self) -> bool {
        self.inner.debug.is_some()
    }

    /// Whether the layer's synchronization validation is on too (with validation, whenever
    /// the layer offers VK_EXT_validation_features): hazards between commands recorded
    /// without a barrier between them are reported like any other validation error.
    pub fn sync_validation_enabled(&self) -> bool {
        self.validation_enabled() && self.inner.sync_validation
    }

    /// Device memory reserved by the allocator right now (blocks, in bytes).
    pub fn memory_reserved(&self) -> u64 {
        self.inner
            .allocator
            .lock()
            .unwrap()
            .as_ref()
            .map_or(0, |a| a.generate_report().total_capacity_bytes)
    }

    pub(crate) fn device(&self) -> &ash::Device {
        &self.inner.device
    }
}

/// The messenger that hands validation warnings and errors to `log`.
fn create_messenger(
    entry: &ash::Entry,
    instance: &ash::Instance,
    log: &Arc<ValidationLog>,
) -> GpuResult<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)> {
    let loader = ash::ext::debug_utils::Instance::new(entry, instance);
    let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(
            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
        )
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(debug_callback))
        .user_data(Arc::as_ptr(log) as *mut c_void);
    // SAFETY: the log outlives the messenger (both owned by Inner, messenger destroyed first).
    let messenger = unsafe { loader.create_debug_utils_messenger(&info, None) }
        .vk("vkCreateDebugUtilsMessengerEXT")?;
    Ok((loader, messenger))
}

/// The physical device `choose_device` picks for `wanted`, with its capabilities.
fn pick_physical(
    instance: &ash::Instance,
    wanted: Option<&str>,
) -> GpuResult<(vk::PhysicalDevice, DeviceCaps)> {
    let cands = enumerate(instance)?;
    let index = choose_device(&cands, wanted)?;
    // SAFETY: plain query.
    let physical =
        unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?[index];
    Ok((physical, cands[index].caps.clone()))
}

/// The memory allocator over `device` (no buffer device addresses).
fn create_allocator(
    instance: &ash::Instance,
    device: &ash::Device,
    physical: vk::PhysicalDevice,
) -> GpuResult<Allocator> {
    Allocator::new(&AllocatorCreateDesc {
        instance: instance.clone(),
        device: device.clone(),
        physical_device: physical,
        debug_settings: Default::default(),
        buffer_device_address: true,
        allocation_sizes: Default::default(),
    })
    .map_err(|source| GpuError::Allocation {
        name: "allocator".into(),
        size: 0,
        source,
    })
}

fn create_device(
    instance: &ash::Instance,
    physical: vk::PhysicalDevice,
    caps: &DeviceCaps,
    queue_family: u32,
) -> GpuResult<ash::Device> {
    let priorities = [1.0f32];
    let queue_info = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family)
        .queue_priorities(&priorities)];
    let mut exts = vec![ash::khr::push_descriptor::NAME.as_ptr()];
    if caps.has_atomic_float_ext {
        exts.push(ash::ext::shader_atomic_float::NAME.as_ptr());
    }
    let mut atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default()
        .shader_buffer_float32_atomics(caps.float_atomic_add)
        .shader_buffer_float32_atomic_add(caps.float_atomic_add);
    let mut v12 = vk::PhysicalDeviceVulkan12Features::default()
        .shader_buffer_int64_atomics(caps.int64_atomics)
        .buffer_device_address(true)
        .storage_buffer8_bit_access(caps.storage_8bit)
        .shader_int8(caps.storage_8bit);
    let mut v13 = vk::PhysicalDeviceVulkan13Features::default()
        .subgroup_size_control(true)
        .compute_full_subgroups(true);
    let base = vk::PhysicalDeviceFeatures::default()
        .shader_int64(caps.int64)
        .shader_float64(caps.float64);
    let mut features = vk::PhysicalDeviceFeatures2::default()
        .features(base)
        .push_next(&mut v12)
        .push_next(&mut v13);
    if caps.has_atomic_float_ext {
        features = features.push_next(&mut atomic_float);
    }
    let info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_info)
        .enabled_extension_names(&exts)
        .push_next(&mut features);
    // SAFETY: all pointers in `info` outlive the call; features were checked by probe_device.
    unsafe { instance.create_device(physical, &info, None) }.vk("vkCreateDevice")
}

/// Destroys the instance (and messenger) if device setup fails half way.
struct InstanceGuard {
    instance: Option<ash::Instance>,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
}

impl InstanceGuard {
    fn disarm(&mut self) {
        self.instance = None;
        self.debug = None;
    }
}

impl Drop for InstanceGuard {
    fn drop(&mut self) {
        // SAFETY: only reached on error paths, before any device object exists.
        unsafe {
            if let Some((loader, m)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(m, None);
            }
            if let Some(i) = self.instance.take() {
                i.destroy_instance(None);
            }
        }
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        // SAFETY: every buffer and recorder holds an Arc to Inner, so none remain; we wait
        // for the device before destroying objects in reverse creation order.
        unsafe {
            let _ = self.device.device_wait_idle();
            for (_, k) in self.kernels.lock().unwrap().drain() {
                k.destroy(&self.device);
            }
            for parts in self.recycled_recorders.lock().unwrap().drain(..) {
                parts.destroy(&self.device);
            }
            drop(self.allocator.lock().unwrap().take());
            self.device.destroy_device(None);
            if let Some((loader, m)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(m, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}
