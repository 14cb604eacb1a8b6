//! Where a kernel chain reads its element count on the GPU, so callers need no readback.

use super::buffer::Buffer;

/// The element count is `ceil(buffer[index] / div) * mul` (u32 words), read on the GPU.
#[derive(Clone, Copy)]
pub struct GpuCount<'a> {
    pub buffer: &'a Buffer,
    pub index: u32,
    pub div: u32,
    pub mul: u32,
}

impl<'a> GpuCount<'a> {
    /// The count is the u32 at word `index` of `buffer`.
    pub fn at(buffer: &'a Buffer, index: u32) -> Self {
        GpuCount {
            buffer,
            index,
            div: 1,
            mul: 1,
        }
    }
}
