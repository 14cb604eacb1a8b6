//! Buffers through gpu-allocator: device-local storage buffers, and staging buffers for
//! uploads and downloads.

use ash::vk;
use bytemuck::Pod;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::context::Gpu;
use super::error::{GpuError, GpuResult};
use super::recorder::Recorder;

/// A GPU buffer. Device-local buffers can be bound to kernels, used as indirect dispatch
/// arguments, and copied to and from.
pub struct Buffer {
    pub(crate) gpu: Gpu,
    pub(crate) raw: vk::Buffer,
    allocation: Option<Allocation>,
    size: u64,
    name: String,
    /// The buffer's device address (device-local buffers; 0 for staging buffers).
    address: u64,
}

impl Buffer {
    /// Size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The address kernels reach this buffer at (`GL_EXT_buffer_reference`), as the two
    /// 32-bit words of a `uvec2` push constant, for an array of `elem_bytes`-byte elements.
    ///
    /// Kernels that index per-Gaussian arrays at arbitrary Gaussians (through the tile
    /// lists) reach them by address, not by a binding: a binding is capped at
    /// maxStorageBufferRange (128 MiB on lavapipe, 8.4M Gaussians of 16 bytes), an address
    /// only by the buffer's own size. A shader's index is a signed 32-bit value, so the
    /// array may hold at most `i32::MAX` elements.
    pub fn address_words(&self, elem_bytes: u64) -> GpuResult<[u32; 2]> {
        assert!(self.address != 0, "{} has no device address", self.name);
        let elements = self.size / elem_bytes.max(1);
        if elements > i32::MAX as u64 {
            return Err(GpuError::Limit(format!(
                "buffer '{}' holds {elements} elements of {elem_bytes} bytes; a kernel indexes \
                 at most {} (use fewer Gaussians, classes per pass or pixels)",
                self.name,
                i32::MAX
            )));
        }
        Ok([self.address as u32, (self.address >> 32) as u32])
    }

    /// Writes `data` at the start of this host-mapped (staging) buffer.
    pub fn write_mapped<T: Pod>(&mut self, data: &[T]) {
        self.write_mapped_at(0, data);
    }

    /// Writes `data` at byte `offset` of this host-mapped (staging) buffer.
    pub fn write_mapped_at<T: Pod>(&mut self, offset: u64, data: &[T]) {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        assert!(
            offset + bytes.len() as u64 <= self.size,
            "staging buffer {} is too small",
            self.name
        );
        let at = offset as usize;
        self.mapped()[at..at + bytes.len()].copy_from_slice(bytes);
    }

    /// The first `count` elements of this host-mapped (readback) buffer; the GPU writes must
    /// be finished and made visible to the host ([`Recorder::host_barrier`] before the wait).
    pub fn read_mapped<T: Pod>(&mut self, count: usize) -> Vec<T> {
        let bytes = count * std::mem::size_of::<T>();
        bytemuck::pod_collect_to_vec(&self.mapped()[..bytes])
    }

    pub(crate) fn mapped(&mut self) -> &mut [u8] {
        let size = self.size as usize;
        self.allocation
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .map(|s| &mut s[..size])
            .expect("staging buffers are host-mapped")
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        if let Some(a) = self.allocation.take() {
            if let Some(alloc) = self.gpu.inner.allocator.lock().unwrap().as_mut() {
                let _ = alloc.free(a);
            }
        }
        // SAFETY: recorders wait for their submission before returning, so no command
        // using this buffer is pending.
        unsafe { self.gpu.device().destroy_buffer(self.raw, None) };
    }
}

/// Device-local buffers serve as kernel storage (bound, or reached by address), indirect
/// arguments and copy ends; staging buffers only as copy ends.
fn usage_for(location: MemoryLocation) -> vk::BufferUsageFlags {
    match location {
        MemoryLocation::GpuOnly => {
            vk::BufferUsageFlags::STORAGE_BUFFER
                | vk::BufferUsageFlags::TRANSFER_SRC
                | vk::BufferUsageFlags::TRANSFER_DST
                | vk::BufferUsageFlags::INDIRECT_BUFFER
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
        }
        _ => vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST,
    }
}

impl Gpu {
    fn create_buffer(&self, name: &str, size: u64, location: MemoryLocation) -> GpuResult<Buffer> {
        self.create_buffer_for(name, size, location, usage_for(location))
    }

    fn create_buffer_for(
        &self,
        name: &str,
        size: u64,
        location: MemoryLocation,
        usage: vk::BufferUsageFlags,
    ) -> GpuResult<Buffer> {
        // Vulkan forbids empty buffers; a 4-byte one keeps n = 0 cases uniform.
        let size = size.max(4);
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        let device = self.device();
        // SAFETY: valid create info; the buffer is destroyed on every error path below.
        let raw =
            unsafe { device.create_buffer(&info, None) }.map_err(|result| GpuError::Buffer {
                name: name.to_string(),
                size,
                what: "vkCreateBuffer",
                result,
            })?;
        let requirements = unsafe { device.get_buffer_memory_requirements(raw) };
        let allocation = self
            .inner
            .allocator
            .lock()
            .unwrap()
            .as_mut()
            .expect("allocator lives as long as the device")
            .allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            });
        let allocation = match allocation {
            Ok(a) => a,
            Err(source) => {
                unsafe { device.destroy_buffer(raw, None) };
                return Err(GpuError::Allocation {
                    name: name.to_string(),
                    size,
                    source,
                });
            }
        };
        if let Err(e) =
            unsafe { device.bind_buffer_memory(raw, allocation.memory(), allocation.offset()) }
        {
            unsafe { device.destroy_buffer(raw, None) };
            if let Some(alloc) = self.inner.allocator.lock().unwrap().as_mut() {
                let _ = alloc.free(allocation);
            }
            return Err(GpuError::Buffer {
                name: name.to_string(),
                size,
                what: "vkBindBufferMemory",
                result: e,
            });
        }
        self.name_object(raw, name);
        let address = if usage.contains(vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS) {
            let info = vk::BufferDeviceAddressInfo::default().buffer(raw);
            // SAFETY: a live buffer with memory bound, made with SHADER_DEVICE_ADDRESS on a
            // device with bufferDeviceAddress enabled (core in Vulkan 1.3, which we require).
            unsafe { device.get_buffer_device_address(&info) }
        } else {
            0
        };
        Ok(Buffer {
            gpu: self.clone(),
            raw,
            allocation: Some(allocation),
            size,
            name: name.to_string(),
            address,
        })
    }

    /// Gives `raw` its name in validation messages (only with validation on).
    fn name_object(&self, raw: vk::Buffer, name: &str) {
        let Some(names) = &self.inner.debug_names else {
            return;
        };
        let Ok(name) = std::ffi::CString::new(name) else {
            return;
        };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(raw)
            .object_name(&name);
        // SAFETY: `raw` is a live buffer of this device; a failure only loses the name.
        let _ = unsafe { names.set_debug_utils_object_name(&info) };
    }

    /// A device-local buffer of `size` bytes (contents undefined).
    pub fn buffer(&self, name: &str, size: u64) -> GpuResult<Buffer> {
        self.create_buffer(name, size, MemoryLocation::GpuOnly)
    }

    /// A device-local buffer holding `data`.
    pub fn buffer_from<T: Pod>(&self, name: &str, data: &[T]) -> GpuResult<Buffer> {
        let buf = self.buffer(name, std::mem::size_of_val(data) as u64)?;
        self.upload(&buf, 0, data)?;
        Ok(buf)
    }

    /// A host-visible staging buffer for [`Gpu::upload_with`], reused across uploads (one per
    /// view in a loop over views, instead of an allocation each time).
    ///
    /// It lives in cached system memory (the allocator's `GpuToCpu` choice), not in the
    /// host-visible device memory that `CpuToGpu` prefers: the copy engine reads system
    /// memory at full speed, while CPU writes through the PCIe BAR into device memory can
    /// crawl where the BAR is mapped uncached (as in VMs). On an H100 VM, fusion's
    /// per-view host time fell from ~31 ms to ~4 ms with this and the fusion bench's
    /// change to one run over all views; the two were not measured apart.
    pub fn staging_buffer(&self, size: u64) -> GpuResult<Buffer> {
        self.create_buffer("staging-upload", size, MemoryLocation::GpuToCpu)
    }

    /// A host-readable buffer that GPU copies write into ([`Buffer::read_mapped`]).
    pub fn readback_buffer(&self, size: u64) -> GpuResult<Buffer> {
        self.create_buffer("readback", size, MemoryLocation::GpuToCpu)
    }

    /// A host-readable buffer that kernels write by address ([`Buffer::address_words`]),
    /// read on the host after the fence ([`Recorder::host_barrier`]) with no copy: for an
    /// output whose size only the GPU knows (a view's compacted observations), which a
    /// copy recorded beforehand would have to take whole. Cached system memory, as
    /// [`Gpu::readback_buffer`].
    pub fn host_output_buffer(&self, name: &str, size: u64) -> GpuResult<Buffer> {
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
            | vk::BufferUsageFlags::TRANSFER_DST;
        self.create_buffer_for(name, size, MemoryLocation::GpuToCpu, usage)
    }

    /// Copies `data` into `dst` at byte `offset` through a fresh staging buffer, and waits.
    pub fn upload<T: Pod>(&self, dst: &Buffer, offset: u64, data: &[T]) -> GpuResult<()> {
        let bytes = std::mem::size_of_val(data) as u64;
        if bytes == 0 {
            return Ok(());
        }
        let mut staging = self.staging_buffer(bytes)?;
        self.upload_with(&mut staging, dst, offset, data)
    }

    /// Copies `data` into `dst` at byte `offset` through `staging` (a
    /// [`Gpu::staging_buffer`] at least as large), and waits.
    pub fn upload_with<T: Pod>(
        &self,
        staging: &mut Buffer,
        dst: &Buffer,
        offset: u64,
        data: &[T],
    ) -> GpuResult<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.is_empty() {
            return Ok(());
        }
        assert!(
            offset + bytes.len() as u64 <= dst.size,
            "upload past the end of {}",
            dst.name
        );
        staging.write_mapped(bytes);
        let mut rec = Recorder::new(self)?;
        rec.copy(staging, 0, dst, offset, bytes.len() as u64);
        rec.submit_and_wait()?;
        Ok(())
    }

    /// Reads `count` elements of type T from `src` starting at byte `offset`, and waits.
    pub fn download<T: Pod>(&self, src: &Buffer, offset: u64, count: usize) -> GpuResult<Vec<T>> {
        let len = (count * std::mem::size_of::<T>()) as u64;
        let bytes = self
            .download_many(&[(src, offset, len)])?
            .pop()
            .unwrap_or_default();
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// Reads several ranges `(buffer, byte offset, bytes)` through one staging buffer and one
    /// submission (a frame's outputs at once), returning the bytes of each.
    pub fn download_many(&self, ranges: &[(&Buffer, u64, u64)]) -> GpuResult<Vec<Vec<u8>>> {
        let total: u64 = ranges.iter().map(|r| r.2).sum();
        if total == 0 {
            return Ok(ranges.iter().map(|_| Vec::new()).collect());
        }
        let mut staging = self.stage_download(ranges, total)?;
        let bytes = staging.mapped();
        let mut at = 0;
        Ok(ranges
            .iter()
            .map(|r| {
                let v = bytes[at as usize..(at + r.2) as usize].to_vec();
                at += r.2;
                v
            })
            .collect())
    }

    /// Reads `len` bytes of `src` from byte `offset` and hands them to `read` straight from
    /// the staging buffer (a large matrix is converted once, not copied first), and waits.
    pub fn download_with<R>(
        &self,
        src: &Buffer,
        offset: u64,
        len: u64,
        read: impl FnOnce(&[u8]) -> R,
    ) -> GpuResult<R> {
        if len == 0 {
            return Ok(read(&[]));
        }
        let mut staging = self.stage_download(&[(src, offset, len)], len)?;
        Ok(read(&staging.mapped()[..len as usize]))
    }

    /// A host staging buffer holding `ranges` back to back (`total` bytes), copied in one
    /// submission.
    fn stage_download(&self, ranges: &[(&Buffer, u64, u64)], total: u64) -> GpuResult<Buffer> {
        let staging = self.create_buffer("staging-download", total, MemoryLocation::GpuToCpu)?;
        let mut rec = Recorder::new(self)?;
        let mut at = 0;
        for &(src, offset, len) in ranges {
            assert!(
                offset + len <= src.size,
                "download past the end of {}",
                src.name
            );
            rec.copy(src, offset, &staging, at, len);
            at += len;
        }
        rec.host_barrier();
        rec.submit_and_wait()?;
        Ok(staging)
    }

    /// Reads the whole buffer as elements of type T.
    pub fn read<T: Pod>(&self, src: &Buffer) -> GpuResult<Vec<T>> {
        self.download(src, 0, src.size as usize / std::mem::size_of::<T>())
    }
}
