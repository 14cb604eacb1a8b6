//! Compute pipelines built from the reflected kernel table, created on first use and cached.

use std::io::Cursor;
use std::sync::Arc;

use ash::vk;

use super::context::Gpu;
use super::error::{GpuResult, VkContext};
use super::kernel_table::{KernelId, KernelInfo};

/// A built kernel: pipeline plus the layouts derived from its reflection.
pub struct Pipeline {
    pub info: &'static KernelInfo,
    pub(crate) pipeline: vk::Pipeline,
    pub(crate) layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
    module: vk::ShaderModule,
}

impl Pipeline {
    /// # Safety
    /// The device must be idle with respect to this kernel.
    pub(crate) unsafe fn destroy(&self, device: &ash::Device) {
        unsafe {
            device.destroy_pipeline(self.pipeline, None);
            device.destroy_pipeline_layout(self.layout, None);
            device.destroy_descriptor_set_layout(self.set_layout, None);
            device.destroy_shader_module(self.module, None);
        }
    }
}

impl Gpu {
    /// The pipeline for a kernel, built on first use.
    pub fn kernel(&self, id: KernelId) -> GpuResult<Arc<Pipeline>> {
        let mut cache = self.inner.kernels.lock().unwrap();
        if let Some(k) = cache.get(&id.0) {
            return Ok(k.clone());
        }
        let k = Arc::new(self.build_kernel(id.info())?);
        cache.insert(id.0, k.clone());
        Ok(k)
    }

    fn build_kernel(&self, info: &'static KernelInfo) -> GpuResult<Pipeline> {
        let words =
            ash::util::read_spv(&mut Cursor::new(info.spirv)).expect("build.rs wrote valid SPIR-V");
        // SAFETY: what each step creates is destroyed if a later step fails.
        unsafe {
            let (set_layout, layout) = self.create_layouts(info)?;
            match self.create_pipeline(info, layout, &words) {
                Ok((module, pipeline)) => Ok(Pipeline {
                    info,
                    pipeline,
                    layout,
                    set_layout,
                    module,
                }),
                Err(e) => {
                    self.device().destroy_pipeline_layout(layout, None);
                    self.device()
                        .destroy_descriptor_set_layout(set_layout, None);
                    Err(e)
                }
            }
        }
    }

    /// The push-descriptor set layout and the pipeline layout of a kernel's reflection.
    ///
    /// # Safety
    /// The caller destroys both when done with them.
    unsafe fn create_layouts(
        &self,
        info: &KernelInfo,
    ) -> GpuResult<(vk::DescriptorSetLayout, vk::PipelineLayout)> {
        let device = self.device();
        let bindings: Vec<_> = info
            .bindings
            .iter()
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b.binding)
                    .descriptor_type(b.descriptor_type())
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .size(info.push_constant_size)];
        let ranges: &[vk::PushConstantRange] = if info.push_constant_size > 0 {
            &ranges
        } else {
            &[]
        };
        // SAFETY: create infos reference locals that outlive each call.
        unsafe {
            let set_layout = device
                .create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default()
                        .flags(vk::DescriptorSetLayoutCreateFlags::PUSH_DESCRIPTOR_KHR)
                        .bindings(&bindings),
                    None,
                )
                .vk("vkCreateDescriptorSetLayout")?;
            let set_layouts = [set_layout];
            match device.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default()
                    .set_layouts(&set_layouts)
                    .push_constant_ranges(ranges),
                None,
            ) {
                Ok(layout) => Ok((set_layout, layout)),
                Err(e) => {
                    device.destroy_descriptor_set_layout(set_layout, None);
                    Err(e).vk("vkCreatePipelineLayout")
                }
            }
        }
    }

    /// The shader module and compute pipeline of a kernel.
    ///
    /// # Safety
    /// `layout` is a live pipeline layout; the caller destroys what this returns.
    unsafe fn create_pipeline(
        &self,
        info: &KernelInfo,
        layout: vk::PipelineLayout,
        words: &[u32],
    ) -> GpuResult<(vk::ShaderModule, vk::Pipeline)> {
        let device = self.device();
        // Full subgroups make gl_SubgroupID * gl_SubgroupSize + gl_SubgroupInvocationID a
        // bijection onto the workgroup, which the scans and the stable sort rely on.
        let full_subgroups = info.workgroup_size[0].is_multiple_of(self.caps().max_subgroup_size);
        let stage_flags = if full_subgroups {
            vk::PipelineShaderStageCreateFlags::REQUIRE_FULL_SUBGROUPS
        } else {
            vk::PipelineShaderStageCreateFlags::empty()
        };
        // SAFETY: create infos reference locals that outlive each call.
        unsafe {
            let module = device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(words), None)
                .vk("vkCreateShaderModule")?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .flags(stage_flags)
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            let create = [vk::ComputePipelineCreateInfo::default()
                .stage(stage)
                .layout(layout)];
            match device.create_compute_pipelines(vk::PipelineCache::null(), &create, None) {
                Ok(p) => Ok((module, p[0])),
                Err((_, e)) => {
                    device.destroy_shader_module(module, None);
                    Err(e).vk("vkCreateComputePipelines")
                }
            }
        }
    }
}
