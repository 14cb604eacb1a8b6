//! Staging buffers kept across the transfers of a loop over views, recorded into the
//! caller's own submission.
//!
//! Why: [`Gpu::upload`] and [`Gpu::download_many`] each make a fresh staging buffer and
//! submit and wait on their own. In a loop over hundreds of views that is an allocation and
//! a round trip per transfer; on an H100 the FlashSplat pass spent ~31 ms of host time a
//! view before its label maps went through reused staging buffers in the view's own
//! submission (~4 ms after, with other changes). Here the uploads are copied in at the
//! start of the caller's submission and the downloads copied out at its end, so a view's
//! transfers cost one wait.

use std::borrow::Cow;

use bytemuck::Pod;

use super::buffer::Buffer;
use super::context::Gpu;
use super::error::GpuResult;
use super::recorder::Recorder;

/// One host buffer for uploads and one for downloads, each grown to the largest transfer.
#[derive(Default)]
pub struct Staging {
    up: Option<Buffer>,
    down: Option<Buffer>,
    /// Byte lengths of the downloads last recorded, in order.
    downloads: Vec<u64>,
}

impl Staging {
    /// Writes each part's data into the upload buffer, back to back, and records its copy
    /// to the start of its destination, then a barrier (the next commands read them). The
    /// upload buffer must not be in use: the caller waited for its last submission.
    pub fn record_uploads<T: Pod>(
        &mut self,
        gpu: &Gpu,
        rec: &mut Recorder,
        parts: &[(&Buffer, &[T])],
    ) -> GpuResult<()> {
        let sizes: Vec<u64> = parts
            .iter()
            .map(|(_, data)| std::mem::size_of_val(*data) as u64)
            .collect();
        let up = grown(&mut self.up, gpu, sizes.iter().sum(), Gpu::staging_buffer)?;
        let mut at = 0;
        for ((dst, data), &bytes) in parts.iter().zip(&sizes) {
            assert!(bytes <= dst.size(), "upload past the end of {}", dst.name());
            up.write_mapped_at(at, data);
            rec.copy(up, at, dst, 0, bytes);
            at += bytes;
        }
        rec.barrier();
        Ok(())
    }

    /// Records copies of the leading `bytes` of each buffer into the download buffer, back
    /// to back, and the barrier that makes them visible to the host; [`Staging::read`]
    /// gives them once the submission has been waited for.
    pub fn record_downloads(
        &mut self,
        gpu: &Gpu,
        rec: &mut Recorder,
        ranges: &[(&Buffer, u64)],
    ) -> GpuResult<()> {
        self.downloads = ranges.iter().map(|r| r.1).collect();
        let down = grown(
            &mut self.down,
            gpu,
            self.downloads.iter().sum(),
            Gpu::readback_buffer,
        )?;
        let mut at = 0;
        for &(src, bytes) in ranges {
            assert!(
                bytes <= src.size(),
                "download past the end of {}",
                src.name()
            );
            rec.copy(src, 0, down, at, bytes);
            at += bytes;
        }
        rec.host_barrier();
        Ok(())
    }

    /// The downloads last recorded, as elements of T each (their submission waited for).
    pub fn read<T: Pod>(&mut self) -> Vec<Vec<T>> {
        self.read_with(|parts: &[&[T]]| parts.iter().map(|p| p.to_vec()).collect())
    }

    /// `read` given the downloads last recorded as elements of T each, read where they lie
    /// in the mapped buffer (a copy only where a part is not aligned for T): a large
    /// readback is read once instead of copied first.
    pub fn read_with<T: Pod, R>(&mut self, read: impl FnOnce(&[&[T]]) -> R) -> R {
        let bytes: &[u8] = self.down.as_mut().map(|d| &*d.mapped()).unwrap_or_default();
        let mut at = 0;
        let parts: Vec<Cow<[T]>> = self
            .downloads
            .iter()
            .map(|&len| {
                at += len as usize;
                let part = &bytes[at - len as usize..at];
                match bytemuck::try_cast_slice(part) {
                    Ok(words) => Cow::Borrowed(words),
                    Err(_) => Cow::Owned(bytemuck::pod_collect_to_vec(part)),
                }
            })
            .collect();
        let slices: Vec<&[T]> = parts.iter().map(|p| &**p).collect();
        read(&slices)
    }
}

/// `slot`'s buffer, replaced by a new one from `make` where it is smaller than `bytes`.
pub fn grown<'a>(
    slot: &'a mut Option<Buffer>,
    gpu: &Gpu,
    bytes: u64,
    make: fn(&Gpu, u64) -> GpuResult<Buffer>,
) -> GpuResult<&'a mut Buffer> {
    if slot.as_ref().is_none_or(|b| b.size() < bytes) {
        *slot = Some(make(gpu, bytes.max(4))?);
    }
    Ok(slot.as_mut().expect("made above"))
}
