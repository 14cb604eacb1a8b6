//! Connected label regions on the GPU (glsl/fuse/label_regions.glsl and the region_*
//! kernels), for the segment consensus's observations: per view, the region under every
//! Gaussian's center pixel and whether that pixel is on the region's edge, without the
//! host touching the view's pixels. Region ids are the index of the region's first pixel in
//! scan order, as [`label_regions`] gives them. `--relabel` relabels each view's regions
//! here too ([`RegionFinder::relabel`]): only the per-region decision runs on the host.
//!
//! A CPU Vulkan driver caps the loop iterations of one invocation (lavapipe: 65,535), which
//! could cut a union short on a pathological map; a check pass finds any such view and the
//! host then finds its regions itself ([`RegionStats::host_fallbacks`]).
//!
//! On a CPU device the host finds every view's regions itself
//! ([`RegionFinder::for_device`], `DeviceCaps::cpu_forms`): the driver runs the kernels
//! on the same cores, and lavapipe took 47 ms a view of 320x240 with 200k Gaussians (the
//! union-find and the lookup and compaction of the Gaussians) where the host takes 2.5 ms.

use std::cell::RefCell;

use anyhow::Result;

use super::consensus_confusion::ConfusionRates;
use super::consensus_relabel::{decide_regions, relabel_view, RegionSeed, RelabelRule};
use super::consensus_segments::{label_regions, region_edges};
use super::NO_LABEL;
use crate::contract::params::RegionParams;
use crate::contract::{OBSERVED_HEADER_WORDS, OBSERVED_WORDS, REGION_EDGE_BIT, RELABEL_KEEP};
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, GpuCount, GpuResult, PrefixScan, Recorder, Staging};

/// Workgroups one dispatch dimension holds (Vulkan's guaranteed minimum, lavapipe's limit).
const MAX_GROUPS: u32 = 65_535;

/// Farthest region_depth and region_near search (city-block; a diamond of (2d + 1)^2 pixels
/// stays far under a CPU driver's loop cap); a rule reaching farther (`depth` or `near`)
/// relabels on the host.
pub const MAX_GPU_REACH: u32 = 32;

/// What the region finder did over its views.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegionStats {
    pub gpu_ms: f64,
    /// Views whose regions the check found incomplete, found again on the host.
    pub host_fallbacks: usize,
}

/// One observation of a view, as observed_compact writes it: a Gaussian whose center lies
/// on a labeled pixel, that pixel, its label and its region id (with [`REGION_EDGE_BIT`]
/// where the pixel is on the region's edge).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Observed {
    pub gaussian: u32,
    pub pixel: u32,
    pub label: u32,
    pub region: u32,
}

const _: () = assert!(std::mem::size_of::<Observed>() == OBSERVED_WORDS as usize * 4);

/// The device side of [`RegionFinder::observations`], made on its first call.
struct Compaction {
    /// [n]: 1 per observed Gaussian, then scanned in place into each one's place.
    slots: Buffer,
    /// [1]: n, the scan's element count read on the GPU.
    count: Buffer,
    scan: PrefixScan,
    /// Host-visible: the count, then the observations ([`Observed`]).
    out: Buffer,
}

impl Compaction {
    fn new(gpu: &Gpu, n: usize) -> Result<Compaction> {
        let words = OBSERVED_HEADER_WORDS as u64 + OBSERVED_WORDS as u64 * n as u64;
        Ok(Compaction {
            slots: gpu.buffer("observed-slots", (n.max(1) * 4) as u64)?,
            count: gpu.buffer_from("observed-count", &[n as u32])?,
            scan: PrefixScan::new(gpu, n as u64)?,
            out: gpu.host_output_buffer("observed", words * 4)?,
        })
    }
}

/// What [`RegionFinder::find_regions`]'s reader made of its read-back.
struct Found<R> {
    read: R,
    gpu_ms: f64,
}

/// Device buffers for one view's regions at a time (sized for the largest view so far).
pub struct RegionFinder<'a> {
    gpu: &'a Gpu,
    /// Labels, links, ids: [pixels] each.
    pixel_bufs: Option<[Buffer; 3]>,
    pixels: usize,
    status: Buffer,
    out: Buffer,
    n: usize,
    /// For [`RegionFinder::relabel`], made on its first call: the seeds' pixels, classes,
    /// depths and near flags ([n] each) and the decided (region, label) pairs ([2n]).
    relabel_bufs: Option<[Buffer; 5]>,
    compaction: Option<Compaction>,
    /// Every view's regions found on the host ([`RegionFinder::for_device`]).
    on_host: bool,
    /// Every view's uploads and downloads go through these, in the view's submissions (a
    /// cell: a submission records into them while it reads the finder's own buffers).
    staging: RefCell<Staging>,
    pub stats: RegionStats,
}

impl<'a> RegionFinder<'a> {
    /// A finder for lookups of `n` Gaussians, finding the regions on the GPU.
    pub fn new(gpu: &'a Gpu, n: usize) -> Result<RegionFinder<'a>> {
        Ok(RegionFinder {
            gpu,
            pixel_bufs: None,
            pixels: 0,
            status: gpu.buffer("region-status", 4)?,
            out: gpu.buffer("region-lookup", (n.max(1) * 4) as u64)?,
            n,
            relabel_bufs: None,
            compaction: None,
            on_host: false,
            staging: RefCell::default(),
            stats: RegionStats::default(),
        })
    }

    /// A finder for lookups of `n` Gaussians in the device's form: on the host where
    /// [`RegionFinder::on_host_for`] says so, else on the GPU.
    pub fn for_device(gpu: &'a Gpu, n: usize) -> Result<RegionFinder<'a>> {
        Ok(RegionFinder {
            on_host: Self::on_host_for(gpu),
            ..RegionFinder::new(gpu, n)?
        })
    }

    /// Whether the host finds (and relabels) the regions on `gpu`: where the device takes
    /// the CPU drivers' forms (`DeviceCaps::cpu_forms`).
    pub fn on_host_for(gpu: &Gpu) -> bool {
        gpu.caps().cpu_forms
    }

    /// `read` given the view's observations, in Gaussian order: each Gaussian whose center
    /// pixel (as `centers` holds it, [n], NO_LABEL: none) is labeled in `map` (`width`
    /// pixels a row), with that pixel, its label and its region, as [`Observed`]. Compacted
    /// on the GPU (a prefix scan places each one) and read where the kernel wrote them:
    /// only the observations cross to the host, not two words for every Gaussian of the
    /// scene. Where the finder works on the host, the region check fails, or the map is
    /// too large for one dispatch, found on the host from the center pixels.
    pub fn observations<R>(
        &mut self,
        map: &[u32],
        width: u32,
        centers: &Buffer,
        read: impl FnOnce(&[Observed]) -> R,
    ) -> Result<R> {
        if self.n == 0 {
            return Ok(read(&[]));
        }
        if self.on_host || !Self::fits(map) {
            self.stats.host_fallbacks += usize::from(!self.on_host);
            return Ok(read(&self.observed_on_host(map, width, centers)?));
        }
        if self.compaction.is_none() {
            self.compaction = Some(Compaction::new(self.gpu, self.n)?);
        }
        let mut params = self.view_params(map, width, centers.address_words(4)?)?;
        let c = self.compaction.as_ref().expect("made above");
        params.slots_addr = c.slots.address_words(4)?;
        params.observed_addr = c.out.address_words(4)?;
        let compact = |rec: &mut Recorder| {
            for kernel in [ids::FUSE_REGION_LOOKUP, ids::FUSE_OBSERVED_FLAG] {
                rec.dispatch(kernel, &[], &params, kernel.groups_for(params.n))?;
                rec.barrier();
            }
            c.scan
                .record(rec, &c.slots, &c.slots, GpuCount::at(&c.count, 0))?;
            let scatter = ids::FUSE_OBSERVED_COMPACT;
            rec.dispatch(scatter, &[], &params, scatter.groups_for(params.n))?;
            rec.host_barrier();
            Ok(())
        };
        let uploads = [(self.labels_buffer(), map)];
        let found = self.find_regions(&params, &uploads, compact, &[], |complete, _| complete)?;
        self.stats.gpu_ms += found.gpu_ms;
        if !found.read {
            self.stats.host_fallbacks += 1;
            return Ok(read(&self.observed_on_host(map, width, centers)?));
        }
        let out = &mut self.compaction.as_mut().expect("made above").out;
        let words: &[u32] = bytemuck::cast_slice(out.mapped());
        let count = words[0] as usize;
        anyhow::ensure!(
            count <= self.n,
            "the GPU compacted {count} observations of {} Gaussians",
            self.n
        );
        let start = OBSERVED_HEADER_WORDS as usize;
        let end = start + count * OBSERVED_WORDS as usize;
        Ok(read(bytemuck::cast_slice(&words[start..end])))
    }

    /// [`RegionFinder::observations`] on the host: the center pixels read back, their
    /// regions found here.
    fn observed_on_host(
        &mut self,
        map: &[u32],
        width: u32,
        centers: &Buffer,
    ) -> Result<Vec<Observed>> {
        let pixels: Vec<u32> = self.gpu.download(centers, 0, self.n)?;
        let regions = regions_on_host(map, width as usize, &pixels);
        let observed = (0..self.n)
            .filter(|&g| regions[g] != NO_LABEL)
            .map(|g| Observed {
                gaussian: g as u32,
                pixel: pixels[g],
                label: map[pixels[g] as usize],
                region: regions[g],
            });
        Ok(observed.collect())
    }

    /// Whether one dispatch over the pixels of `map` reaches them all (past 16.7M pixels
    /// it does not).
    fn fits(map: &[u32]) -> bool {
        let pixel_groups = ids::FUSE_REGION_INIT.groups_for(map.len() as u32);
        map.len() <= u32::MAX as usize && pixel_groups[0] <= MAX_GROUPS
    }

    /// One submission and wait: `uploads` copied in, the regions of the view (`params`)
    /// found, `then` recorded (lookups over them), the region check's status and the
    /// leading bytes of each of `downloads` copied out.
    fn find_regions<R>(
        &self,
        params: &RegionParams,
        uploads: &[(&Buffer, &[u32])],
        then: impl FnOnce(&mut Recorder) -> GpuResult<()>,
        downloads: &[(&Buffer, u64)],
        read: impl FnOnce(bool, &[&[u32]]) -> R,
    ) -> Result<Found<R>> {
        let pixel_groups = ids::FUSE_REGION_INIT.groups_for(params.width * params.height);
        let mut staging = self.staging.borrow_mut();
        let mut rec = Recorder::new(self.gpu)?;
        staging.record_uploads(self.gpu, &mut rec, uploads)?;
        rec.fill(&self.status, 0, 4, 0);
        rec.barrier();
        let m0 = rec.mark();
        for kernel in [
            ids::FUSE_REGION_INIT,
            ids::FUSE_REGION_MERGE,
            ids::FUSE_REGION_FLATTEN,
            ids::FUSE_REGION_CHECK,
        ] {
            rec.dispatch(kernel, &[], params, pixel_groups)?;
            rec.barrier();
        }
        then(&mut rec)?;
        let m1 = rec.mark();
        rec.barrier();
        let status = [(&self.status, 4)];
        staging.record_downloads(self.gpu, &mut rec, &[&status[..], downloads].concat())?;
        let t = rec.submit_and_wait()?;
        let read = staging.read_with(|words: &[&[u32]]| read(words[0][0] == 0, &words[1..]));
        Ok(Found {
            read,
            gpu_ms: t.between(m0, m1).unwrap_or(0.0) * 1e-6,
        })
    }

    /// `map` (`width` pixels a row) relabeled from `seeds`, the (pixel, class) of the
    /// observed Gaussians' centers, by `rule` and the scene's `confusions`: what
    /// [`relabel_view`] gives. The regions and
    /// the seeds' regions, depths and near flags are found on the GPU, each region's label
    /// decided on the host from its seeds ([`decide_regions`]), the pixels rewritten on the
    /// GPU. A view past the GPU's reach (more seeds than the finder's Gaussians, an
    /// incomplete region check, a depth or near radius past [`MAX_GPU_REACH`]) is relabeled
    /// on the host.
    pub fn relabel(
        &mut self,
        map: &[u32],
        width: u32,
        seeds: &[(u32, u32)],
        rule: &RelabelRule,
        confusions: &ConfusionRates,
    ) -> Result<Vec<u32>> {
        if seeds.is_empty() {
            return Ok(map.to_vec()); // no region holds a seed: every one keeps its label
        }
        let past_reach = rule.depth.max(rule.near) > MAX_GPU_REACH;
        if self.on_host || !Self::fits(map) || seeds.len() > self.n || past_reach {
            self.stats.host_fallbacks += usize::from(!self.on_host);
            return Ok(self.relabel_on_host(map, width, seeds, rule, confusions));
        }
        let bufs = match self.relabel_bufs.take() {
            Some(bufs) => bufs,
            None => {
                let words = (self.n.max(1) * 4) as u64;
                [
                    self.gpu.buffer("relabel-seed-pixels", words)?,
                    self.gpu.buffer("relabel-seed-classes", words)?,
                    self.gpu.buffer("relabel-seed-depths", words)?,
                    self.gpu.buffer("relabel-seed-near", words)?,
                    self.gpu.buffer("relabel-pairs", 2 * words)?,
                ]
            }
        };
        let relabeled = self.relabel_with(&bufs, map, width, seeds, rule, confusions);
        self.relabel_bufs = Some(bufs);
        relabeled
    }

    /// [`RegionFinder::relabel`] on the GPU with `bufs` (the seeds' pixels, classes, depths
    /// and near flags, the decided pairs).
    fn relabel_with(
        &mut self,
        [seed_pixels, seed_classes, seed_depths, seed_near, pairs]: &[Buffer; 5],
        map: &[u32],
        width: u32,
        seeds: &[(u32, u32)],
        rule: &RelabelRule,
        confusions: &ConfusionRates,
    ) -> Result<Vec<u32>> {
        let (pixels, classes): (Vec<u32>, Vec<u32>) = seeds.iter().copied().unzip();
        let mut params = self.view_params(map, width, seed_pixels.address_words(4)?)?;
        params.n = seeds.len() as u32;
        params.classes_addr = seed_classes.address_words(4)?;
        params.depth_addr = seed_depths.address_words(4)?;
        params.near_addr = seed_near.address_words(4)?;
        params.pairs_addr = pairs.address_words(4)?;
        params.max_depth = rule.depth;
        params.near_radius = rule.near;
        let per_seed = |rec: &mut Recorder| {
            let groups = ids::FUSE_REGION_LOOKUP.groups_for(params.n);
            rec.dispatch(ids::FUSE_REGION_LOOKUP, &[], &params, groups)?;
            rec.dispatch(ids::FUSE_REGION_DEPTH, &[], &params, groups)?;
            rec.dispatch(ids::FUSE_REGION_NEAR, &[], &params, groups)
        };
        let uploads = [
            (seed_pixels, &pixels[..]),
            (seed_classes, &classes[..]),
            (self.labels_buffer(), map),
        ];
        let bytes = (seeds.len() * 4) as u64;
        let downloads = [(&self.out, bytes), (seed_depths, bytes), (seed_near, bytes)];
        let found = self.find_regions(
            &params,
            &uploads,
            per_seed,
            &downloads,
            |complete, words| {
                complete.then(|| words.iter().map(|w| w.to_vec()).collect::<Vec<_>>())
            },
        )?;
        self.stats.gpu_ms += found.gpu_ms;
        let Some(words) = found.read else {
            self.stats.host_fallbacks += 1;
            return Ok(self.relabel_on_host(map, width, seeds, rule, confusions));
        };
        let [regions, depths, near] = words.try_into().expect("three downloads");
        let found = (0..seeds.len())
            .filter(|&i| regions[i] != NO_LABEL)
            .map(|i| RegionSeed {
                region: regions[i] & !REGION_EDGE_BIT,
                depth: depths[i],
                class: seeds[i].1,
                near: near[i] != 0,
            });
        let decided: Vec<u32> = decide_regions(found.collect(), map, rule, confusions)
            .into_iter()
            .flat_map(|(region, label)| [region, label])
            .collect();
        if decided.is_empty() {
            return Ok(map.to_vec());
        }
        params.pairs = (decided.len() / 2) as u32;
        self.rewrite_labels(&params, pairs, &decided, map.len())
    }

    /// Rewrites the view's labels (uploaded with the regions) from the `decided` (region,
    /// label) pairs, copied into `pairs`: the table filled with RELABEL_KEEP, the pairs
    /// scattered into it, every pixel looked up; one submission, the labels read back.
    fn rewrite_labels(
        &mut self,
        params: &RegionParams,
        pairs: &Buffer,
        decided: &[u32],
        pixels: usize,
    ) -> Result<Vec<u32>> {
        let [labels, table, _] = self.pixel_bufs.as_ref().expect("sized by view_params");
        let staging = self.staging.get_mut();
        let mut rec = Recorder::new(self.gpu)?;
        staging.record_uploads(self.gpu, &mut rec, &[(pairs, decided)])?;
        let m0 = rec.mark();
        rec.fill(table, 0, (pixels * 4) as u64, RELABEL_KEEP);
        rec.barrier();
        let pair_groups = ids::FUSE_REGION_RELABEL_SCATTER.groups_for(params.pairs);
        rec.dispatch(ids::FUSE_REGION_RELABEL_SCATTER, &[], params, pair_groups)?;
        rec.barrier();
        let pixel_groups = ids::FUSE_REGION_RELABEL.groups_for(pixels as u32);
        rec.dispatch(ids::FUSE_REGION_RELABEL, &[], params, pixel_groups)?;
        let m1 = rec.mark();
        rec.barrier();
        staging.record_downloads(self.gpu, &mut rec, &[(labels, (pixels * 4) as u64)])?;
        let t = rec.submit_and_wait()?;
        self.stats.gpu_ms += t.between(m0, m1).unwrap_or(0.0) * 1e-6;
        Ok(staging.read::<u32>().pop().expect("one download"))
    }

    fn relabel_on_host(
        &mut self,
        map: &[u32],
        width: u32,
        seeds: &[(u32, u32)],
        rule: &RelabelRule,
        confusions: &ConfusionRates,
    ) -> Vec<u32> {
        let mut relabeled = map.to_vec();
        let seeds = seeds.iter().copied();
        relabel_view(&mut relabeled, width as usize, seeds, rule, confusions);
        relabeled
    }

    /// Whether `region_ids` (per pixel of `map`, NO_LABEL where unlabeled) are complete
    /// regions by region_check's test, the one that sends a view to the host: every id a
    /// root pixel of the same label, every equal-label left or upper neighbour in the same
    /// region. For tests of that check.
    pub fn regions_complete(
        &mut self,
        map: &[u32],
        width: u32,
        region_ids: &[u32],
    ) -> Result<bool> {
        assert_eq!(map.len(), region_ids.len(), "one id per pixel");
        // region_check reads no center pixels: any address will do.
        let params = self.view_params(map, width, self.out.address_words(4)?)?;
        let [labels, _, region] = self.pixel_bufs.as_ref().expect("sized by view_params");
        let staging = self.staging.get_mut();
        let mut rec = Recorder::new(self.gpu)?;
        staging.record_uploads(self.gpu, &mut rec, &[(labels, map), (region, region_ids)])?;
        rec.fill(&self.status, 0, 4, 0);
        rec.barrier();
        let groups = ids::FUSE_REGION_CHECK.groups_for(map.len() as u32);
        rec.dispatch(ids::FUSE_REGION_CHECK, &[], &params, groups)?;
        rec.barrier();
        staging.record_downloads(self.gpu, &mut rec, &[(&self.status, 4)])?;
        rec.submit_and_wait()?;
        Ok(staging.read::<u32>()[0][0] == 0)
    }

    /// The kernels' parameters for a view labeled `map` (buffers grown to fit; the labels
    /// are uploaded in the view's submission), for the center pixels at `centers_addr`.
    fn view_params(
        &mut self,
        map: &[u32],
        width: u32,
        centers_addr: [u32; 2],
    ) -> Result<RegionParams> {
        self.size_pixel_buffers(map.len())?;
        let [labels, parent, region] = self.pixel_bufs.as_ref().expect("sized above");
        Ok(RegionParams {
            labels_addr: labels.address_words(4)?,
            parent_addr: parent.address_words(4)?,
            region_addr: region.address_words(4)?,
            status_addr: self.status.address_words(4)?,
            pixels_addr: centers_addr,
            out_addr: self.out.address_words(4)?,
            // Set by the relabeling that reads them.
            depth_addr: [0; 2],
            pairs_addr: [0; 2],
            classes_addr: [0; 2],
            near_addr: [0; 2],
            // Set by the compaction of observations.
            slots_addr: [0; 2],
            observed_addr: [0; 2],
            width,
            height: (map.len() / width.max(1) as usize) as u32,
            n: self.n as u32,
            max_depth: 0,
            near_radius: 0,
            pairs: 0,
        })
    }

    /// The buffer the view's labels are uploaded to (sized by [`RegionFinder::view_params`]).
    fn labels_buffer(&self) -> &Buffer {
        &self.pixel_bufs.as_ref().expect("sized by view_params")[0]
    }

    fn size_pixel_buffers(&mut self, pixels: usize) -> Result<()> {
        if self.pixel_bufs.is_none() || pixels > self.pixels {
            let bytes = (pixels.max(1) * 4) as u64;
            let gpu = self.gpu;
            self.pixel_bufs = Some([
                gpu.buffer("region-labels", bytes)?,
                gpu.buffer("region-parent", bytes)?,
                gpu.buffer("region-ids", bytes)?,
            ]);
            self.pixels = pixels;
        }
        Ok(())
    }
}

/// What region_lookup computes, on the host: per center pixel (NO_LABEL: none), its region
/// id with [`REGION_EDGE_BIT`] where on the region's edge; NO_LABEL where unlabeled.
pub fn regions_on_host(map: &[u32], width: usize, centers: &[u32]) -> Vec<u32> {
    let regions = label_regions(map, width);
    let edges = region_edges(&regions, width);
    centers
        .iter()
        .map(|&p| match regions.get(p as usize) {
            Some(&r) if r != NO_LABEL => {
                r | if edges[p as usize] {
                    REGION_EDGE_BIT
                } else {
                    0
                }
            }
            _ => NO_LABEL,
        })
        .collect()
}
