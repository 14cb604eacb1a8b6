//! The GPU forward rasterizer: project, compact, depth sort, emit tile intersections,
//! stable sort by tile id on only the bits needed, tile ranges, blend. Counts stay on the
//! GPU (indirect dispatch); the only host read is after the frame, to fetch the images and
//! the overflow flag that tells the buffers to grow.

use std::ops::Range;

use anyhow::{ensure, Result};

use super::chunks::{bands, chunk_len, chunks, part_of, row_step, Band, BandLimits, CHUNK_GRANULE};
use super::frame::RenderedFrame;
use super::gpu_scene::{GpuScene, ParamTensor, SceneAttributes};
use super::windows::{window_args_bytes, PassWindows};
use super::{project_params, RenderOptions, SemanticMode, StageTimes};
use crate::contract::params::{BlendParams, CompactParams, EmitParams, GatherTouchedParams};
use crate::contract::{
    BLEND_CARRY_BASE, GRAD2D_STRIDE, ST_ARGS_ISECT, ST_ARGS_VISIBLE, ST_ISECT, ST_ISECT_NEEDED,
    ST_ISECT_WRAPPED, ST_N_PLUS1, ST_OVERFLOW, ST_VISIBLE, ST_VISIBLE_PLUS1, ST_WORDS,
};
use crate::gpu::kernel_table::{ids, Kernel};
use crate::gpu::{
    Buffer, BufferRange, Gpu, GpuCount, Mark, PrefixScan, RadixSort, Recorder, Submission, Timings,
};
use crate::scene::Camera;

pub use crate::contract::{SEM_CHUNK, TILE_SIZE};

/// Entries of a tile's list one per-tile dispatch walks on a device without a loop cap:
/// every list fits one window (a list holds at most n <= u32::MAX / 2 entries in practice,
/// and starts plus lengths stay inside u32 in the kernels).
const UNCAPPED_WINDOW: u32 = u32::MAX / 2;

/// Buffers sized for the largest scene, image and intersection count seen so far.
struct Buffers {
    n_cap: u32,
    pixel_cap: u64,
    sem_cap: u64,
    best_cap: u64,
    carry_cap: u64,
    window_args_cap: u64,
    tiles_cap: u32,
    isect_cap: u32,
    xy: Buffer,
    xy_frac: Buffer,
    camera64: Buffer,
    conic: Buffer,
    color: Buffer,
    rect: Buffer,
    flags: Buffer,
    visible_offsets: Buffer,
    depth_keys: Buffer,
    depth_ids: Buffer,
    sorted_touched: Buffer,
    isect_offsets: Buffer,
    isect_keys: Buffer,
    isect_ids: Buffer,
    ranges: Buffer,
    /// Indirect arguments of the per-tile passes' later windows (src/render/windows.rs).
    window_args: Buffer,
    carry: Buffer,
    rgb: Buffer,
    alpha: Buffer,
    depth: Buffer,
    /// Per pixel, the depth where the transmittance falls below `OPAQUE_T` (median-depth
    /// frames only).
    opaque_depth: Buffer,
    final_t: Buffer,
    last: Buffer,
    n_contrib: Buffer,
    sem: Buffer,
    sem_norm: Buffer,
    /// Per pixel (value bits, class) of the label argmax.
    label_best: Buffer,
    /// Frame status words (ST_*), one region of `status_stride` words per band of tile rows
    /// a view is binned in; the frame-wide words are copied from band 0's into the others.
    status: Buffer,
    /// Host-readable copy of `status`, written at the end of each view's submission.
    status_host: Buffer,
    status_stride: u32,
    scan_n: PrefixScan,
    scan_v: PrefixScan,
    depth_sort: RadixSort,
    tile_sort: RadixSort,
}

/// Renders scenes on the GPU; reuses its buffers across frames and grows them on demand.
pub struct Rasterizer {
    /// The attempt at a view submitted and not yet waited for. The first field, so a
    /// dropped rasterizer waits for it before its buffers are freed.
    pending: Option<PendingRun>,
    gpu: Gpu,
    bufs: Option<Buffers>,
    /// Entries of a tile's list one per-tile dispatch walks (see [`FrameSpec::window_len`]).
    window_len: u32,
    /// Project means in float64 (on devices with shaderFloat64).
    float64: bool,
    /// Gaussians per projection dispatch, when a test sets it (else from the binding limit).
    projection_chunk: Option<u32>,
    /// Tile rows per band of a per-tile pass, when a test sets it (else as many as fit).
    band_rows: Option<u32>,
    /// Bands of tile rows the last view was binned in (see `run_tiled_in_bands`).
    list_bands: u32,
    /// Entries one band's lists hold at most, when a test sets it (else one binding's).
    list_capacity: Option<u32>,
    /// The rows an additive pass's view must run again after some of its bands overflowed.
    retry: Option<Retry>,
}

/// What a per-tile pass does to the frame, which decides what a view whose lists
/// overflowed in some bands runs again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BandWork {
    /// Writes each pixel's outputs (rendering, depths): the whole view runs again, since
    /// growing the lists may reallocate the outputs the other bands wrote.
    Overwrite,
    /// Adds into the caller's buffers (fusion's evidence): the bands that did not overflow
    /// have added their part, so only the rows of those that did run again (running every
    /// band again counted the others twice).
    Add,
}

/// The rows of a view an additive pass runs again, and the intersections its bands that
/// did not overflow already binned (for the run's statistics).
struct Retry {
    cam: Camera,
    rows: Vec<Range<u32>>,
    intersections: u32,
}

/// How finely the rasterizer splits its work, where a test overrides the sizes the device
/// dictates, so small scenes walk the split paths (None: the device's size).
#[derive(Clone, Copy, Debug, Default)]
pub struct SplitSizes {
    /// Entries of a tile's list one per-tile dispatch walks.
    pub window_len: Option<u32>,
    /// Tile rows one per-tile dispatch covers.
    pub band_rows: Option<u32>,
    /// Entries one band's intersection lists may hold before the view is binned in
    /// (more) bands of tile rows.
    pub list_capacity: Option<u32>,
}

/// One attempt at a view, submitted ([`Rasterizer::submit_tiled_in_bands`]).
struct PendingRun {
    submission: Submission,
    recorded: RecordedRun,
    cam: Camera,
    banded: bool,
    work: BandWork,
    /// The attempt's bands of tile rows, and whether they are only the rows of an
    /// additive pass's retry (not the whole frame).
    rows: Vec<Range<u32>>,
    partial: bool,
    /// Intersections of the view's bands an earlier attempt already ran (a retry's).
    done_intersections: u32,
    /// The sizes the attempt ran with (grown from on an overflow).
    need: Need,
}

/// Where an attempt's timestamps are: the frame's marks (before projection, depth sort and
/// binning, ...) and (start, lists built, per-tile done) for each band.
struct RecordedRun {
    marks: [Option<Mark>; 5],
    spans: Vec<(Option<Mark>, Option<Mark>, Option<Mark>)>,
    channels: u32,
}

impl RecordedRun {
    /// The run, from the attempt's timings and each band's status words.
    fn run(&self, timings: Timings, statuses: &[Vec<u32>]) -> TiledRun {
        let [m0, m1, m2, ..] = self.marks;
        let mut stages = StageTimes::from_marks(&timings, &[m0, m1, m2, m2, m2]);
        for &(start, lists, end) in &self.spans {
            stages.bin_ms += timings.between(start, lists).unwrap_or(0.0) * 1e-6;
            stages.blend_ms += timings.between(lists, end).unwrap_or(0.0) * 1e-6;
        }
        TiledRun {
            timings,
            marks: self.marks,
            stages,
            visible: statuses[0][ST_VISIBLE as usize],
            intersections: statuses.iter().map(|s| s[ST_ISECT as usize]).sum(),
            list_bands: statuses.len() as u32,
            channels: self.channels,
        }
    }
}

/// Most bands of tile rows one view's lists are split into (a status region each).
const MAX_LIST_BANDS: u32 = 256;

/// What [`Rasterizer::run_binned`] does after a run.
enum Attempt {
    Done,
    /// Grow the intersection lists to this many entries and run again.
    Grow(u32),
    /// Bin the view in this many bands of tile rows and run again.
    Split(u32),
}

/// The emission kernel for a band of `rows` tile rows `tiles_x` wide: the CPU drivers' form
/// (one invocation a Gaussian) where one Gaussian's pairs in the band stay under the
/// driver's loop cap, which counts every iteration of an invocation (a Gaussian of 70k
/// tiles lost its last 4,653 in a 4224x4224 view); else the load-balanced form, whose
/// invocations write a 256th of their group's pairs.
fn emit_kernel(gpu: &Gpu, tiles_x: u32, rows: &Range<u32>) -> Kernel<EmitParams> {
    let iterations = rows.len() as u64 * (tiles_x as u64 + 1);
    let fits = gpu
        .caps()
        .loop_iteration_cap
        .is_none_or(|cap| iterations < cap as u64);
    match fits {
        true => ids::RASTER_EMIT.for_device(ids::RASTER_EMIT_WIDE, gpu),
        false => ids::RASTER_EMIT,
    }
}

/// The fewest bands, from `least` up (at most one a tile row, and [`MAX_LIST_BANDS`]), that
/// [`split_rows`] really makes more of than the `bands` an attempt had: band starts are
/// multiples of `step` rows, so several counts give the same bands, and asking for one of
/// those again would run the same attempt for ever. None where no count gives more.
fn more_bands(tiles_y: u32, least: u32, bands: u32, step: u32) -> Option<u32> {
    let most = tiles_y.min(MAX_LIST_BANDS);
    (least.min(most)..=most).find(|&m| split_rows(tiles_y, m, step).len() as u32 > bands)
}

/// `tiles_y` tile rows split into at most `bands` consecutive ranges of nearly equal size,
/// each starting at a multiple of `step` rows.
fn split_rows(tiles_y: u32, bands: u32, step: u32) -> Vec<Range<u32>> {
    split_range(0..tiles_y.max(1), bands, step)
}

/// `rows` (starting at a multiple of `step`) split into at most `bands` consecutive ranges
/// of nearly equal size, each starting at a multiple of `step` rows.
fn split_range(rows: Range<u32>, bands: u32, step: u32) -> Vec<Range<u32>> {
    let per_band = rows
        .len()
        .div_ceil(bands.max(1) as usize)
        .next_multiple_of(step.max(1) as usize)
        .max(1);
    let end = rows.end;
    rows.step_by(per_band)
        .map(|first| first..(first + per_band as u32).min(end))
        .collect()
}

/// Sizes a frame needs.
#[derive(Clone, Copy)]
struct Need {
    n: u32,
    pixels: u64,
    tiles: u32,
    sem: u64,
    /// Pixels of the label argmax (0 unless rendering labels).
    best: u64,
    carry: u64,
    /// Bytes of indirect arguments: one (x, y, z) per later window and band of tile rows.
    window_args: u64,
    isect: u32,
}

fn grow(current: u64, need: u64) -> u64 {
    if need <= current {
        current
    } else {
        need.max(current + current / 2)
    }
}

impl Buffers {
    fn new(gpu: &Gpu, need: Need) -> Result<Buffers> {
        let n = need.n.max(1) as u64;
        let p = need.pixels.max(1);
        let isect = need.isect.max(1) as u64;
        let b = |name: &str, bytes: u64| gpu.buffer(name, bytes);
        // Each band's status region starts at an offset the device can bind.
        let align_words = gpu.caps().min_storage_offset_alignment.div_ceil(4) as u32;
        let status_stride = ST_WORDS
            .max(align_words)
            .next_multiple_of(align_words.max(1));
        Ok(Buffers {
            n_cap: n as u32,
            pixel_cap: p,
            sem_cap: need.sem,
            best_cap: need.best,
            carry_cap: need.carry,
            window_args_cap: need.window_args,
            tiles_cap: need.tiles,
            isect_cap: isect as u32,
            xy: b("xy_depth_opacity", n * 16)?,
            xy_frac: b("xy_frac", n * 8)?,
            camera64: b("camera64", 16 * 8)?,
            conic: b("conics", n * 16)?,
            color: b("colors", n * 16)?,
            rect: b("tile_rects", n * 16)?,
            flags: b("visible", (n + 1) * 4)?,
            visible_offsets: b("visible_offsets", (n + 1) * 4)?,
            depth_keys: b("depth_keys", n * 4)?,
            depth_ids: b("depth_ids", n * 4)?,
            sorted_touched: b("sorted_touched", (n + 1) * 4)?,
            isect_offsets: b("isect_offsets", (n + 1) * 4)?,
            isect_keys: b("isect_keys", isect * 4)?,
            isect_ids: b("isect_ids", isect * 4)?,
            ranges: b("tile_ranges", need.tiles as u64 * 8)?,
            window_args: b("window_args", need.window_args.max(12))?,
            carry: b("carry", need.carry * 4)?,
            rgb: b("rgb", p * 12)?,
            alpha: b("alpha", p * 4)?,
            depth: b("depth", p * 4)?,
            opaque_depth: b("opaque_depth", p * 4)?,
            final_t: b("final_t", p * 4)?,
            last: b("last", p * 4)?,
            n_contrib: b("n_contrib", p * 4)?,
            sem: b("sem", need.sem * 4)?,
            sem_norm: b("sem_norm", need.sem * 4)?,
            label_best: b("label_best", need.best.max(1) * 8)?,
            status: b("status", MAX_LIST_BANDS as u64 * status_stride as u64 * 4)?,
            status_host: gpu.readback_buffer(MAX_LIST_BANDS as u64 * status_stride as u64 * 4)?,
            status_stride,
            scan_n: PrefixScan::new(gpu, n + 1)?,
            scan_v: PrefixScan::new(gpu, n + 1)?,
            depth_sort: RadixSort::new(gpu, n)?,
            tile_sort: RadixSort::new(gpu, isect)?,
        })
    }

    fn fits(&self, need: Need) -> bool {
        need.n <= self.n_cap
            && need.pixels <= self.pixel_cap
            && need.sem <= self.sem_cap
            && need.best <= self.best_cap
            && need.carry <= self.carry_cap
            && need.window_args <= self.window_args_cap
            && need.tiles <= self.tiles_cap
            && need.isect <= self.isect_cap
    }
}

/// Bits needed to hold tile ids 0..tiles.
fn tile_bits(tiles: u32) -> u32 {
    32 - tiles.saturating_sub(1).leading_zeros()
}

impl Rasterizer {
    pub fn new(gpu: &Gpu) -> Rasterizer {
        // A device that cuts loops after `cap` iterations per invocation gets windows of
        // half the cap, so the per-entry loops and their bookkeeping stay below it.
        let window_len = gpu
            .caps()
            .loop_iteration_cap
            .map_or(UNCAPPED_WINDOW, |cap| cap.div_ceil(2));
        Rasterizer {
            gpu: gpu.clone(),
            bufs: None,
            window_len,
            float64: gpu.caps().float64,
            projection_chunk: None,
            band_rows: None,
            list_bands: 1,
            list_capacity: None,
            pending: None,
            retry: None,
        }
    }

    /// Chooses float64 (default where the device has it) or float32 projection of the
    /// means; float32 loses about 1e-5 px, which shows in alpha far from a center.
    pub fn set_float64_projection(&mut self, on: bool) {
        self.float64 = on && self.gpu.caps().float64;
    }

    /// The device this rasterizer renders on.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// How many windows walk the longest tile list of a scene of `n` Gaussians.
    pub fn windows_for(&self, n: u32) -> u32 {
        n.div_ceil(self.window_len).max(1)
    }

    /// Overrides how many entries of a tile's list one blend dispatch walks (tests use a
    /// small window to exercise the carried state on small scenes).
    pub fn set_window_len(&mut self, len: u32) {
        self.window_len = len.max(1);
    }

    /// Overrides how many Gaussians one projection dispatch covers (rounded to whole
    /// granules; tests use a small chunk to split small scenes).
    pub fn set_projection_chunk(&mut self, len: u32) {
        self.projection_chunk = Some(len.div_ceil(CHUNK_GRANULE).max(1) * CHUNK_GRANULE);
    }

    /// Overrides how many tile rows one per-tile dispatch covers (tests split small images).
    pub fn set_band_rows(&mut self, rows: u32) {
        self.band_rows = Some(rows.max(1));
    }

    /// Overrides how many entries one band's intersection lists hold at most (tests bin
    /// small views in bands of tile rows).
    pub fn set_list_capacity(&mut self, entries: u32) {
        self.list_capacity = Some(entries.max(1));
    }

    /// Applies every size `split` overrides.
    pub fn set_split_sizes(&mut self, split: SplitSizes) {
        if let Some(len) = split.window_len {
            self.set_window_len(len);
        }
        if let Some(rows) = split.band_rows {
            self.set_band_rows(rows);
        }
        if let Some(entries) = split.list_capacity {
            self.set_list_capacity(entries);
        }
    }

    /// Entries one intersection list may hold: one binding's worth (or a test's override).
    fn list_capacity(&self) -> u32 {
        let binding = self.gpu.caps().max_storage_buffer_range / 4;
        self.list_capacity
            .map_or(binding, |c| c as u64)
            .min(binding)
            .min(u32::MAX as u64) as u32
    }

    /// Gaussians one projection dispatch (or its backward) covers: as many as the widest
    /// per-Gaussian range (SH coefficients, the 16-byte projected attributes, or the
    /// backward's screen-space gradient) fits in one binding.
    fn projection_chunk_len(&self, scene: &GpuScene) -> Result<u32> {
        if let Some(len) = self.projection_chunk {
            return Ok(len);
        }
        let widest = ParamTensor::ALL
            .iter()
            .filter(|&&p| scene.attributes.holds(p))
            .map(|p| p.floats(scene.sh_coeffs) as u64 * 4)
            .max()
            .unwrap_or(0)
            .max(GRAD2D_STRIDE as u64 * 4);
        let max_range = self.gpu.caps().max_storage_buffer_range;
        chunk_len(widest, 4, max_range).ok_or_else(|| {
            anyhow::anyhow!(
                "one Gaussian's parameters take {widest} bytes, too many for the device's \
                 {max_range}-byte binding limit"
            )
        })
    }

    fn ensure(&mut self, need: Need) -> Result<()> {
        let ok = self.bufs.as_ref().is_some_and(|b| b.fits(need));
        if !ok {
            let merged = match &self.bufs {
                Some(b) => Need {
                    n: grow(b.n_cap as u64, need.n as u64) as u32,
                    pixels: grow(b.pixel_cap, need.pixels),
                    tiles: grow(b.tiles_cap as u64, need.tiles as u64) as u32,
                    sem: grow(b.sem_cap, need.sem),
                    best: grow(b.best_cap, need.best),
                    carry: grow(b.carry_cap, need.carry),
                    window_args: grow(b.window_args_cap, need.window_args),
                    // Growth past a need never exceeds what one list may hold.
                    isect: grow(b.isect_cap as u64, need.isect as u64)
                        .min(self.list_capacity() as u64)
                        .max(need.isect as u64) as u32,
                },
                None => need,
            };
            self.bufs = None; // free before allocating the larger set
            self.bufs = Some(Buffers::new(&self.gpu, merged)?);
        }
        Ok(())
    }

    /// Renders one view and downloads its images.
    pub fn render(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
    ) -> Result<RenderedFrame> {
        let frame =
            self.run_tiled_in_bands(scene, cam, opts, BandWork::Overwrite, |rec, tiles| {
                tiles.record_blend(rec)
            })?;
        self.download_frame(cam, &frame)
    }

    /// Downloads the images of the frame `run` just rendered.
    pub(crate) fn download_frame(&self, cam: &Camera, frame: &TiledRun) -> Result<RenderedFrame> {
        let b = self.bufs.as_ref().expect("ran");
        let stages = frame.stages;
        RenderedFrame::download(
            &self.gpu,
            cam,
            frame.channels,
            [
                &b.rgb,
                &b.alpha,
                &b.depth,
                &b.final_t,
                &b.last,
                &b.n_contrib,
                &b.sem,
                &b.sem_norm,
            ],
            frame.visible,
            frame.intersections,
            stages,
        )
    }

    /// Bins one view on the GPU (projection, depth sort, tile lists) and, in the same
    /// submission, records `per_tile`: the stage that consumes the tile lists (blending,
    /// or the fusion kernels). On an intersection overflow the buffers grow and everything
    /// is recorded again, so `per_tile` may run more than once. The tile lists carry the
    /// frame (`opts`' semantics, background, windows) that every per-tile pass reads. The
    /// whole view is binned at once: a view whose lists pass one binding is an error (see
    /// [`Rasterizer::run_tiled_in_bands`]).
    pub fn run_tiled<F>(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        per_tile: F,
    ) -> Result<TiledRun>
    where
        F: FnMut(&mut Recorder, &TileLists) -> Result<()>,
    {
        self.run_binned(scene, cam, opts, None, per_tile)
    }

    /// [`Rasterizer::run_tiled`] for passes that honour [`FrameSpec::rows`]: a view whose
    /// (tile, Gaussian) pairs pass one binding (or 2^32) is binned in bands of tile rows,
    /// each binned and passed to `per_tile` in turn. `work` says what runs again where some
    /// bands overflowed ([`BandWork`]).
    pub fn run_tiled_in_bands<F>(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        work: BandWork,
        per_tile: F,
    ) -> Result<TiledRun>
    where
        F: FnMut(&mut Recorder, &TileLists) -> Result<()>,
    {
        self.run_binned(scene, cam, opts, Some(work), per_tile)
    }

    /// Runs the view until no band overflows (`banded`: None bins it in one band).
    fn run_binned<F>(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        banded: Option<BandWork>,
        mut per_tile: F,
    ) -> Result<TiledRun>
    where
        F: FnMut(&mut Recorder, &TileLists) -> Result<()>,
    {
        loop {
            self.submit_binned(scene, cam, opts, banded, &mut per_tile)?;
            if let Some(run) = self.wait_tiled()? {
                return Ok(run);
            }
        }
    }

    /// [`Rasterizer::run_tiled_in_bands`] without waiting: records one attempt at the view
    /// and submits it; the host may prepare other work (another rasterizer's view) while it
    /// runs. [`Rasterizer::wait_tiled`] finishes it. The buffers `per_tile` binds must
    /// outlive the wait (dropping the rasterizer waits too).
    pub fn submit_tiled_in_bands<F>(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        work: BandWork,
        mut per_tile: F,
    ) -> Result<()>
    where
        F: FnMut(&mut Recorder, &TileLists) -> Result<()>,
    {
        self.submit_binned(scene, cam, opts, Some(work), &mut per_tile)
    }

    /// Records one attempt at the view (binning and `per_tile`, band by band, then a copy
    /// of the status words the host reads) and submits it: the whole frame, or an additive
    /// pass's rows left to run again.
    fn submit_binned<F>(
        &mut self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        banded: Option<BandWork>,
        per_tile: &mut F,
    ) -> Result<()>
    where
        F: FnMut(&mut Recorder, &TileLists) -> Result<()>,
    {
        ensure!(
            cam.width > 0 && cam.height > 0,
            "camera {} has an empty image",
            cam.name
        );
        // One view in flight per rasterizer (its buffers are shared), and an attempt that
        // overflowed must be run again by whoever submitted it, not dropped here.
        ensure!(
            self.pending.is_none(),
            "internal error: a view is still in flight on this rasterizer; wait for it first"
        );
        let work = banded.unwrap_or(BandWork::Overwrite);
        let retry = self.retry.take().filter(|r| r.cam == *cam);
        let frame = self.frame_spec(scene, cam, opts)?;
        let need = self.need(scene, &frame);
        self.ensure(need)?;
        let (rows, partial, done_intersections) = match retry {
            Some(r) if work == BandWork::Add => (r.rows, true, r.intersections),
            _ => {
                // Start from the last view's band count: neighbouring views need about the
                // same.
                let bands = match banded {
                    Some(_) => self.list_bands.min(frame.tiles_y),
                    None => 1,
                };
                let step = row_step(cam.width, frame.band_limits.offset_alignment);
                (split_rows(frame.tiles_y, bands, step), false, 0)
            }
        };
        let (recorded, rec) = self.record_bands(scene, opts, &frame, &rows, per_tile)?;
        self.pending = Some(PendingRun {
            submission: rec.submit()?,
            recorded,
            cam: cam.clone(),
            banded: banded.is_some(),
            work,
            rows,
            partial,
            done_intersections,
            need,
        });
        Ok(())
    }

    /// Waits for the view [`Rasterizer::submit_tiled_in_bands`] submitted, if any: its run
    /// when the view is done. None when its lists overflowed: the rasterizer has grown them
    /// (or chosen more bands), and the view must run again
    /// ([`Rasterizer::run_tiled_in_bands`]); its `per_tile` work saw the overflow flag and
    /// must have added nothing.
    pub fn wait_tiled(&mut self) -> Result<Option<TiledRun>> {
        let Some(pending) = self.pending.take() else {
            return Ok(None);
        };
        let timings = pending.submission.wait()?;
        let b = self.bufs.as_mut().expect("ensured");
        let stride = b.status_stride as usize;
        let bands = pending.recorded.spans.len();
        let words: Vec<u32> = b.status_host.read_mapped(bands * stride);
        let statuses: Vec<Vec<u32>> = words.chunks(stride).map(|w| w.to_vec()).collect();
        let mut run = pending.recorded.run(timings, &statuses);
        run.intersections = run.intersections.saturating_add(pending.done_intersections);
        let attempt = self.next_attempt(&pending.cam, &statuses, bands as u32, pending.banded)?;
        // Set only once the view can run again: a retry left by an attempt that failed
        // here would bin a later view's rows from this one's.
        let retry = match pending.work == BandWork::Add && !matches!(attempt, Attempt::Done) {
            true => {
                let done = pending.done_intersections;
                Some(self.failed_rows(&pending.cam, &pending.rows, done, &statuses, &attempt)?)
            }
            false => None,
        };
        match attempt {
            Attempt::Done => {
                if !pending.partial {
                    self.list_bands = bands as u32;
                }
                Ok(Some(run))
            }
            Attempt::Grow(isect) => {
                self.ensure(Need {
                    isect,
                    ..pending.need
                })?;
                self.retry = retry;
                Ok(None)
            }
            Attempt::Split(more) => {
                // Bands that only need longer lists get them now, not after another attempt.
                let fits = self.list_capacity();
                let longest = (statuses.iter())
                    .filter(|s| s[ST_OVERFLOW as usize] != 0)
                    .map(|s| s[ST_ISECT_NEEDED as usize])
                    .filter(|&n| n <= fits)
                    .max();
                if let Some(isect) = longest {
                    self.ensure(Need {
                        isect,
                        ..pending.need
                    })?;
                }
                self.list_bands = self.list_bands.max(more);
                self.retry = retry;
                Ok(None)
            }
        }
    }

    /// The rows of an attempt's bands (`rows`, with `statuses`) that overflowed, which an
    /// additive pass runs again: as they were for lists grown, or each split in enough bands
    /// that its pairs fit. `done`: intersections of bands earlier attempts ran.
    fn failed_rows(
        &self,
        cam: &Camera,
        rows: &[Range<u32>],
        done: u32,
        statuses: &[Vec<u32>],
        attempt: &Attempt,
    ) -> Result<Retry> {
        let fits = self.list_capacity();
        let step = row_step(cam.width, self.gpu.caps().min_storage_offset_alignment);
        let mut retry = Retry {
            cam: cam.clone(),
            rows: Vec::new(),
            intersections: done,
        };
        for (status, rows) in statuses.iter().zip(rows) {
            let wrapped = status[ST_ISECT_WRAPPED as usize] != 0;
            if !wrapped && status[ST_OVERFLOW as usize] == 0 {
                retry.intersections = retry
                    .intersections
                    .saturating_add(status[ST_ISECT as usize]);
                continue;
            }
            let needed = status[ST_ISECT_NEEDED as usize];
            // Only a band past one list splits; one that needs longer lists runs whole,
            // and grows them when no band is left to split.
            let pieces = match attempt {
                Attempt::Split(_) if wrapped => 4,
                Attempt::Split(_) if needed > fits => needed.div_ceil(fits) + 1,
                _ => 1,
            };
            let split = split_range(rows.clone(), pieces, step);
            ensure!(
                pieces == 1 || split.len() > 1,
                "view {}: tile rows {rows:?} alone cover {} (tile, Gaussian) pairs, more than one \
                 list holds within the binding limit ({fits} entries); render a smaller image or \
                 fewer (or smaller) Gaussians",
                cam.name,
                if wrapped {
                    "more than 2^32 - 1".to_string()
                } else {
                    needed.to_string()
                }
            );
            retry.rows.extend(split);
        }
        ensure!(
            retry.rows.len() <= MAX_LIST_BANDS as usize,
            "view {}: its lists need more than {MAX_LIST_BANDS} bands of tile rows",
            cam.name
        );
        Ok(retry)
    }

    /// Records the view's binning and `per_tile` band by band, and the copy of each band's
    /// status words for the host.
    fn record_bands<F>(
        &self,
        scene: &GpuScene,
        opts: &RenderOptions,
        frame: &FrameSpec,
        rows: &[Range<u32>],
        per_tile: &mut F,
    ) -> Result<(RecordedRun, Recorder)>
    where
        F: FnMut(&mut Recorder, &TileLists) -> Result<()>,
    {
        let b = self.bufs.as_ref().expect("ensured");
        let mut rec = Recorder::new(&self.gpu)?;
        let [m0, m1, m2] =
            self.record_project_and_sort(&mut rec, scene, frame, opts, rows.len())?;
        let mut marks = [m0, m1, m2, None, None];
        let mut spans = Vec::with_capacity(rows.len());
        for (band, band_rows) in rows.iter().enumerate() {
            let start = rec.mark();
            b.record_tile_lists(
                &mut rec,
                frame.tiles_x,
                frame.tiles_y,
                band as u32,
                band_rows,
            )?;
            let lists = rec.mark();
            marks[3] = marks[3].or(lists);
            let tiles = TileLists {
                bufs: b,
                band: band as u32,
                frame: FrameSpec {
                    rows: band_rows.clone(),
                    ..frame.clone()
                },
                marks,
            };
            per_tile(&mut rec, &tiles)?;
            rec.barrier(); // the next band reuses the lists
            spans.push((start, lists, rec.mark()));
        }
        marks[4] = spans.last().and_then(|s| s.2);
        let status_bytes = rows.len() as u64 * b.status_stride as u64 * 4;
        rec.copy(&b.status, 0, &b.status_host, 0, status_bytes);
        rec.host_barrier();
        let recorded = RecordedRun {
            marks,
            spans,
            channels: if frame.labels.is_some() {
                0
            } else {
                frame.channels
            },
        };
        Ok((recorded, rec))
    }

    /// What to do after a run whose bands reported `statuses`: done, grow the lists, or
    /// bin in more bands (a band's pairs past one binding, or past 2^32 - 1 where its
    /// 32-bit scan wrapped).
    fn next_attempt(
        &self,
        cam: &Camera,
        statuses: &[Vec<u32>],
        bands: u32,
        banded: bool,
    ) -> Result<Attempt> {
        let fits = self.list_capacity();
        let word = |s: &Vec<u32>, w: u32| s[w as usize];
        let wrapped = statuses.iter().any(|s| word(s, ST_ISECT_WRAPPED) != 0);
        let needed = statuses
            .iter()
            .filter(|s| word(s, ST_OVERFLOW) != 0)
            .map(|s| word(s, ST_ISECT_NEEDED))
            .max();
        let too_many = wrapped || needed.is_some_and(|n| n > fits);
        if too_many {
            let tiles_y = cam.height.div_ceil(TILE_SIZE);
            // Enough bands that an even split would fit, and at least twice as many.
            let wanted = needed.map_or(0, |n| (n as u64 * bands as u64).div_ceil(fits as u64));
            let step = row_step(cam.width, self.gpu.caps().min_storage_offset_alignment);
            let least = (wanted as u32 + 1).max(bands * 2);
            let more = more_bands(tiles_y, least, bands, step).unwrap_or(bands);
            ensure!(
                banded && more > bands,
                "view {}: {} visible Gaussians cover {} (tile, Gaussian) pairs at {}x{}, more \
                 than one list holds within the binding limit ({} entries){}; render a smaller \
                 image or fewer (or smaller) Gaussians",
                cam.name,
                word(&statuses[0], ST_VISIBLE),
                if wrapped {
                    "more than 2^32 - 1".to_string()
                } else {
                    needed.unwrap_or(0).to_string()
                },
                cam.width,
                cam.height,
                fits,
                if banded { " even per row of tiles" } else { "" }
            );
            return Ok(Attempt::Split(more));
        }
        Ok(match needed {
            Some(n) => Attempt::Grow(n),
            None => Attempt::Done,
        })
    }

    /// The frame every per-tile pass over `scene` seen by `cam` works on.
    fn frame_spec<'a>(
        &self,
        scene: &'a GpuScene,
        cam: &'a Camera,
        opts: &RenderOptions,
    ) -> Result<FrameSpec<'a>> {
        let labels = opts.semantics.and(scene.class_index.as_ref());
        let semantics = match opts.semantics {
            Some(mode) => scene.semantics(&self.gpu, mode)?.map(|buf| (mode, buf)),
            None => None,
        };
        Ok(FrameSpec {
            cam,
            tiles_x: cam.width.div_ceil(TILE_SIZE),
            tiles_y: cam.height.div_ceil(TILE_SIZE),
            window_len: self.window_len,
            windows: self.windows_for(scene.n),
            channels: if semantics.is_some() || labels.is_some() {
                scene.channels
            } else {
                0
            },
            semantics,
            labels,
            background: opts.background,
            band_limits: BandLimits {
                max_binding: self.gpu.caps().max_storage_buffer_range,
                offset_alignment: self.gpu.caps().min_storage_offset_alignment,
                tile_rows: self.band_rows,
            },
            rows: 0..cam.height.div_ceil(TILE_SIZE),
            gaussian_chunk: self.projection_chunk_len(scene)?,
        })
    }

    /// The buffer sizes a frame needs, with a first guess at its intersections (the GPU
    /// reports the real count and the buffers grow on overflow).
    fn need(&self, scene: &GpuScene, frame: &FrameSpec) -> Need {
        let pixels = frame.cam.width as u64 * frame.cam.height as u64;
        Need {
            n: scene.n,
            pixels,
            tiles: frame.tiles_x * frame.tiles_y,
            sem: if frame.labels.is_some() {
                0
            } else {
                pixels * frame.channels as u64
            },
            best: if frame.labels.is_some() { pixels } else { 0 },
            carry: (pixels * frame.blend_carry_floats()).max(1),
            window_args: window_args_bytes(frame),
            isect: self
                .bufs
                .as_ref()
                .map_or(0, |b| b.isect_cap)
                .max(scene.n.saturating_mul(4))
                .max(1 << 16)
                .min(self.list_capacity()),
        }
    }

    /// Renders several views of one scene, reusing the same buffers.
    pub fn render_batch(
        &mut self,
        scene: &GpuScene,
        cams: &[Camera],
        opts: &RenderOptions,
    ) -> Result<Vec<RenderedFrame>> {
        cams.iter()
            .map(|cam| self.render(scene, cam, opts))
            .collect()
    }

    /// The (tile id, Gaussian id) pairs of the last rendered frame, in list order (by tile,
    /// then depth). For tests and debugging: it downloads.
    pub fn last_intersections(&self) -> Result<Vec<(u32, u32)>> {
        let Some(b) = &self.bufs else {
            return Ok(Vec::new());
        };
        let status: Vec<u32> = self.gpu.download(&b.status, 0, ST_WORDS as usize)?;
        let count = status[ST_ISECT as usize] as usize;
        let keys: Vec<u32> = self.gpu.download(&b.isect_keys, 0, count)?;
        let ids: Vec<u32> = self.gpu.download(&b.isect_ids, 0, count)?;
        Ok(keys.into_iter().zip(ids).collect())
    }

    /// Per pixel of the last frame rendered from a scene uploaded with classes
    /// ([`GpuScene::upload_with_classes`]): the class index whose one-hot vectors blend to
    /// the largest share (later classes winning ties), None where no class shows.
    pub fn last_labels(&self, pixels: usize) -> Result<Vec<Option<u32>>> {
        let b = self.bufs.as_ref().expect("a frame was rendered");
        let best: Vec<[u32; 2]> = self.gpu.download(&b.label_best, 0, pixels)?;
        Ok(best
            .into_iter()
            .map(|[value, class]| (f32::from_bits(value) > 0.0).then_some(class))
            .collect())
    }

    /// The expected depth per pixel of the last rendered frame.
    ///
    /// # Panics
    /// Before the first frame.
    pub fn depth(&self) -> &Buffer {
        &self.bufs.as_ref().expect("a frame was rendered").depth
    }

    /// The median and opaque depths per pixel of the last frame recorded with
    /// [`TileLists::record_median_depth`].
    ///
    /// # Panics
    /// Before the first frame.
    pub fn occlusion_depths(&self) -> OcclusionDepths<'_> {
        let bufs = self.bufs.as_ref().expect("a frame was rendered");
        OcclusionDepths {
            median: &bufs.depth,
            opaque: &bufs.opaque_depth,
        }
    }

    /// The last frame's tile lists (its last band's, where it was binned in bands): each
    /// tile's (start, end) in them, and the Gaussian of each entry.
    ///
    /// # Panics
    /// Before the first frame.
    pub fn last_tile_lists(&self) -> (&Buffer, &Buffer) {
        let b = self.bufs.as_ref().expect("a frame was rendered");
        (&b.ranges, &b.isect_ids)
    }

    /// Per Gaussian of the last frame: 1 where it was projected into the view.
    pub fn last_visible_flags(&self, n: u32) -> Result<Vec<u32>> {
        let Some(b) = &self.bufs else {
            return Ok(vec![0; n as usize]);
        };
        Ok(self.gpu.download(&b.flags, 0, n as usize)?)
    }

    /// Records projection, compaction and the depth sort; returns the marks before and
    /// after each stage. Every band's status region starts zeroed, with the frame-wide
    /// words (visible count, dispatch sizes) copied from band 0's after compaction.
    fn record_project_and_sort(
        &self,
        rec: &mut Recorder,
        scene: &GpuScene,
        frame: &FrameSpec,
        opts: &RenderOptions,
        bands: usize,
    ) -> Result<[Option<Mark>; 3]> {
        let b = self.bufs.as_ref().expect("ensured");
        let stride = b.status_stride as u64 * 4;
        // One write of band 0's status (zeros and n + 1) beside one fill of the other
        // bands': overlapping writes would race without a barrier between them.
        let mut status = [0u32; ST_WORDS as usize];
        status[ST_N_PLUS1 as usize] = scene.n + 1;
        rec.update(&b.status, 0, bytemuck::cast_slice(&status));
        rec.fill(&b.status, stride, (bands as u64 - 1) * stride, 0);
        rec.fill(&b.ranges, 0, (frame.tiles_x * frame.tiles_y) as u64 * 8, 0);
        rec.barrier();
        let m0 = rec.mark();
        b.record_project(rec, scene, frame, opts, self.float64)?;
        for band in 1..bands as u64 {
            rec.copy(&b.status, 0, &b.status, band * stride, ST_WORDS as u64 * 4);
        }
        rec.barrier();
        let m1 = rec.mark();
        b.depth_sort.record(
            rec,
            &b.depth_keys,
            &b.depth_ids,
            GpuCount::at(&b.status, ST_VISIBLE),
            32,
        )?;
        let m2 = rec.mark();
        Ok([m0, m1, m2])
    }
}

impl Buffers {
    /// Projects every Gaussian, in chunks of `chunk_len` whose per-Gaussian ranges each fit
    /// one binding, then compacts the visible ones into depth keys (a scan of the
    /// visibility flags keeps their order deterministic).
    fn record_project(
        &self,
        rec: &mut Recorder,
        scene: &GpuScene,
        frame: &FrameSpec,
        opts: &RenderOptions,
        float64: bool,
    ) -> Result<()> {
        let (b, n, cam) = (self, scene.n, frame.cam);
        ensure!(
            scene.attributes >= SceneAttributes::Geometry,
            "rendering needs the scene's shapes and opacities; it was uploaded with {:?}",
            scene.attributes
        );
        // With float64, the camera-space and 2D means are computed from the camera in
        // double precision (float32 loses ~1e-5 px, which shows in alpha).
        let kernel = if float64 {
            let local = scene.local_camera(cam);
            let (r, t) = (local.rotation, local.translation);
            let camera64: Vec<f64> = (0..3)
                .flat_map(|k| {
                    let row = r.row(k);
                    [row.x, row.y, row.z, t[k]]
                })
                .chain([cam.fx, cam.fy, cam.cx, cam.cy])
                .collect();
            rec.update(&b.camera64, 0, bytemuck::cast_slice(&camera64));
            rec.barrier();
            ids::RASTER_PROJECT_F64
        } else {
            ids::RASTER_PROJECT
        };
        for (k, range) in chunks(n, frame.gaussian_chunk).enumerate() {
            if k > 0 {
                rec.barrier(); // this chunk's first flag overwrites the last one's tail zero
            }
            let mut params = project_params(cam, scene, opts.near, opts.far);
            params.n = range.len() as u32;
            let mut bindings = b.project_bindings(scene, &range);
            if float64 {
                bindings.push(("camera64", BufferRange::whole(&b.camera64)));
            }
            rec.dispatch_ranges(kernel, &bindings, &params, kernel.groups_for(params.n + 1))?;
        }
        rec.barrier();
        b.scan_n.record(
            rec,
            &b.flags,
            &b.visible_offsets,
            GpuCount::at(&b.status, ST_N_PLUS1),
        )?;
        rec.dispatch(
            ids::RASTER_COMPACT,
            &[("status", &b.status)],
            &CompactParams {
                visible_addr: b.flags.address_words(4)?,
                visible_offsets_addr: b.visible_offsets.address_words(4)?,
                xy_depth_opacity_addr: b.xy.address_words(16)?,
                depth_keys_addr: b.depth_keys.address_words(4)?,
                depth_ids_addr: b.depth_ids.address_words(4)?,
                n,
            },
            ids::RASTER_COMPACT.groups_for(n + 1),
        )?;
        rec.barrier();
        Ok(())
    }

    /// The projection's bindings for Gaussians `range`: each per-Gaussian buffer's part
    /// (the visibility flags one more, for the scan's trailing zero).
    fn project_bindings<'a>(
        &'a self,
        scene: &'a GpuScene,
        range: &Range<u32>,
    ) -> Vec<(&'static str, BufferRange<'a>)> {
        let part =
            |buf, stride: u64, extra: u32| part_of(buf, &(range.start..range.end + extra), stride);
        let mut bindings: Vec<(&str, BufferRange)> = ParamTensor::ALL
            .iter()
            .map(|&p| (p.name(), scene.param_range(p, range)))
            .collect();
        bindings.extend([
            ("xy_depth_opacity", part(&self.xy, 16, 0)),
            ("xy_frac", part(&self.xy_frac, 8, 0)),
            ("conics", part(&self.conic, 16, 0)),
            ("colors", part(&self.color, 16, 0)),
            ("tile_rects", part(&self.rect, 16, 0)),
            ("visible", part(&self.flags, 4, 1)),
        ]);
        bindings
    }

    /// From the depth-sorted visible Gaussians: (tile, Gaussian) pairs of the tile rows
    /// `rows` emitted in depth order, a stable sort on the tile id's bits, and each tile's
    /// range of the list. Band `band`'s status region counts them.
    fn record_tile_lists(
        &self,
        rec: &mut Recorder,
        tiles_x: u32,
        tiles_y: u32,
        band: u32,
        rows: &Range<u32>,
    ) -> Result<()> {
        let b = self;
        let base = band * b.status_stride;
        let status = BufferRange::new(&b.status, base as u64 * 4, ST_WORDS as u64 * 4);
        let whole = BufferRange::whole;
        let rows_params = (rows.start, rows.end);
        rec.dispatch_indirect_ranges(
            ids::RASTER_GATHER_TOUCHED,
            &[("status", status)],
            &GatherTouchedParams {
                tile_rects_addr: b.rect.address_words(16)?,
                depth_ids_addr: b.depth_ids.address_words(4)?,
                sorted_touched_addr: b.sorted_touched.address_words(4)?,
                row_begin: rows_params.0,
                row_end: rows_params.1,
            },
            &b.status,
            (base + ST_ARGS_VISIBLE) as u64 * 4,
        )?;
        rec.barrier();
        b.scan_v.record(
            rec,
            &b.sorted_touched,
            &b.isect_offsets,
            GpuCount::at(&b.status, base + ST_VISIBLE_PLUS1),
        )?;
        rec.dispatch_indirect_ranges(
            emit_kernel(rec.gpu(), tiles_x, rows),
            &[
                ("status", status),
                ("isect_keys", whole(&b.isect_keys)),
                ("isect_ids", whole(&b.isect_ids)),
            ],
            &EmitParams {
                tile_rects_addr: b.rect.address_words(16)?,
                depth_ids_addr: b.depth_ids.address_words(4)?,
                isect_offsets_addr: b.isect_offsets.address_words(4)?,
                tiles_x,
                capacity: b.isect_cap,
                row_begin: rows_params.0,
                row_end: rows_params.1,
            },
            &b.status,
            (base + ST_ARGS_VISIBLE) as u64 * 4,
        )?;
        rec.barrier();
        b.tile_sort.record(
            rec,
            &b.isect_keys,
            &b.isect_ids,
            GpuCount::at(&b.status, base + ST_ISECT),
            tile_bits(tiles_x * tiles_y),
        )?;
        rec.dispatch_indirect_ranges(
            ids::RASTER_TILE_RANGES,
            &[
                ("status", status),
                ("isect_keys", whole(&b.isect_keys)),
                ("tile_ranges", whole(&b.ranges)),
            ],
            &(),
            &b.status,
            (base + ST_ARGS_ISECT) as u64 * 4,
        )?;
        rec.barrier();
        Ok(())
    }
}

/// What every per-tile pass of one binned view works on, fixed when the view is binned:
/// passes read it from [`TileLists::frame`] instead of each caller supplying it again.
#[derive(Clone)]
pub struct FrameSpec<'a> {
    pub cam: &'a Camera,
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Entries of a tile's list one dispatch walks. On a device with a loop cap the lists
    /// are walked in windows with per-pixel state carried between dispatches, so no
    /// invocation reaches the cap.
    pub window_len: u32,
    /// Windows that cover the longest possible tile list (one entry per Gaussian).
    pub windows: u32,
    /// Semantic channels blended (0: RGB only).
    pub channels: u32,
    /// What the semantic channels blend, and the per-Gaussian vectors (None: RGB only).
    pub semantics: Option<(SemanticMode, &'a Buffer)>,
    /// Per Gaussian class indices whose one-hot vectors blend into a per-pixel argmax
    /// instead of semantic channels (a scene uploaded with classes; `channels` classes).
    pub labels: Option<&'a Buffer>,
    pub background: [f32; 3],
    /// What sizes the bands of tile rows per-tile passes split the image into.
    pub band_limits: BandLimits,
    /// The tile rows these lists hold: all of them, or one band of a view binned in bands
    /// ([`Rasterizer::run_tiled_in_bands`]); per-tile passes cover only these.
    pub rows: Range<u32>,
    /// Gaussians one per-Gaussian dispatch (the projection, its backward) covers, so each
    /// per-Gaussian range it binds fits one binding.
    pub gaussian_chunk: u32,
}

impl FrameSpec<'_> {
    /// Each window's number and first list entry, in walking order (front to back).
    pub fn window_starts(&self) -> impl DoubleEndedIterator<Item = (u32, u32)> + '_ {
        // windows = ceil(n / window_len), so every start is below n: no u32 overflow.
        (0..self.windows).map(|w| (w, w * self.window_len))
    }

    /// Dispatches that cover the semantic channels, SEM_CHUNK at a time (1 for RGB only).
    pub fn sem_chunks(&self) -> u32 {
        self.channels.div_ceil(SEM_CHUNK).max(1)
    }

    /// Floats of state blending carries per pixel between windows (0 with one window).
    pub fn blend_carry_floats(&self) -> u64 {
        let chunk = if self.channels > 0 { SEM_CHUNK } else { 0 };
        if self.windows > 1 {
            (BLEND_CARRY_BASE + chunk) as u64
        } else {
            0
        }
    }

    /// Bands of tile rows such that a per-pixel buffer of `bytes_per_pixel` fits one
    /// binding per band (one band but for very large images or many classes).
    pub fn bands(&self, bytes_per_pixel: u64) -> Result<Vec<Band>> {
        let (w, h) = (self.cam.width, self.cam.height);
        bands(w, h, self.rows.clone(), bytes_per_pixel, self.band_limits)
    }

    /// One workgroup per tile.
    pub fn tile_groups(&self) -> [u32; 3] {
        [self.tiles_x, self.tiles_y, 1]
    }
}

/// A binned view: the tile lists and per-Gaussian screen data a per-tile stage reads.
pub struct TileLists<'a> {
    bufs: &'a Buffers,
    /// Which band of tile rows of the view these lists hold (0 when binned whole).
    band: u32,
    pub frame: FrameSpec<'a>,
    /// Marks around the stages (project, depth sort, bin, per-tile stage).
    pub marks: [Option<Mark>; 5],
}

/// Timings and counts of one [`Rasterizer::run_tiled`].
pub struct TiledRun {
    pub timings: Timings,
    /// Marks around the stages (project, depth sort, bin, per-tile stage, end); with bands
    /// of rows, bin and per-tile are the first band's.
    pub marks: [Option<Mark>; 5],
    /// GPU time per stage, every band's summed.
    pub stages: StageTimes,
    /// Bands of tile rows the view was binned in (1: all at once).
    pub list_bands: u32,
    pub visible: u32,
    pub intersections: u32,
    /// Semantic channels the per-tile stage saw in the frame.
    pub channels: u32,
}

impl TileLists<'_> {
    /// How a pass over `bands` of these lists dispatches each window: records the later
    /// windows' indirect arguments ([`PassWindows`]) where the frame has several.
    pub fn pass_windows(&self, rec: &mut Recorder, bands: &[Band]) -> Result<PassWindows<'_>> {
        PassWindows::record(
            rec,
            &self.frame,
            bands,
            &self.bufs.ranges,
            &self.bufs.window_args,
        )
    }

    /// Which band of tile rows of the view these lists hold (0 when binned whole, and for
    /// the first band).
    pub fn band(&self) -> u32 {
        self.band
    }

    /// The status words (ST_*) of these lists' binning. Its intersection lists overflowed
    /// where `ST_OVERFLOW` is set: the view is recorded again with larger lists (or in
    /// more bands), so a pass that accumulates across views must add nothing then.
    pub fn status(&self) -> BufferRange<'_> {
        let b = self.bufs;
        let offset = (self.band * b.status_stride) as u64 * 4;
        BufferRange::new(&b.status, offset, ST_WORDS as u64 * 4)
    }

    /// Whether these lists hold the view's last band of tile rows (or the whole view).
    pub fn is_last_band(&self) -> bool {
        self.frame.rows.end >= self.frame.tiles_y
    }

    /// Start and end of each tile's run in the sorted lists (uvec2 per tile).
    pub fn ranges(&self) -> &Buffer {
        &self.bufs.ranges
    }

    /// Gaussian id of each list entry, tile-sorted, depth order within a tile.
    pub fn isect_ids(&self) -> &Buffer {
        &self.bufs.isect_ids
    }

    /// Expected depth per pixel, written by [`Self::record_blend`].
    pub fn depth(&self) -> &Buffer {
        &self.bufs.depth
    }

    /// The per-pixel depths [`Self::record_median_depth`] writes.
    pub fn occlusion_depths(&self) -> OcclusionDepths<'_> {
        OcclusionDepths {
            median: &self.bufs.depth,
            opaque: &self.bufs.opaque_depth,
        }
    }

    /// Per Gaussian: 1 where this view projected it (its tile lists may hold it).
    pub fn visible_flags(&self) -> &Buffer {
        &self.bufs.flags
    }

    /// Per pixel, written by [`Self::record_blend`]: rgb (3 floats, background included).
    pub fn rgb(&self) -> &Buffer {
        &self.bufs.rgb
    }

    /// Per pixel: transmittance after the last blended Gaussian.
    pub fn final_t(&self) -> &Buffer {
        &self.bufs.final_t
    }

    /// Per pixel: list entry (absolute) of the last blended Gaussian.
    pub fn last_entry(&self) -> &Buffer {
        &self.bufs.last
    }

    /// Per pixel: how many Gaussians were blended.
    pub fn n_contrib(&self) -> &Buffer {
        &self.bufs.n_contrib
    }

    /// Per pixel: the C normalized semantic channels (Gaussian Semantics Eq. 2).
    pub fn sem_norm(&self) -> &Buffer {
        &self.bufs.sem_norm
    }

    /// Addresses of the projected per-Gaussian arrays, for the kernels that read them at
    /// the Gaussians of the tile lists (addressed_arrays.glsl).
    pub fn projected_addrs(&self) -> Result<ProjectedAddrs> {
        let b = self.bufs;
        Ok(ProjectedAddrs {
            xy_depth_opacity: b.xy.address_words(16)?,
            xy_frac: b.xy_frac.address_words(8)?,
            conics: b.conic.address_words(16)?,
            colors: b.color.address_words(16)?,
        })
    }

    /// Push constants of a blend or blend-backward dispatch over the window at `start`
    /// and semantic chunk `chunk` (`write_rgb`: the forward chunk that writes RGB), with
    /// the addresses of the per-Gaussian arrays it reads: the projected attributes and the
    /// frame's semantic vectors (or its classes when rendering labels). The backward adds
    /// its gradient sums' addresses.
    pub fn blend_params(&self, start: u32, chunk: u32, write_rgb: bool) -> Result<BlendParams> {
        let f = &self.frame;
        let projected = self.projected_addrs()?;
        let sem_in = match (f.labels, f.semantics) {
            (Some(classes), _) => classes.address_words(4)?,
            (None, Some((_, sem))) => sem.address_words(4)?,
            // Never read: the kernel blends no channels.
            (None, None) => [0; 2],
        };
        Ok(BlendParams {
            width: f.cam.width,
            height: f.cam.height,
            tiles_x: f.tiles_x,
            channels: f.channels,
            window_start: start,
            window_len: f.window_len,
            chunk_base: chunk * SEM_CHUNK,
            write_rgb: u32::from(write_rgb),
            background: f.background,
            tile_row_base: 0,
            xy_depth_opacity_addr: projected.xy_depth_opacity,
            xy_frac_addr: projected.xy_frac,
            conics_addr: projected.conics,
            colors_addr: projected.colors,
            sem_in_addr: sem_in,
            grad2d_addr: [0; 2],
            grad_sem_addr: [0; 2],
        })
    }

    /// Records forward blending of the frame into the rasterizer's output images, band by
    /// band where the image's per-pixel buffers pass one binding.
    pub fn record_blend(&self, rec: &mut Recorder) -> Result<()> {
        let (b, f) = (self.bufs, &self.frame);
        let carry_bytes = f.blend_carry_floats() * 4;
        let sem_bytes = if f.labels.is_some() {
            8
        } else {
            f.channels as u64 * 4
        };
        let widest = [RGB_BYTES, sem_bytes, carry_bytes]
            .into_iter()
            .max()
            .unwrap_or(4);
        let bands = f.bands(widest)?;
        let windows = self.pass_windows(rec, &bands)?;
        for chunk in 0..f.sem_chunks() {
            for (window, start) in f.window_starts() {
                for (band_index, band) in bands.iter().enumerate() {
                    let mut params = self.blend_params(start, chunk, chunk == 0)?;
                    params.tile_row_base = band.first_tile_row;
                    let px = |buf, bytes| band.range(buf, bytes);
                    let mut bindings = self.window_bindings(band, carry_bytes);
                    bindings.extend([
                        ("out_rgb", px(&b.rgb, RGB_BYTES)),
                        ("out_alpha", px(&b.alpha, 4)),
                        ("out_depth", px(&b.depth, 4)),
                        ("out_final_t", px(&b.final_t, 4)),
                        ("out_last", px(&b.last, 4)),
                        ("out_n_contrib", px(&b.n_contrib, 4)),
                    ]);
                    let (narrow, wide) = match (f.labels, f.semantics) {
                        (Some(_), _) => {
                            bindings.push(("label_best", px(&b.label_best, 8)));
                            (ids::RASTER_BLEND_LABEL, ids::RASTER_BLEND_LABEL_WIDE)
                        }
                        (None, Some(_)) => {
                            bindings.extend([
                                ("out_sem", px(&b.sem, sem_bytes)),
                                ("out_sem_norm", px(&b.sem_norm, sem_bytes)),
                            ]);
                            (ids::RASTER_BLEND_SEM, ids::RASTER_BLEND_SEM_WIDE)
                        }
                        (None, None) => (ids::RASTER_BLEND_RGB, ids::RASTER_BLEND_RGB_WIDE),
                    };
                    let kernel = narrow.for_device(wide, rec.gpu());
                    windows.dispatch(rec, kernel, &bindings, &params, (window, band_index))?;
                }
                rec.barrier();
            }
        }
        Ok(())
    }

    /// Records each pixel's median depth into the depth image (the depth of the Gaussian
    /// that takes its transmittance below one half; 0 where none does) and its opaque depth
    /// (below `OPAQUE_T`; [`Self::occlusion_depths`]) and nothing else: a pixel stops there,
    /// not at saturation. For occlusion tests, which need only the nearest surface
    /// (src/fuse/consensus.rs).
    pub fn record_median_depth(&self, rec: &mut Recorder) -> Result<()> {
        let f = &self.frame;
        // The kernel carries no semantic channels, whatever the frame blends.
        let carry_bytes = f.blend_carry_floats().min(BLEND_CARRY_BASE as u64) * 4;
        let bands = f.bands(carry_bytes.max(4))?;
        let windows = self.pass_windows(rec, &bands)?;
        for (window, start) in f.window_starts() {
            for (band_index, band) in bands.iter().enumerate() {
                let mut params = self.blend_params(start, 0, false)?;
                params.tile_row_base = band.first_tile_row;
                let mut bindings = self.window_bindings(band, carry_bytes);
                bindings.push(("out_depth", band.range(&self.bufs.depth, 4)));
                bindings.push(("out_opaque_depth", band.range(&self.bufs.opaque_depth, 4)));
                let kernel = ids::RASTER_BLEND_MEDIAN_DEPTH
                    .for_device(ids::RASTER_BLEND_MEDIAN_DEPTH_WIDE, rec.gpu());
                windows.dispatch(rec, kernel, &bindings, &params, (window, band_index))?;
            }
            rec.barrier();
        }
        Ok(())
    }

    /// The bindings every forward-blending window reads and carries its state in.
    fn window_bindings<'b>(
        &'b self,
        band: &Band,
        carry_bytes: u64,
    ) -> Vec<(&'static str, BufferRange<'b>)> {
        let b = self.bufs;
        vec![
            ("tile_ranges", BufferRange::whole(&b.ranges)),
            ("isect_ids", BufferRange::whole(&b.isect_ids)),
            ("carry", band.range_or_whole(&b.carry, carry_bytes)),
        ]
    }
}

/// Per pixel, the depths the occlusion tests of Gaussian centers read: the median depth
/// (of the Gaussian that takes the transmittance below `MEDIAN_T`) and the opaque depth
/// (below `OPAQUE_T`), each 0 where the transmittance never falls that far.
#[derive(Clone, Copy)]
pub struct OcclusionDepths<'a> {
    pub median: &'a Buffer,
    pub opaque: &'a Buffer,
}

/// Device addresses of the projected per-Gaussian arrays ([`TileLists::projected_addrs`]).
pub struct ProjectedAddrs {
    /// Per Gaussian: (floor(mean2d) x, y, depth, opacity).
    pub xy_depth_opacity: [u32; 2],
    /// Per Gaussian: the fraction of the 2D mean, mean2d - floor(mean2d).
    pub xy_frac: [u32; 2],
    /// Per Gaussian: (conic A, B, C, -).
    pub conics: [u32; 2],
    /// Per Gaussian: view-dependent color (r, g, b, -).
    pub colors: [u32; 2],
}

/// Bytes of a pixel's RGB.
pub(crate) const RGB_BYTES: u64 = 12;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn more_bands_asks_for_a_count_that_gives_more_bands() {
        // Ten tile rows whose bands start at multiples of 4 rows: 3 bands at most.
        assert_eq!(split_rows(10, 6, 4).len(), 3);
        // From 2 bands, asking for 4 gives 3: more.
        assert_eq!(more_bands(10, 4, 2, 4), Some(4));
        assert_eq!(split_rows(10, 4, 4).len(), 3);
        // From 3, no count gives more (asking for 6 again gave 3 again, for ever).
        assert_eq!(more_bands(10, 6, 3, 4), None);
        // With a step of one row, the count asked for is the bands it gives.
        assert_eq!(more_bands(10, 4, 2, 1), Some(4));
        // Never more than one band a tile row.
        assert_eq!(more_bands(3, 4, 2, 1), Some(3));
        assert_eq!(more_bands(3, 6, 3, 1), None);
    }

    #[test]
    fn split_range_covers_its_rows_once_from_multiples_of_the_step() {
        for (rows, bands, step) in [(0..10, 3, 1), (4..17, 4, 4), (8..9, 5, 2), (0..1, 1, 1)] {
            let split = split_range(rows.clone(), bands, step);
            assert!(split.len() as u32 <= bands.max(1));
            let covered: Vec<u32> = split.iter().flat_map(|r| r.clone()).collect();
            assert_eq!(covered, rows.clone().collect::<Vec<_>>());
            assert!(split.iter().all(|r| (r.start - rows.start) % step == 0));
        }
    }
}
