//! What a physical device is and supports, and which of our required features it lacks.

use std::ffi::CStr;

use ash::vk;
use serde::Serialize;

/// One memory heap.
#[derive(Clone, Debug, Serialize)]
pub struct Heap {
    pub size_bytes: u64,
    pub device_local: bool,
}

/// Properties and features of a physical device that semsplat cares about.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceCaps {
    pub name: String,
    #[serde(serialize_with = "ser_type")]
    pub device_type: vk::PhysicalDeviceType,
    pub vendor_id: u32,
    pub driver_name: String,
    pub driver_info: String,
    /// "major.minor.patch".
    pub vulkan_version: String,
    #[serde(skip)]
    pub api_version: u32,
    pub subgroup_size: u32,
    pub min_subgroup_size: u32,
    pub max_subgroup_size: u32,
    pub float_atomic_add: bool,
    #[serde(skip)]
    pub has_atomic_float_ext: bool,
    pub int64: bool,
    /// shaderFloat64: projection computes means in float64.
    pub float64: bool,
    pub int64_atomics: bool,
    #[serde(skip)]
    pub storage_8bit: bool,
    pub timestamps: bool,
    pub timestamp_period_ns: f64,
    #[serde(skip)]
    pub timestamp_valid_bits: u32,
    pub max_storage_buffer_range: u64,
    /// The largest single allocation (maxMemoryAllocationSize, 2 GiB on lavapipe): what
    /// one buffer reached by address may hold.
    pub max_allocation: u64,
    /// Byte alignment of a storage buffer range's offset (minStorageBufferOffsetAlignment):
    /// work split into chunks binds each chunk's range at a multiple of it.
    pub min_storage_offset_alignment: u64,
    pub max_workgroup_count: [u32; 3],
    pub max_shared_memory: u32,
    /// Loop iterations one shader invocation may run in total before the driver silently
    /// cuts its loops short, where the driver has such a cap (see [`loop_iteration_cap`]).
    /// Kernels that walk long lists split the walk into dispatches that stay below it.
    pub loop_iteration_cap: Option<u32>,
    /// The forms of the work written for CPU drivers stand in for the GPU forms: on by
    /// default on CPU devices, whose drivers (lavapipe) run a workgroup as SIMD vectors but
    /// read shared memory and storage buffers one lane at a time. The per-tile kernels
    /// take several pixels an invocation (the `*_wide` kernels,
    /// glsl/common/tile_window.glsl: one pixel an invocation reads every step of a tile's
    /// list once per pixel, blending and fusion about 4x slower there), the radix sort's
    /// passes walk runs of keys one after another (glsl/sort/wide_runs.glsl: about 4.5x
    /// faster there), and segment consensus finds each view's label regions on the host,
    /// on the same cores (src/fuse/regions_gpu.rs: about 19x faster there). See
    /// [`cpu_forms`].
    pub cpu_forms: bool,
    pub heaps: Vec<Heap>,
    #[serde(skip)]
    pub compute_queue_family: Option<u32>,
}

fn ser_type<S: serde::Serializer>(t: &vk::PhysicalDeviceType, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(device_type_name(*t))
}

pub fn device_type_name(t: vk::PhysicalDeviceType) -> &'static str {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => "discrete GPU",
        vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated GPU",
        vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual GPU",
        vk::PhysicalDeviceType::CPU => "CPU",
        _ => "other",
    }
}

fn cstr(bytes: &[std::ffi::c_char]) -> String {
    // SAFETY: Vulkan fixed-size strings are NUL-terminated within the array.
    unsafe { CStr::from_ptr(bytes.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

/// Subgroup operations every kernel may use.
pub const REQUIRED_SUBGROUP_OPS: vk::SubgroupFeatureFlags = vk::SubgroupFeatureFlags::from_raw(
    vk::SubgroupFeatureFlags::BASIC.as_raw()
        | vk::SubgroupFeatureFlags::VOTE.as_raw()
        | vk::SubgroupFeatureFlags::ARITHMETIC.as_raw()
        | vk::SubgroupFeatureFlags::BALLOT.as_raw()
        | vk::SubgroupFeatureFlags::SHUFFLE.as_raw(),
);

/// Reads a device's capabilities and lists the required features it lacks.
pub fn probe_device(instance: &ash::Instance, pd: vk::PhysicalDevice) -> (DeviceCaps, Vec<String>) {
    // SAFETY (this and the extension query): plain queries on a valid physical device.
    let base = unsafe { instance.get_physical_device_properties(pd) };
    let api = base.api_version;
    let has_13 = vk::api_version_major(api) > 1 || vk::api_version_minor(api) >= 3;
    let exts = unsafe { instance.enumerate_device_extension_properties(pd) }.unwrap_or_default();
    let has_ext = |name: &CStr| {
        exts.iter()
            .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
    };
    let has_atomic_float_ext = has_ext(ash::ext::shader_atomic_float::NAME);
    let props = query_properties(instance, pd, has_13);
    let features = query_features(instance, pd, has_13, has_atomic_float_ext);

    // SAFETY: plain query on a valid physical device.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let compute_family = pick_compute_family(&families);
    let timestamp_valid_bits = compute_family
        .map(|f| families[f as usize].timestamp_valid_bits)
        .unwrap_or(0);

    let missing = missing_features(
        api,
        compute_family.is_some(),
        has_ext(ash::khr::push_descriptor::NAME),
        &props,
        &features,
    );
    let (min_sg, max_sg) = if has_13 {
        (
            props.size_control.min_subgroup_size,
            props.size_control.max_subgroup_size,
        )
    } else {
        (props.subgroup.subgroup_size, props.subgroup.subgroup_size)
    };
    let (atomic_float, v12, base_features) =
        (&features.atomic_float, &features.v12, &features.base);
    let driver_name = cstr(&props.driver.driver_name);
    let caps = DeviceCaps {
        name: cstr(&base.device_name),
        device_type: base.device_type,
        vendor_id: base.vendor_id,
        loop_iteration_cap: loop_iteration_cap(&driver_name),
        cpu_forms: base.device_type == vk::PhysicalDeviceType::CPU,
        driver_name,
        driver_info: cstr(&props.driver.driver_info),
        vulkan_version: format!(
            "{}.{}.{}",
            vk::api_version_major(api),
            vk::api_version_minor(api),
            vk::api_version_patch(api)
        ),
        api_version: api,
        subgroup_size: props.subgroup.subgroup_size,
        min_subgroup_size: min_sg,
        max_subgroup_size: max_sg,
        float_atomic_add: atomic_float.shader_buffer_float32_atomic_add != 0
            && atomic_float.shader_buffer_float32_atomics != 0,
        has_atomic_float_ext,
        int64: base_features.shader_int64 != 0,
        float64: base_features.shader_float64 != 0,
        int64_atomics: base_features.shader_int64 != 0 && v12.shader_buffer_int64_atomics != 0,
        storage_8bit: v12.storage_buffer8_bit_access != 0 && v12.shader_int8 != 0,
        timestamps: base.limits.timestamp_compute_and_graphics != 0 && timestamp_valid_bits > 0,
        timestamp_period_ns: base.limits.timestamp_period as f64,
        timestamp_valid_bits,
        max_storage_buffer_range: base.limits.max_storage_buffer_range as u64,
        max_allocation: props.maintenance3.max_memory_allocation_size,
        min_storage_offset_alignment: base.limits.min_storage_buffer_offset_alignment,
        max_workgroup_count: base.limits.max_compute_work_group_count,
        max_shared_memory: base.limits.max_compute_shared_memory_size,
        heaps: memory_heaps(instance, pd),
        compute_queue_family: compute_family,
    };
    (caps, missing)
}

/// The device's `maxStorageBufferRange` (`device`), or less where `asked` (else
/// `SEMSPLAT_MAX_BINDING`, bytes) asks for less, rounded down to 256 bytes: see
/// `GpuOptions::max_binding`. It can only lower the limit.
pub(crate) fn binding_limit(device: u64, asked: Option<u64>) -> u64 {
    let asked = asked.or_else(|| {
        let v = std::env::var("SEMSPLAT_MAX_BINDING").ok()?;
        let parsed = v.trim().parse::<u64>().ok();
        if parsed.is_none() {
            eprintln!("warning: SEMSPLAT_MAX_BINDING={v} is not a whole number of bytes: the device's limit is used");
        }
        parsed
    });
    asked.map_or(device, |a| (a / 256 * 256).clamp(256, device))
}

/// Whether the CPU drivers' forms of the work stand in for the GPU forms
/// (`DeviceCaps::cpu_forms`): `asked` (else `SEMSPLAT_CPU_FORMS`, 0 or 1), or the device's
/// default (`device`, CPU devices). Tests set it to run both forms on one device; see
/// `GpuOptions::cpu_forms`.
pub(crate) fn cpu_forms(device: bool, asked: Option<bool>) -> bool {
    let asked = asked.or_else(|| match std::env::var("SEMSPLAT_CPU_FORMS").as_deref() {
        Ok("0") => Some(false),
        Ok("1") => Some(true),
        Ok(other) => {
            eprintln!("warning: SEMSPLAT_CPU_FORMS={other} is neither 0 nor 1: the device's default is used");
            None
        }
        Err(_) => None,
    });
    asked.unwrap_or(device)
}

/// The properties of the `vkGetPhysicalDeviceProperties2` chain we read (`size_control`
/// only on Vulkan 1.3; default otherwise).
struct ChainedProperties {
    subgroup: vk::PhysicalDeviceSubgroupProperties<'static>,
    driver: vk::PhysicalDeviceDriverProperties<'static>,
    size_control: vk::PhysicalDeviceSubgroupSizeControlProperties<'static>,
    maintenance3: vk::PhysicalDeviceMaintenance3Properties<'static>,
}

fn query_properties(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    has_13: bool,
) -> ChainedProperties {
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut size_control = vk::PhysicalDeviceSubgroupSizeControlProperties::default();
    let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
    {
        let mut props = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut subgroup)
            .push_next(&mut driver)
            .push_next(&mut maintenance3);
        if has_13 {
            props = props.push_next(&mut size_control);
        }
        // SAFETY: plain query on a valid physical device; the chain outlives the call.
        unsafe { instance.get_physical_device_properties2(pd, &mut props) };
    }
    // The chain's links point into this frame: cut them before the structs move out.
    subgroup.p_next = std::ptr::null_mut();
    driver.p_next = std::ptr::null_mut();
    size_control.p_next = std::ptr::null_mut();
    maintenance3.p_next = std::ptr::null_mut();
    ChainedProperties {
        subgroup,
        driver,
        size_control,
        maintenance3,
    }
}

/// The features of the `vkGetPhysicalDeviceFeatures2` chain we read (`v13` only on Vulkan
/// 1.3, `atomic_float` only with VK_EXT_shader_atomic_float; default otherwise).
struct ChainedFeatures {
    base: vk::PhysicalDeviceFeatures,
    v12: vk::PhysicalDeviceVulkan12Features<'static>,
    v13: vk::PhysicalDeviceVulkan13Features<'static>,
    atomic_float: vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT<'static>,
}

fn query_features(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    has_13: bool,
    has_atomic_float_ext: bool,
) -> ChainedFeatures {
    let mut atomic_float = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
    let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut v13 = vk::PhysicalDeviceVulkan13Features::default();
    let base = {
        let mut features = vk::PhysicalDeviceFeatures2::default().push_next(&mut v12);
        if has_13 {
            features = features.push_next(&mut v13);
        }
        if has_atomic_float_ext {
            features = features.push_next(&mut atomic_float);
        }
        // SAFETY: plain query on a valid physical device; the chain outlives the call.
        unsafe { instance.get_physical_device_features2(pd, &mut features) };
        features.features
    };
    // The chain's links point into this frame: cut them before the structs move out.
    atomic_float.p_next = std::ptr::null_mut();
    v12.p_next = std::ptr::null_mut();
    v13.p_next = std::ptr::null_mut();
    ChainedFeatures {
        base,
        v12,
        v13,
        atomic_float,
    }
}

/// Prefers a compute family without graphics (async compute), else any with compute.
fn pick_compute_family(families: &[vk::QueueFamilyProperties]) -> Option<u32> {
    families
        .iter()
        .position(|f| {
            f.queue_flags.contains(vk::QueueFlags::COMPUTE)
                && !f.queue_flags.contains(vk::QueueFlags::GRAPHICS)
        })
        .or_else(|| {
            families
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
        })
        .map(|i| i as u32)
}

fn memory_heaps(instance: &ash::Instance, pd: vk::PhysicalDevice) -> Vec<Heap> {
    // SAFETY: plain query on a valid physical device.
    let mem = unsafe { instance.get_physical_device_memory_properties(pd) };
    mem.memory_heaps[..mem.memory_heap_count as usize]
        .iter()
        .map(|h| Heap {
            size_bytes: h.size,
            device_local: h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL),
        })
        .collect()
}

/// The required features a device lacks, in words (empty: usable).
fn missing_features(
    api: u32,
    has_compute_family: bool,
    has_push_descriptor: bool,
    props: &ChainedProperties,
    features: &ChainedFeatures,
) -> Vec<String> {
    let mut missing = Vec::new();
    let has_13 = vk::api_version_major(api) > 1 || vk::api_version_minor(api) >= 3;
    if !has_13 {
        missing.push(format!(
            "Vulkan 1.3 (device reports {}.{})",
            vk::api_version_major(api),
            vk::api_version_minor(api)
        ));
    }
    if !has_compute_family {
        missing.push("a compute queue".into());
    }
    if !has_push_descriptor {
        missing.push("VK_KHR_push_descriptor".into());
    }
    let subgroup = &props.subgroup;
    if !subgroup
        .supported_stages
        .contains(vk::ShaderStageFlags::COMPUTE)
    {
        missing.push("subgroup operations in compute shaders".into());
    } else if !subgroup
        .supported_operations
        .contains(REQUIRED_SUBGROUP_OPS)
    {
        missing.push("subgroup basic/vote/arithmetic/ballot/shuffle operations".into());
    }
    // Our kernels lay out per-subgroup scratch for subgroups of 4..=128 lanes.
    if !(4..=128).contains(&subgroup.subgroup_size) {
        missing.push(format!(
            "a subgroup size within 4..=128 (device: {})",
            subgroup.subgroup_size
        ));
    }
    // Kernels reach large per-Gaussian arrays by address (mandatory in Vulkan 1.3).
    if features.v12.buffer_device_address == 0 {
        missing.push("bufferDeviceAddress".into());
    }
    let v13 = &features.v13;
    if has_13 && (v13.subgroup_size_control == 0 || v13.compute_full_subgroups == 0) {
        missing.push("subgroupSizeControl with computeFullSubgroups".into());
    }
    missing
}

impl DeviceCaps {
    /// Total size of device-local heaps.
    pub fn device_local_bytes(&self) -> u64 {
        self.heaps
            .iter()
            .filter(|h| h.device_local)
            .map(|h| h.size_bytes)
            .sum()
    }
}

/// The loop cap of a driver: Mesa's llvmpipe (lavapipe) stops every invocation after
/// 65,535 loop iterations, shared by all its loops (measured: a 100,000-iteration loop
/// returns after 65,535; nested 300 x 300 loops after 65,100), and says nothing.
pub fn loop_iteration_cap(driver_name: &str) -> Option<u32> {
    driver_name
        .to_lowercase()
        .contains("llvmpipe")
        .then_some(65_535)
}
