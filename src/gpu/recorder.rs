//! Command recording: dispatches (direct and indirect) with push descriptors bound by the
//! names the kernel table reflected, barriers, copies, and a timestamp after every
//! dispatch so each kernel's time can be read back after the submission.

use ash::vk;

use super::buffer::Buffer;
use super::caps::DeviceCaps;
use super::context::Gpu;
use super::error::{GpuError, GpuResult, VkContext};
use super::kernel_table::{Kernel, KernelId, KernelInfo};
use super::timings::{Mark, Timings};

/// Timestamps one command buffer can hold; later dispatches go untimed.
const MAX_QUERIES: u32 = 4096;

/// Records one command buffer; `submit_and_wait` runs it and returns the timings.
pub struct Recorder {
    gpu: Gpu,
    parts: RecorderParts,
    /// Label of each timestamp after the first (kernel name or None for marks).
    stamps: Vec<Option<&'static str>>,
    /// No submission of its command buffer can be pending (never submitted, or waited
    /// for): its pools may be reused by the next recorder instead of destroyed.
    idle: bool,
}

/// A recorder's Vulkan objects. Creating a command pool and a 4096-entry query pool for
/// every submission cost host time on every view; a few finished ones are kept on the
/// device for the next recorders (see [`MAX_RECYCLED`]).
#[derive(Clone, Copy)] // Vulkan handles; the recorder or the recycle list owns them
pub(crate) struct RecorderParts {
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    queries: Option<vk::QueryPool>,
}

/// Finished recorders' parts kept for reuse (more than one recorder may be open at once).
const MAX_RECYCLED: usize = 8;

impl RecorderParts {
    fn create(gpu: &Gpu) -> GpuResult<RecorderParts> {
        let device = gpu.device();
        // SAFETY: objects are created from a valid device; they are destroyed by
        // `destroy`, by the recorder's Drop or the device's.
        unsafe {
            let pool = device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(gpu.inner.queue_family)
                        .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                    None,
                )
                .vk("vkCreateCommandPool")?;
            let mut parts = RecorderParts {
                pool,
                cmd: vk::CommandBuffer::null(),
                queries: None,
            };
            let allocated = device.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            );
            match allocated {
                Ok(cmds) => parts.cmd = cmds[0],
                Err(e) => {
                    parts.destroy(device);
                    return Err(e).vk("vkAllocateCommandBuffers");
                }
            }
            if gpu.caps().timestamps {
                let qp = device.create_query_pool(
                    &vk::QueryPoolCreateInfo::default()
                        .query_type(vk::QueryType::TIMESTAMP)
                        .query_count(MAX_QUERIES),
                    None,
                );
                match qp {
                    Ok(qp) => parts.queries = Some(qp),
                    Err(e) => {
                        parts.destroy(device);
                        return Err(e).vk("vkCreateQueryPool");
                    }
                }
            }
            Ok(parts)
        }
    }

    /// # Safety
    /// Nothing recorded into the pool's buffer may be pending.
    pub(crate) unsafe fn destroy(&self, device: &ash::Device) {
        if let Some(qp) = self.queries {
            device.destroy_query_pool(qp, None);
        }
        device.destroy_command_pool(self.pool, None);
    }
}

impl Recorder {
    /// Starts recording; timestamps are on when the device supports them.
    pub fn new(gpu: &Gpu) -> GpuResult<Recorder> {
        let device = gpu.device();
        let recycled = gpu.inner.recycled_recorders.lock().unwrap().pop();
        let parts = match recycled {
            Some(parts) => parts,
            None => RecorderParts::create(gpu)?,
        };
        let mut rec = Recorder {
            gpu: gpu.clone(),
            parts,
            stamps: vec![],
            idle: false,
        };
        // SAFETY: the pool's buffer is not pending (a recycled one was waited for); recording
        // into our own command buffer.
        unsafe {
            device
                .reset_command_pool(rec.parts.pool, vk::CommandPoolResetFlags::empty())
                .vk("vkResetCommandPool")?;
            device
                .begin_command_buffer(
                    rec.parts.cmd,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .vk("vkBeginCommandBuffer")?;
            if let Some(qp) = rec.parts.queries {
                device.cmd_reset_query_pool(rec.parts.cmd, qp, 0, MAX_QUERIES);
                device.cmd_write_timestamp(
                    rec.parts.cmd,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    qp,
                    0,
                );
            }
        }
        rec.idle = true; // recorded, never submitted: nothing of it can be pending
        Ok(rec)
    }

    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    fn stamp(&mut self, label: Option<&'static str>) -> Option<Mark> {
        let qp = self.parts.queries?;
        let index = self.stamps.len() as u32 + 1;
        if index >= MAX_QUERIES {
            return None;
        }
        // SAFETY: recording into our command buffer; the query index is in range.
        unsafe {
            self.gpu.device().cmd_write_timestamp(
                self.parts.cmd,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                qp,
                index,
            );
        }
        self.stamps.push(label);
        Some(Mark(index))
    }

    /// A timestamp to measure spans with [`Timings::between`]; None without timestamps.
    pub fn mark(&mut self) -> Option<Mark> {
        self.stamp(None)
    }

    fn bind(
        &mut self,
        kernel: KernelId,
        bindings: &[(&str, BufferRange)],
        push: &[u8],
    ) -> GpuResult<()> {
        let k = self.gpu.kernel(kernel)?;
        let info = k.info;
        assert_eq!(
            push.len(),
            info.push_constant_size as usize,
            "{}: push constants are {} bytes, kernel expects {}",
            info.name,
            push.len(),
            info.push_constant_size
        );
        assert_eq!(
            bindings.len(),
            info.bindings.len(),
            "{}: {} buffers given, kernel binds {:?}",
            info.name,
            bindings.len(),
            info.bindings.iter().map(|b| b.name).collect::<Vec<_>>()
        );
        let infos = buffer_infos(info, bindings, self.gpu.caps())?;
        let writes: Vec<_> = info
            .bindings
            .iter()
            .zip(&infos)
            .map(|(b, bi)| {
                vk::WriteDescriptorSet::default()
                    .dst_binding(b.binding)
                    .descriptor_type(b.descriptor_type())
                    .buffer_info(bi)
            })
            .collect();
        let device = self.gpu.device();
        // SAFETY: recording into our command buffer with a pipeline that lives in the cache.
        unsafe {
            device.cmd_bind_pipeline(self.parts.cmd, vk::PipelineBindPoint::COMPUTE, k.pipeline);
            // A kernel that reaches all its buffers by address binds none.
            if !writes.is_empty() {
                self.gpu.inner.push_descriptor.cmd_push_descriptor_set(
                    self.parts.cmd,
                    vk::PipelineBindPoint::COMPUTE,
                    k.layout,
                    0,
                    &writes,
                );
            }
            if !push.is_empty() {
                device.cmd_push_constants(
                    self.parts.cmd,
                    k.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    push,
                );
            }
        }
        Ok(())
    }

    /// Dispatches `groups` workgroups of `kernel`, binding buffers by their GLSL names.
    pub fn dispatch<P: bytemuck::Pod>(
        &mut self,
        kernel: Kernel<P>,
        bindings: &[(&str, &Buffer)],
        params: &P,
        groups: [u32; 3],
    ) -> GpuResult<()> {
        self.dispatch_ranges(kernel, &whole(bindings), params, groups)
    }

    /// [`Recorder::dispatch`] binding byte ranges of buffers: a pass split into chunks binds
    /// each chunk's part of a buffer larger than one binding may hold.
    pub fn dispatch_ranges<P: bytemuck::Pod>(
        &mut self,
        kernel: Kernel<P>,
        bindings: &[(&str, BufferRange)],
        params: &P,
        groups: [u32; 3],
    ) -> GpuResult<()> {
        if groups.contains(&0) {
            return Ok(());
        }
        let limit = self.gpu.caps().max_workgroup_count;
        if !groups.iter().zip(limit).all(|(g, l)| *g <= l) {
            return Err(GpuError::Limit(format!(
                "{}: {groups:?} workgroups exceed the device's limit {limit:?}: too many \
                 Gaussians, pixels or classes for one dispatch",
                kernel.info().name
            )));
        }
        self.bind(kernel.id(), bindings, bytemuck::bytes_of(params))?;
        // SAFETY: recording into our command buffer.
        unsafe {
            self.gpu
                .device()
                .cmd_dispatch(self.parts.cmd, groups[0], groups[1], groups[2])
        };
        self.stamp(Some(kernel.info().name));
        Ok(())
    }

    /// Dispatches with the workgroup count read from `args` at byte `offset`
    /// (three u32: x, y, z), so counts computed on the GPU need no readback.
    pub fn dispatch_indirect<P: bytemuck::Pod>(
        &mut self,
        kernel: Kernel<P>,
        bindings: &[(&str, &Buffer)],
        params: &P,
        args: &Buffer,
        offset: u64,
    ) -> GpuResult<()> {
        self.dispatch_indirect_ranges(kernel, &whole(bindings), params, args, offset)
    }

    /// [`Recorder::dispatch_indirect`] binding byte ranges of buffers.
    pub fn dispatch_indirect_ranges<P: bytemuck::Pod>(
        &mut self,
        kernel: Kernel<P>,
        bindings: &[(&str, BufferRange)],
        params: &P,
        args: &Buffer,
        offset: u64,
    ) -> GpuResult<()> {
        self.bind(kernel.id(), bindings, bytemuck::bytes_of(params))?;
        // SAFETY: recording into our command buffer; args has INDIRECT usage.
        unsafe {
            self.gpu
                .device()
                .cmd_dispatch_indirect(self.parts.cmd, args.raw, offset)
        };
        self.stamp(Some(kernel.info().name));
        Ok(())
    }

    /// Makes every earlier shader or transfer write visible to later shader, transfer and
    /// indirect-argument reads.
    pub fn barrier(&mut self) {
        let mb = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::INDIRECT_COMMAND_READ
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::TRANSFER_WRITE,
            );
        // SAFETY: recording into our command buffer.
        unsafe {
            self.gpu.device().cmd_pipeline_barrier(
                self.parts.cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::COMPUTE_SHADER
                    | vk::PipelineStageFlags::DRAW_INDIRECT
                    | vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[mb],
                &[],
                &[],
            );
        }
    }

    /// Makes transfer and shader writes visible to the host after the fence.
    pub(crate) fn host_barrier(&mut self) {
        let mb = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE | vk::AccessFlags::SHADER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        // SAFETY: recording into our command buffer.
        unsafe {
            self.gpu.device().cmd_pipeline_barrier(
                self.parts.cmd,
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[mb],
                &[],
                &[],
            );
        }
    }

    /// Copies `size` bytes between buffers.
    pub fn copy(
        &mut self,
        src: &Buffer,
        src_offset: u64,
        dst: &Buffer,
        dst_offset: u64,
        size: u64,
    ) {
        if size == 0 {
            return;
        }
        let region = vk::BufferCopy {
            src_offset,
            dst_offset,
            size,
        };
        // SAFETY: recording into our command buffer; callers keep ranges in bounds.
        unsafe {
            self.gpu
                .device()
                .cmd_copy_buffer(self.parts.cmd, src.raw, dst.raw, &[region])
        };
    }

    /// Writes a few bytes (a multiple of 4, at most 65,536) into `dst` from the command
    /// buffer itself: no staging buffer, ordered with the other commands.
    pub fn update(&mut self, dst: &Buffer, offset: u64, data: &[u8]) {
        assert!(
            data.len().is_multiple_of(4) && data.len() <= 65_536,
            "vkCmdUpdateBuffer takes 4..=65536 bytes in words"
        );
        if data.is_empty() {
            return;
        }
        // SAFETY: recording into our command buffer; callers keep the range in bounds.
        unsafe {
            self.gpu
                .device()
                .cmd_update_buffer(self.parts.cmd, dst.raw, offset, data)
        };
    }

    /// Fills `size` bytes (a multiple of 4) at `offset` with a repeated u32.
    pub fn fill(&mut self, dst: &Buffer, offset: u64, size: u64, value: u32) {
        if size == 0 {
            return;
        }
        // SAFETY: recording into our command buffer.
        unsafe {
            self.gpu
                .device()
                .cmd_fill_buffer(self.parts.cmd, dst.raw, offset, size, value)
        };
    }

    /// Submits, waits for completion, and returns the per-kernel timings.
    pub fn submit_and_wait(self) -> GpuResult<Timings> {
        self.submit()?.wait()
    }

    /// Submits without waiting: the host may record the next work while this runs. Every
    /// buffer the commands use must outlive the returned [`Submission`] (dropping it waits).
    pub fn submit(mut self) -> GpuResult<Submission> {
        let device = self.gpu.device();
        // SAFETY: the command buffer is fully recorded; the submission waits on the fence
        // before reading queries or letting the recorder's Drop free or recycle anything.
        unsafe {
            device
                .end_command_buffer(self.parts.cmd)
                .vk("vkEndCommandBuffer")?;
            let fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .vk("vkCreateFence")?;
            self.idle = false;
            let cmds = [self.parts.cmd];
            let submit = vk::SubmitInfo::default().command_buffers(&cmds);
            let submitted = {
                let queue = self.gpu.inner.queue.lock().unwrap();
                device.queue_submit(*queue, &[submit], fence)
            };
            if let Err(e) = submitted {
                device.destroy_fence(fence, None);
                return Err(e).vk("vkQueueSubmit");
            }
            Ok(Submission {
                rec: Some(self),
                fence,
            })
        }
    }

    /// Waits for `fence` (this recorder's submission) and destroys it. The recorder is idle
    /// afterwards unless the wait failed (a device error: its pools are then destroyed, not
    /// reused).
    fn wait_for(&mut self, fence: vk::Fence) -> GpuResult<()> {
        let device = self.gpu.device();
        // SAFETY: the fence belongs to this recorder's submission and is destroyed once.
        let waited = unsafe {
            let waited = device.wait_for_fences(&[fence], true, u64::MAX);
            device.destroy_fence(fence, None);
            waited
        };
        self.idle = waited.is_ok();
        waited.vk("vkWaitForFences")
    }

    /// The timings of a finished submission.
    fn read_timings(&self) -> GpuResult<Timings> {
        let mut raw = vec![0u64; self.stamps.len() + 1];
        if let Some(qp) = self.parts.queries {
            // SAFETY: the submission that wrote the queries has finished.
            unsafe {
                self.gpu
                    .device()
                    .get_query_pool_results(
                        qp,
                        0,
                        &mut raw,
                        vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                    )
                    .vk("vkGetQueryPoolResults")?;
            }
        }
        let bits = self.gpu.caps().timestamp_valid_bits;
        let mask = if bits >= 64 {
            u64::MAX
        } else {
            (1u64 << bits) - 1
        };
        let period = self.gpu.caps().timestamp_period_ns;
        let ns: Vec<f64> = raw.iter().map(|t| (t & mask) as f64 * period).collect();
        Ok(Timings::new(
            &ns,
            &self.stamps,
            self.parts.queries.is_some(),
        ))
    }
}

/// Recorded work running on the GPU ([`Recorder::submit`]). Dropping it waits for the work
/// to finish, so the buffers it uses are not freed under it.
pub struct Submission {
    rec: Option<Recorder>,
    fence: vk::Fence,
}

impl Submission {
    /// Waits for the work and returns its per-kernel timings.
    pub fn wait(mut self) -> GpuResult<Timings> {
        let mut rec = self.rec.take().expect("waited once");
        rec.wait_for(self.fence)?;
        rec.read_timings()
    }
}

impl Drop for Submission {
    fn drop(&mut self) {
        if let Some(mut rec) = self.rec.take() {
            let _ = rec.wait_for(self.fence);
        }
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        let parts = self.parts;
        if self.idle {
            let mut recycled = self.gpu.inner.recycled_recorders.lock().unwrap();
            if recycled.len() < MAX_RECYCLED {
                recycled.push(parts);
                return;
            }
        }
        // SAFETY: an idle buffer is not pending; one that is not idle failed to submit or
        // to be waited for, a device error after which nothing of it runs.
        unsafe { parts.destroy(self.gpu.device()) }
    }
}

/// A byte range of a buffer, bound to one kernel binding.
#[derive(Clone, Copy)]
pub struct BufferRange<'a> {
    pub buffer: &'a Buffer,
    pub offset: u64,
    pub size: u64,
}

impl<'a> BufferRange<'a> {
    /// All of `buffer`.
    pub fn whole(buffer: &'a Buffer) -> Self {
        BufferRange {
            buffer,
            offset: 0,
            size: buffer.size(),
        }
    }

    /// `size` bytes of `buffer` from `offset`.
    pub fn new(buffer: &'a Buffer, offset: u64, size: u64) -> Self {
        BufferRange {
            buffer,
            offset,
            size,
        }
    }
}

fn whole<'a>(bindings: &[(&'a str, &'a Buffer)]) -> Vec<(&'a str, BufferRange<'a>)> {
    bindings
        .iter()
        .map(|(name, buf)| (*name, BufferRange::whole(buf)))
        .collect()
}

/// The buffer range given for each of the kernel's bindings, matched by GLSL name. A range
/// larger than one binding may hold is an error (the input was too large), not a panic.
fn buffer_infos(
    info: &KernelInfo,
    bindings: &[(&str, BufferRange)],
    caps: &DeviceCaps,
) -> GpuResult<Vec<[vk::DescriptorBufferInfo; 1]>> {
    let max_range = caps.max_storage_buffer_range;
    info.bindings
        .iter()
        .map(|b| {
            let range = bindings
                .iter()
                .find(|(n, _)| *n == b.name)
                .map(|(_, range)| *range)
                .unwrap_or_else(|| {
                    panic!(
                        "{}: no buffer given for binding '{}' (given: {:?})",
                        info.name,
                        b.name,
                        bindings.iter().map(|(n, _)| *n).collect::<Vec<_>>()
                    )
                });
            let buf = range.buffer;
            assert!(
                range.offset % caps.min_storage_offset_alignment == 0
                    && range.offset + range.size <= buf.size(),
                "{}: range {}+{} of buffer '{}' ({} bytes) is out of bounds or misaligned",
                info.name,
                range.offset,
                range.size,
                buf.name(),
                buf.size()
            );
            if range.size > max_range {
                return Err(GpuError::BindingRange {
                    kernel: info.name.to_string(),
                    buffer: buf.name().to_string(),
                    bytes: range.size,
                    max: max_range,
                });
            }
            Ok([vk::DescriptorBufferInfo::default()
                .buffer(buf.raw)
                .offset(range.offset)
                .range(if range.size == 0 {
                    vk::WHOLE_SIZE
                } else {
                    range.size
                })])
        })
        .collect()
}

/// `bindings`, and those of `optional` that `kernel` uses (the optimizer drops bindings a
/// variant never reads; binding one it lacks is an error).
pub fn with_optional<'a, P>(
    kernel: Kernel<P>,
    bindings: &[(&'a str, BufferRange<'a>)],
    optional: &[(&'a str, BufferRange<'a>)],
) -> Vec<(&'a str, BufferRange<'a>)> {
    let used = kernel.info().bindings;
    let mut all = bindings.to_vec();
    all.extend(
        optional
            .iter()
            .filter(|(name, _)| used.iter().any(|b| b.name == *name)),
    );
    all
}
