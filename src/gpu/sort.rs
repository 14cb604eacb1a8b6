//! GPU radix sort of u32 keys with u32 values: stable, sorting only the low `bits` bits,
//! element count read from a GPU buffer. Each pass is count (per-block digit histogram),
//! an exclusive scan of the digit-major histogram, and a stable scatter: reduce-then-scan,
//! no workgroup waits on another, and every invocation's loops stay far below lavapipe's
//! 65,535-iteration cap. On CPU devices the count and scatter take their `*_wide` forms
//! (glsl/sort/wide_runs.glsl: each invocation walks a run of a block's keys in order, with
//! no ballots; `DeviceCaps::cpu_forms`) with digits of 6 bits where the GPU forms take 4:
//! the same blocks and result.

use super::buffer::Buffer;
use super::context::Gpu;
use super::count::GpuCount;
use super::error::{GpuError, GpuResult};
use super::kernel_table::ids;
use super::recorder::Recorder;
use super::scan::PrefixScan;
use crate::contract::params::{SortPassParams, SortSetupParams};
use crate::contract::{self, RADIX_BITS, RADIX_BITS_WIDE};

/// Elements per workgroup.
pub const SORT_BLOCK: u64 = contract::SORT_BLOCK as u64;

/// The digit width of the passes `gpu` runs: the CPU-driver forms count 6-bit digits
/// (fewer passes over the keys, the sort being half of a frame on lavapipe; a private
/// histogram of 64 per run: 128 and 256 measured slower there), the GPU forms 4 (their
/// shared-memory histograms and ballots grow with the digit).
pub fn digit_bits(gpu: &Gpu) -> u32 {
    match gpu.caps().cpu_forms {
        true => RADIX_BITS_WIDE,
        false => RADIX_BITS,
    }
}

/// The digit passes for sorting the low `bits` bits with digits of at most `digit` bits:
/// (shift, width) each. The number of passes is even so the result lands back in the
/// caller's buffers without a copy; the widths are spread evenly.
///
/// ```
/// use semsplat::gpu::sort::plan_passes;
/// // 13 bits (tile ids of a 1080p frame): four passes of 4 + 3 + 3 + 3 bits (with 6-bit
/// // digits too: three, made even); 12 bits: two passes of 6 bits with 6-bit digits.
/// assert_eq!(plan_passes(13, 4), vec![(0, 4), (4, 3), (7, 3), (10, 3)]);
/// assert_eq!(plan_passes(12, 6), vec![(0, 6), (6, 6)]);
/// // One bit still takes two passes (the second copies), so no copy-back is needed.
/// assert_eq!(plan_passes(1, 4).len(), 2);
/// ```
pub fn plan_passes(bits: u32, digit: u32) -> Vec<(u32, u32)> {
    assert!(bits <= 32, "radix sort of {bits} bits: keys are 32-bit");
    let mut passes = bits.div_ceil(digit.max(1));
    if passes % 2 == 1 {
        passes += 1;
    }
    let mut out = Vec::with_capacity(passes as usize);
    let mut shift = 0;
    for p in 0..passes {
        let width = bits / passes + u32::from(p < bits % passes);
        // A zero-width pass is a stable copy; keep its shift in range for bitfieldExtract.
        out.push((shift.min(31), width));
        shift += width;
    }
    out
}

/// A radix sorter for up to `capacity` pairs, owning its scratch buffers (reuse it).
pub struct RadixSort {
    capacity: u64,
    /// Bits of each pass's digit ([`digit_bits`]).
    digit: u32,
    tmp_keys: Buffer,
    tmp_values: Buffer,
    counts: Buffer,
    state: Buffer,
    scan: PrefixScan,
}

impl RadixSort {
    pub fn new(gpu: &Gpu, capacity: u64) -> GpuResult<RadixSort> {
        let caps = gpu.caps();
        let max_groups = caps.max_workgroup_count[0] as u64;
        // The passes reach keys and values by address: what bounds a sort is one
        // dispatch's workgroups (and a kernel's signed 32-bit index), not one binding.
        let max_elems = (max_groups * SORT_BLOCK).min(i32::MAX as u64);
        if capacity > max_elems {
            return Err(GpuError::Limit(format!(
                "radix sort of {capacity} pairs exceeds this device's limit of {max_elems} \
                 ({max_groups} workgroups of {SORT_BLOCK})"
            )));
        }
        let blocks = capacity.div_ceil(SORT_BLOCK).max(1);
        let digit = digit_bits(gpu);
        let radix = 1u64 << digit;
        Ok(RadixSort {
            capacity,
            digit,
            tmp_keys: gpu.buffer("sort-tmp-keys", capacity * 4)?,
            tmp_values: gpu.buffer("sort-tmp-values", capacity * 4)?,
            counts: gpu.buffer("sort-counts", blocks * radix * 4)?,
            state: gpu.buffer("sort-state", 16)?,
            scan: PrefixScan::new(gpu, blocks * radix)?,
        })
    }

    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// Records a stable sort of `keys` (with `values` alongside) by their low `bits` bits,
    /// in place, for the first `count` elements (clamped to the capacity).
    pub fn record(
        &self,
        rec: &mut Recorder,
        keys: &Buffer,
        values: &Buffer,
        count: GpuCount,
        bits: u32,
    ) -> GpuResult<()> {
        let passes = plan_passes(bits, self.digit);
        if passes.is_empty() {
            return Ok(());
        }
        let setup = SortSetupParams {
            count_index: count.index,
            capacity: self.capacity as u32,
        };
        rec.dispatch(
            ids::SORT_SETUP,
            &[("count_src", count.buffer), ("state", &self.state)],
            &setup,
            [1, 1, 1],
        )?;
        rec.barrier();
        // 2^digit counters per block; state[0] holds the block count. Every pass scans a
        // histogram of that size, so one scan setup serves them all.
        let histogram_len = GpuCount {
            buffer: &self.state,
            index: 0,
            div: 1,
            mul: 1 << self.digit,
        };
        self.scan.record_setup(rec, histogram_len)?;
        for (p, &(shift, width)) in passes.iter().enumerate() {
            let (src_k, src_v, dst_k, dst_v) = if p % 2 == 0 {
                (keys, values, &self.tmp_keys, &self.tmp_values)
            } else {
                (&self.tmp_keys, &self.tmp_values, keys, values)
            };
            let params = SortPassParams {
                keys_in_addr: src_k.address_words(4)?,
                values_in_addr: src_v.address_words(4)?,
                keys_out_addr: dst_k.address_words(4)?,
                values_out_addr: dst_v.address_words(4)?,
                shift,
                bits: width,
            };
            rec.dispatch_indirect(
                ids::SORT_COUNT.for_device(ids::SORT_COUNT_WIDE, rec.gpu()),
                &[("state", &self.state), ("counts", &self.counts)],
                &params,
                &self.state,
                0,
            )?;
            rec.barrier();
            self.scan.record_scan(rec, &self.counts, &self.counts)?;
            rec.dispatch_indirect(
                ids::SORT_SCATTER.for_device(ids::SORT_SCATTER_WIDE, rec.gpu()),
                &[("state", &self.state), ("offsets", &self.counts)],
                &params,
                &self.state,
                0,
            )?;
            rec.barrier();
        }
        Ok(())
    }
}

/// Sorts pairs on the GPU (uploads, sorts, downloads): for tests and tools.
pub fn sort_pairs(
    gpu: &Gpu,
    keys: &[u32],
    values: &[u32],
    bits: u32,
) -> GpuResult<(Vec<u32>, Vec<u32>)> {
    assert_eq!(keys.len(), values.len());
    let n = keys.len();
    let sorter = RadixSort::new(gpu, n as u64)?;
    let k = gpu.buffer_from("sort-keys", keys)?;
    let v = gpu.buffer_from("sort-values", values)?;
    let count = gpu.buffer_from("sort-count", &[n as u32])?;
    let mut rec = Recorder::new(gpu)?;
    sorter.record(&mut rec, &k, &v, GpuCount::at(&count, 0), bits)?;
    rec.submit_and_wait()?;
    Ok((gpu.download(&k, 0, n)?, gpu.download(&v, 0, n)?))
}
