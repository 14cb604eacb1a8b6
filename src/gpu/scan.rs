//! GPU exclusive prefix sum of u32 (reduce-then-scan; no workgroup waits on another, so it
//! is correct on lavapipe). The element count is read from a GPU buffer.

use super::buffer::Buffer;
use super::context::Gpu;
use super::count::GpuCount;
use super::error::{GpuError, GpuResult};
use super::kernel_table::ids;
use super::recorder::Recorder;
use crate::contract;
use crate::contract::params::{ScanDownsweepParams, ScanReduceParams, ScanSetupParams};

/// Elements per workgroup.
pub const SCAN_BLOCK: u64 = contract::SCAN_BLOCK as u64;
/// Levels the state buffer has room for.
const MAX_LEVELS: usize = contract::SCAN_MAX_LEVELS as usize;
/// Word offset of the indirect arguments in the state buffer.
const ARGS_OFFSET: u64 = contract::SCAN_ARGS_OFFSET as u64;

/// A planned prefix scan for up to `capacity` elements, owning its scratch buffers.
pub struct PrefixScan {
    capacity: u64,
    /// partials[l] holds the block sums of level l, i.e. the elements of level l + 1.
    partials: Vec<Buffer>,
    state: Buffer,
}

impl PrefixScan {
    pub fn new(gpu: &Gpu, capacity: u64) -> GpuResult<PrefixScan> {
        let caps = gpu.caps();
        let max_groups = caps.max_workgroup_count[0] as u64;
        // Kernels reach the levels by address: one dispatch's workgroups (and a kernel's
        // signed 32-bit index) bound a scan, not one binding.
        let max_elems = (max_groups * SCAN_BLOCK).min(i32::MAX as u64);
        if capacity > max_elems {
            return Err(GpuError::Limit(format!(
                "prefix scan of {capacity} elements exceeds this device's limit of {max_elems}"
            )));
        }
        let mut partials = Vec::new();
        let mut n = capacity.max(1);
        while n > SCAN_BLOCK {
            n = n.div_ceil(SCAN_BLOCK);
            partials.push(gpu.buffer("scan-partials", n * 4)?);
        }
        debug_assert!(partials.len() < MAX_LEVELS);
        let state = gpu.buffer("scan-state", (ARGS_OFFSET + 3 * MAX_LEVELS as u64) * 4)?;
        Ok(PrefixScan {
            capacity,
            partials,
            state,
        })
    }

    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    fn level_buffer<'a>(&'a self, input: &'a Buffer, level: usize) -> &'a Buffer {
        if level == 0 {
            input
        } else {
            &self.partials[level - 1]
        }
    }

    /// Records `output[i] = input[0] + ... + input[i-1]` for the first `count` elements
    /// (clamped to the capacity). `input` and `output` may be the same buffer.
    pub fn record(
        &self,
        rec: &mut Recorder,
        input: &Buffer,
        output: &Buffer,
        count: GpuCount,
    ) -> GpuResult<()> {
        self.record_setup(rec, count)?;
        self.record_scan(rec, input, output)
    }

    /// Records the setup of scans of `count` elements alone: the element count and
    /// dispatch size of each level. Scans of the same count (a radix sort's passes) share
    /// one setup: a dispatch and a barrier each saved ([`PrefixScan::record_scan`]).
    pub fn record_setup(&self, rec: &mut Recorder, count: GpuCount) -> GpuResult<()> {
        let levels = self.partials.len() + 1;
        let setup = ScanSetupParams {
            count_index: count.index,
            div: count.div,
            mul: count.mul,
            levels: levels as u32,
            capacity: self.capacity as u32,
        };
        rec.dispatch(
            ids::SCAN_SETUP,
            &[("count_src", count.buffer), ("state", &self.state)],
            &setup,
            [1, 1, 1],
        )?;
        rec.barrier();
        Ok(())
    }

    /// Records the scan of `input` into `output` for the count of the last
    /// [`PrefixScan::record_setup`] recorded before it (in this or an earlier submission).
    pub fn record_scan(
        &self,
        rec: &mut Recorder,
        input: &Buffer,
        output: &Buffer,
    ) -> GpuResult<()> {
        let levels = self.partials.len() + 1;
        let args_offset = |level: usize| (ARGS_OFFSET + 3 * level as u64) * 4;
        for level in 0..levels - 1 {
            let params = ScanReduceParams {
                src_addr: self.level_buffer(input, level).address_words(4)?,
                sums_addr: self.partials[level].address_words(4)?,
                level: level as u32,
            };
            rec.dispatch_indirect(
                ids::SCAN_REDUCE,
                &[("state", &self.state)],
                &params,
                &self.state,
                args_offset(level),
            )?;
            rec.barrier();
        }
        for level in (0..levels).rev() {
            let top = level == levels - 1;
            let dst = if level == 0 {
                output
            } else {
                &self.partials[level - 1]
            };
            // The top level has no offsets (never read there).
            let offsets_addr = if top {
                [0; 2]
            } else {
                self.partials[level].address_words(4)?
            };
            let params = ScanDownsweepParams {
                src_addr: self.level_buffer(input, level).address_words(4)?,
                dst_addr: dst.address_words(4)?,
                offsets_addr,
                level: level as u32,
                has_offsets: u32::from(!top),
            };
            rec.dispatch_indirect(
                ids::SCAN_DOWNSWEEP,
                &[("state", &self.state)],
                &params,
                &self.state,
                args_offset(level),
            )?;
            rec.barrier();
        }
        Ok(())
    }
}

/// Exclusive scan of `data` on the GPU (uploads, scans, downloads): for tests and tools.
pub fn exclusive_scan(gpu: &Gpu, data: &[u32]) -> GpuResult<Vec<u32>> {
    let scan = PrefixScan::new(gpu, data.len() as u64)?;
    let buf = gpu.buffer_from("scan-data", data)?;
    let count = gpu.buffer_from("scan-count", &[data.len() as u32])?;
    let out = gpu.buffer("scan-out", data.len() as u64 * 4)?;
    let mut rec = Recorder::new(gpu)?;
    scan.record(&mut rec, &buf, &out, GpuCount::at(&count, 0))?;
    rec.submit_and_wait()?;
    gpu.download(&out, 0, data.len())
}
