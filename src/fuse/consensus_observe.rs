//! Segment consensus's observation pass (src/fuse/consensus.rs): per view, the pixel under
//! every Gaussian's visible center (rendered on the GPU, occlusion-checked against the
//! median depth) and that pixel's label and connected label region (regions_gpu.rs),
//! compacted on the GPU to the observed Gaussians and gathered on the host into each
//! Gaussian's observations.
//!
//! Views run on up to `views_in_flight` lanes, each a thread with its own rasterizer,
//! center-pixel buffer and region finder, view `v` on lane `v % lanes`: while one lane waits
//! for the GPU, another records, uploads or gathers. On a GPU one lane was host-bound (an
//! H100: 12 ms a view against 3.2 ms of GPU time, docs/gpu.md). The first view runs alone on
//! the calling thread, and what its lane took decides whether another fits, as in the
//! FlashSplat pass. The observations do not depend on the lanes: each view's are stored by
//! its index.

use std::sync::mpsc;
use std::time::Instant;

use anyhow::{anyhow, ensure, Result};

use super::accumulate::{
    center_params, check_map_size, label_threads, lanes_that_fit, FuseConfig, FuseStats,
    ObserveTimes, LABELS_AHEAD, NO_LABEL,
};
use super::consensus::ConsensusInput;
use super::consensus_footprints::{
    FootprintTable, TileRegions, ViewFootprints, FOOTPRINT_BYTES_MAX,
};
use super::consensus_order::SpatialOrder;
use super::consensus_segments::{label_regions, Observations, ViewObservation};
use super::regions_gpu::{Observed, RegionFinder, RegionStats};
use crate::contract::REGION_EDGE_BIT;
use crate::gpu::kernel_table::ids;
use crate::gpu::timings::KernelTotal;
use crate::gpu::{Buffer, Gpu, Recorder, Timings};
use crate::render::rasterizer::{BandWork, OcclusionDepths};
use crate::render::{GpuScene, Rasterizer};
use crate::scene::Camera;
use crate::util::{prefetch_ordered, BusyTime};

/// What [`observe`] keeps besides the observations. Per view the (Gaussian, pixel) of each
/// observation: 8 bytes an observation, held to the end of the lift, that only `--relabel`
/// reads (it relabels the regions under the centers); plain segment consensus drops them:
/// over a third of what it holds per observation through the clustering (13 bytes against
/// 21). And for `--relabel`, each view's footprints per label region
/// (src/fuse/consensus_footprints.rs), which spare it a second walk of the views.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kept {
    Observations,
    CenterPixels,
    /// The center pixels and the footprints (the walk of every labeled pixel, which gives
    /// the median depth too, instead of the median depth's own walk).
    Footprints,
}

/// What [`observe`] found.
pub struct ViewsObserved {
    pub observations: Observations,
    /// Per view, the (Gaussian, pixel) of each observation (empty lists unless kept).
    pub centers: Vec<Vec<(u32, u32)>>,
    /// Per view, with [`Kept::Footprints`] (else empty).
    pub footprints: Vec<ViewFootprints>,
    pub stats: FuseStats,
}

/// Every view's observations of every Gaussian: label and region under its center (with
/// `occlusion`, only where the center is within the depth tolerance of the rendered median
/// depth), and what `kept` asks for. With an `order`, the observations number the
/// Gaussians by it (the pixels' lists and the footprints keep the scene's numbers).
/// `stats.observe` sums the lanes' host seconds (which overlap when two lanes run).
pub fn observe(
    input: &ConsensusInput,
    cfg: &FuseConfig,
    occlusion: bool,
    kept: Kept,
    order: Option<&SpatialOrder>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ViewsObserved> {
    let (gpu, cams, n) = (input.gpu, input.cams, input.scene.n as usize);
    let mut stats = FuseStats {
        views: cams.len(),
        passes: 1,
        rows_per_pass: input.classes,
        scene_device_bytes: input.scene.device_bytes(),
        ..Default::default()
    };
    let mut views = ObservedViews::new(cams.len(), kept);
    let pass = Pass::new(input, cfg, occlusion, kept, order)?;
    // Label maps are read (decoded) and checked on worker threads a few views ahead, as
    // the FlashSplat pass does, instead of in turn between the views' GPU work.
    let read_time = BusyTime::default();
    let read = |view: usize| read_time.time(|| read_labels(input, view, kept));
    let mut first = Some(Lane::new(gpu, n, cfg, kept)?);
    std::thread::scope(|scope| -> Result<()> {
        let (done, finished) = mpsc::channel::<Result<ObservedView>>();
        let mut running = Running::default();
        let mut waited_since = Instant::now();
        let fed = prefetch_ordered(
            cams.len(),
            label_threads(),
            LABELS_AHEAD,
            read,
            |view, map| {
                stats.label_wait_s += waited_since.elapsed().as_secs_f64();
                input.labels.before_view(view)?;
                progress(view, cams.len());
                while let Ok(observed) = finished.try_recv() {
                    views.store(observed?, &mut stats);
                }
                if let Some(map) = map {
                    stats.views_with_labels += 1;
                    match first.take() {
                        // Alone: what its lane takes says how many lanes fit.
                        Some(mut lane) => {
                            let before = gpu.memory_reserved();
                            views.store(lane.observe(&pass, view, &map)?, &mut stats);
                            let lane_bytes = gpu.memory_reserved().saturating_sub(before);
                            running.start(scope, lane, lane_bytes, &pass, &done)?;
                        }
                        None => running.feed(view, map)?,
                    }
                }
                waited_since = Instant::now();
                Ok(())
            },
        );
        drop(done);
        finish_lanes(running, finished, &mut views, &mut stats).and(fed)
    })?;
    stats.label_read_s += read_time.seconds();
    progress(cams.len(), cams.len());
    let gathering = Instant::now();
    let observations = Observations::from_views(n, &views.observed);
    stats.observe.gather_s += gathering.elapsed().as_secs_f64();
    Ok(ViewsObserved {
        observations,
        centers: views.pixels,
        footprints: views.footprints,
        stats,
    })
}

/// Waits for the lanes and stores the views they observed last; their regions' GPU time
/// goes into `stats`. A lane's own error is returned (it stands before the feed's, which
/// may be only that it stopped).
fn finish_lanes(
    running: Running,
    finished: mpsc::Receiver<Result<ObservedView>>,
    views: &mut ObservedViews,
    stats: &mut FuseStats,
) -> Result<()> {
    stats.views_in_flight = running.feeds.len().max(1);
    for regions in running.finish() {
        stats.gpu_ms += regions.gpu_ms;
        stats.observe.regions_gpu_ms += regions.gpu_ms;
        stats.region_host_fallbacks += regions.host_fallbacks;
    }
    for observed in finished {
        views.store(observed?, stats);
    }
    Ok(())
}

/// A view's label map and, where the footprints are kept, its connected label regions
/// tile by tile.
struct LabeledView {
    map: Vec<u32>,
    regions: Option<TileRegions>,
}

/// View `view`'s label map (None: no labels), checked against its camera and the classes,
/// with its regions where `kept` asks for footprints (found here, on the reading threads).
fn read_labels(input: &ConsensusInput, view: usize, kept: Kept) -> Result<Option<LabeledView>> {
    let (cam, classes) = (&input.cams[view], input.classes);
    let Some(map) = input.labels.labels(view, cam)? else {
        return Ok(None);
    };
    check_map_size(cam, &map)?;
    ensure!(
        map.iter().all(|&l| l == NO_LABEL || (l as usize) < classes),
        "labels of view {} hold a class outside the {classes} classes",
        cam.name
    );
    let width = cam.width as usize;
    let regions =
        (kept == Kept::Footprints).then(|| TileRegions::of(&label_regions(&map, width), width));
    Ok(Some(LabeledView { map, regions }))
}

/// The lanes' threads, each fed its views through a channel of its own.
#[derive(Default)]
struct Running<'scope> {
    feeds: Vec<mpsc::SyncSender<(usize, LabeledView)>>,
    threads: Vec<std::thread::ScopedJoinHandle<'scope, RegionStats>>,
}

impl<'scope> Running<'scope> {
    /// Starts `first`, whose first view took `lane_bytes` of device memory, and as many
    /// more lanes as fit ([`lanes_that_fit`]), each on a thread of `scope`.
    fn start<'env>(
        &mut self,
        scope: &'scope std::thread::Scope<'scope, 'env>,
        first: Lane<'env>,
        lane_bytes: u64,
        pass: &'env Pass<'env>,
        done: &mpsc::Sender<Result<ObservedView>>,
    ) -> Result<()> {
        let (gpu, n) = (pass.input.gpu, pass.input.scene.n as usize);
        let more = (1..lanes_that_fit(gpu, pass.cfg, lane_bytes))
            .map(|_| Lane::new(gpu, n, pass.cfg, pass.kept))
            .collect::<Result<Vec<_>>>()?;
        for lane in std::iter::once(first).chain(more) {
            self.spawn(scope, lane, pass, done.clone());
        }
        Ok(())
    }

    /// Starts `lane` on a thread of `scope`, its views' results sent to `done`.
    fn spawn<'env>(
        &mut self,
        scope: &'scope std::thread::Scope<'scope, 'env>,
        lane: Lane<'env>,
        pass: &'env Pass<'env>,
        done: mpsc::Sender<Result<ObservedView>>,
    ) {
        let (feed, views) = mpsc::sync_channel(1);
        self.threads
            .push(scope.spawn(move || lane.run(pass, views, done)));
        self.feeds.push(feed);
    }

    /// Hands view `view` (labeled `map`) to lane `view % lanes`, once it has room.
    fn feed(&self, view: usize, map: LabeledView) -> Result<()> {
        let lane = &self.feeds[view % self.feeds.len()];
        lane.send((view, map))
            .map_err(|_| anyhow!("an observation lane stopped"))
    }

    /// Closes the feeds and waits for the lanes to finish their views: what each one's
    /// region finder did.
    fn finish(self) -> Vec<RegionStats> {
        drop(self.feeds);
        let finished = self.threads.into_iter().map(|t| t.join());
        finished
            .map(|stats| stats.expect("an observation lane panicked"))
            .collect()
    }
}

/// What every view of the pass shares.
struct Pass<'a> {
    input: &'a ConsensusInput<'a>,
    cfg: &'a FuseConfig,
    occlusion: bool,
    kept: Kept,
    order: Option<&'a SpatialOrder>,
    /// `order`'s number of each Gaussian on the GPU, where the center pixels are written
    /// ([n]).
    spatial: Option<Buffer>,
}

impl<'a> Pass<'a> {
    fn new(
        input: &'a ConsensusInput<'a>,
        cfg: &'a FuseConfig,
        occlusion: bool,
        kept: Kept,
        order: Option<&'a SpatialOrder>,
    ) -> Result<Pass<'a>> {
        let spatial = match order {
            Some(order) => {
                let n = input.scene.n as usize;
                ensure!(
                    order.len() == n,
                    "a numbering of {} Gaussians for a scene of {n}",
                    order.len()
                );
                Some(order.upload(input.gpu)?)
            }
            None => None,
        };
        Ok(Pass {
            input,
            cfg,
            occlusion,
            kept,
            order,
            spatial,
        })
    }
}

/// One view's observations, as a lane found them.
struct ObservedView {
    view: usize,
    observed: Vec<CompactEntry>,
    /// (Gaussian, pixel under its center) of each observation.
    seen: Vec<(u32, u32)>,
    /// With [`Kept::Footprints`].
    footprints: Option<ViewFootprints>,
    gpu_ms: f64,
    kernels: Vec<KernelTotal>,
    times: ObserveTimes,
    device_bytes: u64,
}

/// The views' observations, stored by view as the lanes finish them (views without labels
/// keep none).
struct ObservedViews {
    observed: Vec<Vec<CompactEntry>>,
    pixels: Vec<Vec<(u32, u32)>>,
    footprints: Vec<ViewFootprints>,
    /// Bytes the kept footprints take ([`FOOTPRINT_BYTES_MAX`] at most).
    footprint_bytes: usize,
}

impl ObservedViews {
    fn new(views: usize, kept: Kept) -> ObservedViews {
        let footprints = match kept {
            Kept::Footprints => vec![ViewFootprints::Kept(Vec::new()); views],
            _ => Vec::new(),
        };
        ObservedViews {
            observed: vec![Vec::new(); views],
            pixels: vec![Vec::new(); views],
            footprints,
            footprint_bytes: 0,
        }
    }

    fn store(&mut self, view: ObservedView, stats: &mut FuseStats) {
        self.observed[view.view] = view.observed;
        self.pixels[view.view] = view.seen;
        if let Some(mut footprints) = view.footprints {
            if let ViewFootprints::Kept(kept) = &footprints {
                let bytes = std::mem::size_of_val(kept.as_slice());
                if self.footprint_bytes + bytes > FOOTPRINT_BYTES_MAX {
                    footprints = ViewFootprints::WalkAgain;
                } else {
                    self.footprint_bytes += bytes;
                }
            }
            self.footprints[view.view] = footprints;
        }
        stats.gpu_ms += view.gpu_ms;
        KernelTotal::add_all(&mut stats.kernels, view.kernels);
        stats.peak_device_bytes = stats.peak_device_bytes.max(view.device_bytes);
        stats.observe.render_s += view.times.render_s;
        stats.observe.regions_s += view.times.regions_s;
        stats.observe.gather_s += view.times.gather_s;
    }
}

/// The GPU resources of one view at a time.
struct Lane<'a> {
    /// The first field: a dropped lane waits for its view before its buffers are freed.
    raster: Rasterizer,
    /// The pixel under each Gaussian's visible center ([n]).
    centers: Buffer,
    finder: RegionFinder<'a>,
    /// With [`Kept::Footprints`].
    footprints: Option<FootprintTable>,
}

impl<'a> Lane<'a> {
    fn new(gpu: &'a Gpu, n: usize, cfg: &FuseConfig, kept: Kept) -> Result<Lane<'a>> {
        let mut raster = Rasterizer::new(gpu);
        raster.set_split_sizes(cfg.split);
        let footprints = (kept == Kept::Footprints).then(FootprintTable::default);
        Ok(Lane {
            raster,
            centers: gpu.buffer("center-pixels", (n.max(1) * 4) as u64)?,
            finder: RegionFinder::for_device(gpu, n)?,
            footprints,
        })
    }

    /// Observes the views fed to it until the feed closes or a view fails (its error sent
    /// as its result); returns what its region finder did.
    fn run(
        mut self,
        pass: &Pass,
        feed: mpsc::Receiver<(usize, LabeledView)>,
        done: mpsc::Sender<Result<ObservedView>>,
    ) -> RegionStats {
        for (view, map) in feed {
            let observed = self.observe(pass, view, &map);
            let failed = observed.is_err();
            if done.send(observed).is_err() || failed {
                break;
            }
        }
        self.finder.stats
    }

    /// View `view` labeled `map`: its centers' pixels rendered, their regions found, and
    /// its observations gathered straight from the readback (not copied first).
    fn observe(&mut self, pass: &Pass, view: usize, labeled: &LabeledView) -> Result<ObservedView> {
        let (gpu, scene) = (pass.input.gpu, pass.input.scene);
        let cam = &pass.input.cams[view];
        let mut times = ObserveTimes::default();
        let rendering = Instant::now();
        let mut walk = match (&mut self.footprints, &labeled.regions) {
            (Some(table), Some(regions)) => {
                table.stage_regions(gpu, regions)?;
                Some((table, regions))
            }
            _ => None,
        };
        let table = walk.as_mut().map(|(table, _)| &mut **table);
        let timings = center_pixels(&mut self.raster, scene, cam, &self.centers, table, pass)?;
        let device_bytes = gpu.memory_reserved();
        let footprints = walk
            .map(|(table, regions)| table.read(&self.raster, regions))
            .transpose()?;
        times.render_s = rendering.elapsed().as_secs_f64();
        let finding = Instant::now();
        let keep_pixels = pass.kept != Kept::Observations;
        let (observed, seen) =
            self.finder
                .observations(&labeled.map, cam.width, &self.centers, |observed| {
                    let gathering = Instant::now();
                    let gathered = view_observations(observed, keep_pixels, pass.order);
                    times.gather_s = gathering.elapsed().as_secs_f64();
                    gathered
                })?;
        times.regions_s = finding.elapsed().as_secs_f64() - times.gather_s;
        Ok(ObservedView {
            view,
            observed,
            seen,
            footprints,
            gpu_ms: timings.total_ns() * 1e-6,
            kernels: timings.by_kernel(),
            times,
            device_bytes,
        })
    }
}

/// A view's observation of a Gaussian as the views keep it until they are done: the GPU's
/// region word as it is (with [`REGION_EDGE_BIT`]), 12 bytes where a
/// [`super::consensus_segments::ViewEntry`] takes 16 (a room's Gaussian is observed in
/// about 12% of 200 views: tens of millions of observations for a million Gaussians).
#[derive(Clone, Copy, Debug)]
struct CompactEntry {
    gaussian: u32,
    label: u32,
    region_and_edge: u32,
}

const _: () = assert!(std::mem::size_of::<CompactEntry>() == 12);

impl ViewObservation for CompactEntry {
    fn gaussian(&self) -> u32 {
        self.gaussian
    }

    fn seen(&self) -> (u32, u32, bool) {
        let region = self.region_and_edge & !REGION_EDGE_BIT;
        (
            self.label,
            region,
            self.region_and_edge & REGION_EDGE_BIT != 0,
        )
    }
}

/// One view's observations as the GPU compacted them ([`Observed`], in Gaussian order,
/// the Gaussians numbered by `order` where one is given): (Gaussian, label, region with
/// its edge bit) and, where kept, (Gaussian, pixel) with the scene's numbers.
fn view_observations(
    observed: &[Observed],
    keep_pixels: bool,
    order: Option<&SpatialOrder>,
) -> (Vec<CompactEntry>, Vec<(u32, u32)>) {
    let entry = |o: &Observed| CompactEntry {
        gaussian: o.gaussian,
        label: o.label,
        region_and_edge: o.region,
    };
    let scene_number = |g: u32| order.map_or(g, |order| order.scene(g));
    let seen = match keep_pixels {
        true => (observed.iter())
            .map(|o| (scene_number(o.gaussian), o.pixel))
            .collect(),
        false => Vec::new(),
    };
    (observed.iter().map(entry).collect(), seen)
}

/// Writes the pixel under every Gaussian's visible center into `out`; returns the GPU's
/// timestamps. With `footprints`, the median depth comes from their walk (the view's
/// regions staged), else from its own.
fn center_pixels(
    raster: &mut Rasterizer,
    scene: &GpuScene,
    cam: &Camera,
    out: &Buffer,
    mut footprints: Option<&mut FootprintTable>,
    pass: &Pass,
) -> Result<Timings> {
    let cfg = pass.cfg;
    if !pass.occlusion && footprints.is_none() {
        let mut rec = Recorder::new(raster.gpu())?;
        dispatch_center_pixels(&mut rec, scene, cam, None, out, pass)?;
        return Ok(rec.submit_and_wait()?);
    }
    // The centers are looked up once the whole view's depth is rendered (every Gaussian's
    // entry is written, so a binning that overflowed and runs again leaves nothing behind).
    // The median depth, not the expected one `vote --occlusion` tests against: a pixel
    // stops at the surface in front instead of at saturation (a third of the consensus's
    // time on lavapipe), and on an object's silhouette it is the depth of one of the two
    // surfaces, not a blend that matches neither.
    let opts = cfg.render_options();
    let run = raster.run_tiled_in_bands(scene, cam, &opts, BandWork::Overwrite, |rec, tiles| {
        match footprints.as_deref_mut() {
            Some(table) => table.record_walk(rec, tiles, tiles.occlusion_depths())?,
            None => tiles.record_median_depth(rec)?,
        }
        if !tiles.is_last_band() {
            return Ok(());
        }
        rec.barrier();
        let depths = pass.occlusion.then(|| tiles.occlusion_depths());
        dispatch_center_pixels(rec, scene, cam, depths, out, pass)
    })?;
    Ok(run.timings)
}

fn dispatch_center_pixels(
    rec: &mut Recorder,
    scene: &GpuScene,
    cam: &Camera,
    depths: Option<OcclusionDepths>,
    out: &Buffer,
    pass: &Pass,
) -> Result<()> {
    // No class rows: the observations take every label.
    let mut params = center_params(
        cam,
        scene,
        pass.cfg,
        depths.is_some(),
        (0, 0),
        out.address_words(4)?,
    )?;
    if let Some(spatial) = &pass.spatial {
        params.spatial_addr = spatial.address_words(4)?;
    }
    rec.dispatch(
        ids::FUSE_CENTER_PIXEL,
        &[
            // Never read without occlusion: any readable buffer fills the binding.
            ("depth", depths.map_or(&scene.params.means, |d| d.median)),
            (
                "opaque_depth",
                depths.map_or(&scene.params.means, |d| d.opaque),
            ),
        ],
        &params,
        ids::FUSE_CENTER_PIXEL.groups_for(scene.n),
    )?;
    rec.barrier();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuse::consensus_segments::ViewEntry;
    use crate::util::Rng;

    /// The views' packed lists give the rows the tuples give: the edge bit read off the
    /// region word, the region without it (regions up to the bit below it), with and
    /// without the pixels; the pixels' lists in the scene's numbering where the lists come
    /// numbered in space.
    #[test]
    fn packed_lists_give_the_rows_tuples_give() {
        let (n, mut rng) = (300, Rng::new(5));
        let mut observed: Vec<Vec<Observed>> = vec![Vec::new(); 4];
        for (v, list) in observed.iter_mut().enumerate() {
            for g in 0..n as u32 {
                if !rng.bool(0.6) {
                    continue;
                }
                let region = match g % 3 {
                    0 => REGION_EDGE_BIT - 1 - v as u32, // the largest regions
                    _ => rng.next_u32() % 5000,
                };
                let edge = if rng.bool(0.3) { REGION_EDGE_BIT } else { 0 };
                let (pixel, label) = (rng.next_u32() % 9999, rng.next_u32() % 7);
                list.push(Observed {
                    gaussian: g,
                    pixel,
                    label,
                    region: region | edge,
                });
            }
        }
        let tuples: Vec<Vec<ViewEntry>> = observed
            .iter()
            .map(|list| {
                let entry = |o: &Observed| {
                    let edge = o.region >= REGION_EDGE_BIT;
                    (
                        o.gaussian,
                        o.label,
                        o.region - REGION_EDGE_BIT * edge as u32,
                        edge,
                    )
                };
                list.iter().map(entry).collect()
            })
            .collect();
        // With a numbering in space the GPU's lists carry the Gaussians' numbers there
        // (the rows are as they come), and the pixels' lists the scene's.
        let mut shuffled: Vec<u32> = (0..n as u32).collect();
        rng.shuffle(&mut shuffled);
        let spatial = SpatialOrder::from_scene_of_spatial(shuffled);
        for (keep_pixels, order) in [true, false]
            .into_iter()
            .flat_map(|p| [(p, None), (p, Some(&spatial))])
        {
            let views: Vec<_> = observed
                .iter()
                .map(|l| view_observations(l, keep_pixels, order))
                .collect();
            let packed: Vec<Vec<CompactEntry>> = views.iter().map(|v| v.0.clone()).collect();
            let rows = Observations::from_views(n, &packed);
            assert_eq!(rows, Observations::from_views(n, &tuples));
            assert!(rows.edge.iter().any(|&e| e) && rows.edge.iter().any(|&e| !e));
            let scene_number = |g: u32| order.map_or(g, |o| o.scene(g));
            for ((_, seen), list) in views.iter().zip(&observed) {
                let expected: Vec<(u32, u32)> = match keep_pixels {
                    true => (list.iter())
                        .map(|o| (scene_number(o.gaussian), o.pixel))
                        .collect(),
                    false => Vec::new(),
                };
                assert_eq!(seen, &expected);
            }
        }
    }
}
