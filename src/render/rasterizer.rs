//! The GPU forward rasterizer: project, compact, depth sort, emit tile intersections,
//! stable sort by tile id on only the bits needed, tile ranges, blend. Counts stay on the
//! GPU (indirect dispatch); the only host read is after the frame, to fetch the images and
//! the overflow flag that tells the buffers to grow.

use anyhow::{ensure, Result};
use bytemuck::{Pod, Zeroable};

use super::frame::RenderedFrame;
use super::gpu_scene::GpuScene;
use super::{RenderOptions, StageTimes};
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, GpuCount, Mark, PrefixScan, RadixSort, Recorder, Timings};
use crate::scene::Camera;

/// Tile edge in pixels (glsl/common/raster_common.glsl: TILE_SIZE).
pub const TILE_SIZE: u32 = 16;
/// Frame status words (ST_*).
const ST_VISIBLE: u32 = 0;
const ST_VISIBLE_PLUS1: u32 = 1;
const ST_ISECT: u32 = 2;
const ST_ISECT_NEEDED: u32 = 3;
const ST_OVERFLOW: u32 = 4;
const ST_N_PLUS1: u32 = 5;
const ST_ARGS_VISIBLE: u64 = 8;
const ST_ARGS_ISECT: u64 = 12;
const ST_WORDS: u64 = 16;
/// Semantic channels per blend dispatch (blend_sem.comp: SEM_CHUNK).
pub const SEM_CHUNK: u32 = 16;
/// Entries of a tile's list one blend dispatch walks on devices with a loop cap
/// (lavapipe stops every invocation after 65,535 loop iterations).
const CAPPED_WINDOW: u32 = 32_768;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ProjectParams {
    rot_t: [[f32; 4]; 3],
    intrinsics: [f32; 4],
    center_near: [f32; 4],
    far_pad: [f32; 4],
    dims: [u32; 4],
    counts: [u32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct BlendParams {
    dims: [u32; 4],
    window: [u32; 4],
    background: [f32; 4],
}

/// Buffers sized for the largest scene, image and intersection count seen so far.
struct Buffers {
    n_cap: u32,
    pixel_cap: u64,
    sem_cap: u64,
    carry_cap: u64,
    tiles_cap: u32,
    isect_cap: u32,
    xy: Buffer,
    conic: Buffer,
    color: Buffer,
    rect: Buffer,
    flags: Buffer,
    visible_offsets: Buffer,
    touched: Buffer,
    depth_keys: Buffer,
    depth_ids: Buffer,
    sorted_touched: Buffer,
    isect_offsets: Buffer,
    isect_keys: Buffer,
    isect_ids: Buffer,
    ranges: Buffer,
    carry: Buffer,
    rgb: Buffer,
    alpha: Buffer,
    depth: Buffer,
    final_t: Buffer,
    last: Buffer,
    n_contrib: Buffer,
    sem: Buffer,
    sem_norm: Buffer,
    status: Buffer,
    scan_n: PrefixScan,
    scan_v: PrefixScan,
    depth_sort: RadixSort,
    tile_sort: RadixSort,
}

/// Renders scenes on the GPU; reuses its buffers across frames and grows them on demand.
pub struct Rasterizer {
    gpu: Gpu,
    bufs: Option<Buffers>,
    window_len: u32,
}

/// Sizes a frame needs.
#[derive(Clone, Copy)]
struct Need {
    n: u32,
    pixels: u64,
    tiles: u32,
    sem: u64,
    carry: u64,
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
        Ok(Buffers {
            n_cap: n as u32,
            pixel_cap: p,
            sem_cap: need.sem,
            carry_cap: need.carry,
            tiles_cap: need.tiles,
            isect_cap: isect as u32,
            xy: b("xy_depth_opacity", n * 16)?,
            conic: b("conics", n * 16)?,
            color: b("colors", n * 16)?,
            rect: b("tile_rects", n * 16)?,
            flags: b("visible", (n + 1) * 4)?,
            visible_offsets: b("visible_offsets", (n + 1) * 4)?,
            touched: b("tiles_touched", n * 4)?,
            depth_keys: b("depth_keys", n * 4)?,
            depth_ids: b("depth_ids", n * 4)?,
            sorted_touched: b("sorted_touched", (n + 1) * 4)?,
            isect_offsets: b("isect_offsets", (n + 1) * 4)?,
            isect_keys: b("isect_keys", isect * 4)?,
            isect_ids: b("isect_ids", isect * 4)?,
            ranges: b("tile_ranges", need.tiles as u64 * 8)?,
            carry: b("carry", need.carry * 4)?,
            rgb: b("rgb", p * 12)?,
            alpha: b("alpha", p * 4)?,
            depth: b("depth", p * 4)?,
            final_t: b("final_t", p * 4)?,
            last: b("last", p * 4)?,
            n_contrib: b("n_contrib", p * 4)?,
            sem: b("sem", need.sem * 4)?,
            sem_norm: b("sem_norm", need.sem * 4)?,
            status: b("status", ST_WORDS * 4)?,
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
            && need.carry <= self.carry_cap
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
        let capped = gpu.caps().driver_name.to_lowercase().contains("llvmpipe");
        Rasterizer {
            gpu: gpu.clone(),
            bufs: None,
            window_len: if capped { CAPPED_WINDOW } else { u32::MAX / 2 },
        }
    }

    /// Overrides how many entries of a tile's list one blend dispatch walks (tests use a
    /// small window to exercise the carried state on small scenes).
    pub fn set_window_len(&mut self, len: u32) {
        self.window_len = len.max(1);
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
                    carry: grow(b.carry_cap, need.carry),
                    isect: grow(b.isect_cap as u64, need.isect as u64).min(u32::MAX as u64) as u32,
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
        ensure!(
            cam.width > 0 && cam.height > 0,
            "camera {} has an empty image",
            cam.name
        );
        let tiles_x = cam.width.div_ceil(TILE_SIZE);
        let tiles_y = cam.height.div_ceil(TILE_SIZE);
        let sem_buf = match opts.semantics {
            Some(mode) => scene.semantics(&self.gpu, mode)?,
            None => None,
        };
        let channels = if sem_buf.is_some() { scene.channels } else { 0 };
        let pixels = cam.width as u64 * cam.height as u64;
        let windows = scene.n.div_ceil(self.window_len).max(1);
        let carry_stride = 8 + if channels > 0 { SEM_CHUNK } else { 0 } as u64;
        let mut need = Need {
            n: scene.n,
            pixels,
            tiles: tiles_x * tiles_y,
            sem: pixels * channels as u64,
            carry: if windows > 1 {
                pixels * carry_stride
            } else {
                1
            },
            // A first guess; the GPU reports the real count and we grow on overflow.
            isect: self
                .bufs
                .as_ref()
                .map_or(0, |b| b.isect_cap)
                .max(scene.n.saturating_mul(4))
                .max(1 << 16),
        };
        loop {
            self.ensure(need)?;
            let (timings, marks) =
                self.record_and_run(scene, cam, opts, sem_buf, channels, windows)?;
            let bufs = self.bufs.as_ref().expect("ensured");
            let status: Vec<u32> = self.gpu.download(&bufs.status, 0, ST_WORDS as usize)?;
            if status[ST_OVERFLOW as usize] != 0 {
                need.isect = status[ST_ISECT_NEEDED as usize];
                continue;
            }
            let stages = StageTimes::from_marks(&timings, &marks);
            return RenderedFrame::download(
                &self.gpu,
                cam,
                channels,
                [
                    &bufs.rgb,
                    &bufs.alpha,
                    &bufs.depth,
                    &bufs.final_t,
                    &bufs.last,
                    &bufs.n_contrib,
                    &bufs.sem,
                    &bufs.sem_norm,
                ],
                status[ST_VISIBLE as usize],
                status[ST_ISECT as usize],
                stages,
            );
        }
    }

    fn record_and_run(
        &self,
        scene: &GpuScene,
        cam: &Camera,
        opts: &RenderOptions,
        sem_buf: Option<&Buffer>,
        channels: u32,
        windows: u32,
    ) -> Result<(Timings, [Option<Mark>; 5])> {
        let b = self.bufs.as_ref().expect("ensured");
        let n = scene.n;
        let tiles_x = cam.width.div_ceil(TILE_SIZE);
        let tiles_y = cam.height.div_ceil(TILE_SIZE);
        let mut rec = Recorder::new(&self.gpu)?;
        rec.fill(&b.status, 0, ST_WORDS * 4, 0);
        rec.fill(&b.status, ST_N_PLUS1 as u64 * 4, 4, n + 1);
        rec.fill(&b.ranges, 0, (tiles_x * tiles_y) as u64 * 8, 0);
        rec.barrier();
        let m0 = rec.mark();

        let r = cam.rotation;
        let t = cam.translation;
        let c = cam.center();
        let params = ProjectParams {
            rot_t: [
                [
                    r.x_axis.x as f32,
                    r.y_axis.x as f32,
                    r.z_axis.x as f32,
                    t.x as f32,
                ],
                [
                    r.x_axis.y as f32,
                    r.y_axis.y as f32,
                    r.z_axis.y as f32,
                    t.y as f32,
                ],
                [
                    r.x_axis.z as f32,
                    r.y_axis.z as f32,
                    r.z_axis.z as f32,
                    t.z as f32,
                ],
            ],
            intrinsics: [cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32],
            center_near: [c.x as f32, c.y as f32, c.z as f32, opts.near],
            far_pad: [opts.far, 0.0, 0.0, 0.0],
            dims: [cam.width, cam.height, tiles_x, tiles_y],
            counts: [n, scene.sh_degree, scene.sh_coeffs, 0],
        };
        rec.dispatch(
            ids::RASTER_PROJECT,
            &[
                ("means", &scene.means),
                ("log_scales", &scene.log_scales),
                ("quats", &scene.quats),
                ("opacity_logits", &scene.opacity_logits),
                ("sh", &scene.sh),
                ("xy_depth_opacity", &b.xy),
                ("conics", &b.conic),
                ("colors", &b.color),
                ("tile_rects", &b.rect),
                ("visible", &b.flags),
                ("tiles_touched", &b.touched),
            ],
            bytemuck::bytes_of(&params),
            [(n + 1).div_ceil(256), 1, 1],
        )?;
        rec.barrier();
        b.scan_n.record(
            &mut rec,
            &b.flags,
            &b.visible_offsets,
            GpuCount::at(&b.status, ST_N_PLUS1),
        )?;
        rec.dispatch(
            ids::RASTER_COMPACT,
            &[
                ("visible", &b.flags),
                ("visible_offsets", &b.visible_offsets),
                ("xy_depth_opacity", &b.xy),
                ("depth_keys", &b.depth_keys),
                ("depth_ids", &b.depth_ids),
                ("status", &b.status),
            ],
            bytemuck::bytes_of(&n),
            [(n + 1).div_ceil(256), 1, 1],
        )?;
        rec.barrier();
        let m1 = rec.mark();

        b.depth_sort.record(
            &mut rec,
            &b.depth_keys,
            &b.depth_ids,
            GpuCount::at(&b.status, ST_VISIBLE),
            32,
        )?;
        let m2 = rec.mark();

        rec.dispatch_indirect(
            ids::RASTER_GATHER_TOUCHED,
            &[
                ("status", &b.status),
                ("depth_ids", &b.depth_ids),
                ("tiles_touched", &b.touched),
                ("sorted_touched", &b.sorted_touched),
            ],
            &[],
            &b.status,
            ST_ARGS_VISIBLE * 4,
        )?;
        rec.barrier();
        b.scan_v.record(
            &mut rec,
            &b.sorted_touched,
            &b.isect_offsets,
            GpuCount::at(&b.status, ST_VISIBLE_PLUS1),
        )?;
        rec.dispatch_indirect(
            ids::RASTER_EMIT,
            &[
                ("status", &b.status),
                ("depth_ids", &b.depth_ids),
                ("isect_offsets", &b.isect_offsets),
                ("tile_rects", &b.rect),
                ("isect_keys", &b.isect_keys),
                ("isect_ids", &b.isect_ids),
            ],
            bytemuck::cast_slice(&[tiles_x, b.isect_cap]),
            &b.status,
            ST_ARGS_VISIBLE * 4,
        )?;
        rec.barrier();
        b.tile_sort.record(
            &mut rec,
            &b.isect_keys,
            &b.isect_ids,
            GpuCount::at(&b.status, ST_ISECT),
            tile_bits(tiles_x * tiles_y),
        )?;
        rec.dispatch_indirect(
            ids::RASTER_TILE_RANGES,
            &[
                ("status", &b.status),
                ("isect_keys", &b.isect_keys),
                ("tile_ranges", &b.ranges),
            ],
            &[],
            &b.status,
            ST_ARGS_ISECT * 4,
        )?;
        rec.barrier();
        let m3 = rec.mark();

        let bg = opts.background;
        let chunks = if channels > 0 {
            channels.div_ceil(SEM_CHUNK)
        } else {
            1
        };
        for chunk in 0..chunks {
            for w in 0..windows {
                let params = BlendParams {
                    dims: [cam.width, cam.height, tiles_x, channels],
                    window: [
                        w * self.window_len,
                        self.window_len,
                        chunk * SEM_CHUNK,
                        u32::from(chunk == 0),
                    ],
                    background: [bg[0], bg[1], bg[2], 0.0],
                };
                let mut bindings: Vec<(&str, &Buffer)> = vec![
                    ("tile_ranges", &b.ranges),
                    ("isect_ids", &b.isect_ids),
                    ("xy_depth_opacity", &b.xy),
                    ("conics", &b.conic),
                    ("colors", &b.color),
                    ("carry", &b.carry),
                    ("out_rgb", &b.rgb),
                    ("out_alpha", &b.alpha),
                    ("out_depth", &b.depth),
                    ("out_final_t", &b.final_t),
                    ("out_last", &b.last),
                    ("out_n_contrib", &b.n_contrib),
                ];
                let kernel = match sem_buf {
                    Some(sem) => {
                        bindings.extend([
                            ("sem_in", sem),
                            ("out_sem", &b.sem),
                            ("out_sem_norm", &b.sem_norm),
                        ]);
                        ids::RASTER_BLEND_SEM
                    }
                    None => ids::RASTER_BLEND_RGB,
                };
                rec.dispatch(
                    kernel,
                    &bindings,
                    bytemuck::bytes_of(&params),
                    [tiles_x, tiles_y, 1],
                )?;
                rec.barrier();
            }
        }
        let m4 = rec.mark();
        let timings = rec.submit_and_wait()?;
        Ok((timings, [m0, m1, m2, m3, m4]))
    }
}
