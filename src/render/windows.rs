//! The windows of a per-tile pass. A device with a loop cap walks each tile's list in
//! windows of `window_len` entries, one dispatch a window with the pixels' state carried
//! between them, and the host records as many windows as the longest list the scene could
//! make (every Gaussian in one tile: 7 at 210k Gaussians, 31 at 1M), before it knows the
//! lists. The first window is dispatched directly (it writes every pixel, the background
//! too); the later ones take indirect arguments that glsl/raster/window_args.comp writes
//! from the lists, so a window that starts past every list of a band launches no
//! workgroups. (On lavapipe each launched workgroup costs its start even where it returns at
//! once: at 1M Gaussians the empty windows took half a frame's blending.) A device without a
//! loop cap has one window, and nothing here records anything.

use anyhow::Result;

use super::chunks::Band;
use super::rasterizer::FrameSpec;
use crate::contract::params::WindowArgsParams;
use crate::gpu::kernel_table::ids;
use crate::gpu::kernel_table::Kernel;
use crate::gpu::{Buffer, BufferRange, Recorder};

/// Bytes of one window's indirect arguments for one band: (x, y, z) workgroups.
const ARGS_BYTES: u64 = 12;

/// Bytes of indirect arguments a frame's passes may need: one set per later window and
/// band of tile rows (a pass has at most one band a tile row).
pub(crate) fn window_args_bytes(frame: &FrameSpec) -> u64 {
    (frame.windows.saturating_sub(1) as u64 * frame.tiles_y as u64 * ARGS_BYTES).max(ARGS_BYTES)
}

/// How one pass over a frame's bands dispatches each window ([`PassWindows::dispatch`]).
pub struct PassWindows<'a> {
    /// The later windows' arguments, band-minor; None where the frame has one window.
    args: Option<&'a Buffer>,
    /// Each band's workgroups (one a tile), the first window's.
    band_groups: Vec<[u32; 3]>,
}

impl<'a> PassWindows<'a> {
    /// Records window_args.comp for a pass over `bands` (the frame's rows in bands of
    /// equal height but the last, as `FrameSpec::bands` gives them) of the lists whose
    /// ranges are `ranges`, writing into `args`, and the barrier before its use.
    pub(crate) fn record(
        rec: &mut Recorder,
        frame: &FrameSpec,
        bands: &[Band],
        ranges: &Buffer,
        args: &'a Buffer,
    ) -> Result<PassWindows<'a>> {
        let mut windows = PassWindows {
            args: None,
            band_groups: bands.iter().map(|b| b.groups(frame.tiles_x)).collect(),
        };
        if frame.windows <= 1 || bands.is_empty() {
            return Ok(windows);
        }
        let params = WindowArgsParams {
            tiles_x: frame.tiles_x,
            first_row: frame.rows.start,
            rows: frame.rows.len() as u32,
            band_rows: bands[0].tile_rows,
            window_len: frame.window_len,
            windows: frame.windows,
        };
        rec.dispatch(
            ids::RASTER_WINDOW_ARGS,
            &[("tile_ranges", ranges), ("args", args)],
            &params,
            [bands.len() as u32, 1, 1],
        )?;
        rec.barrier();
        windows.args = Some(args);
        Ok(windows)
    }

    /// Records `kernel` over the tiles of band `band` (an index into the pass's bands) for
    /// window `window` (0: the first, dispatched directly).
    pub fn dispatch<P: bytemuck::Pod>(
        &self,
        rec: &mut Recorder,
        kernel: Kernel<P>,
        bindings: &[(&str, BufferRange)],
        params: &P,
        (window, band): (u32, usize),
    ) -> Result<()> {
        match self.args {
            Some(args) if window > 0 => {
                let bands = self.band_groups.len() as u64;
                let entry = (window as u64 - 1) * bands + band as u64;
                rec.dispatch_indirect_ranges(kernel, bindings, params, args, entry * ARGS_BYTES)?
            }
            _ => rec.dispatch_ranges(kernel, bindings, params, self.band_groups[band])?,
        }
        Ok(())
    }
}
