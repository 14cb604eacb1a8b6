//! Connected label regions on the GPU (glsl/fuse/label_regions.glsl and the region_*
//! kernels), for the segment consensus's observations: per view, the region under every
//! Gaussian's center pixel and whether that pixel is on the region's edge, without the
//! host touching the view's pixels. Region ids are the index of the region's first pixel in
//! scan order, as [`label_regions`] gives them.
//!
//! A CPU Vulkan driver caps the loop iterations of one invocation (lavapipe: 65,535), which
//! could cut a union short on a pathological map; a check pass finds any such view and the
//! host then finds its regions itself ([`RegionStats::host_fallbacks`]).

use anyhow::Result;

use super::consensus_segments::{label_regions, region_edges};
use super::NO_LABEL;
use crate::contract::params::RegionParams;
use crate::contract::REGION_EDGE_BIT;
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, Recorder};

/// Workgroups one dispatch dimension holds (Vulkan's guaranteed minimum, lavapipe's limit).
const MAX_GROUPS: u32 = 65_535;

/// What the region finder did over its views.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegionStats {
    pub gpu_ms: f64,
    /// Views whose regions the check found incomplete, found again on the host.
    pub host_fallbacks: usize,
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
    pub stats: RegionStats,
}

impl<'a> RegionFinder<'a> {
    /// A finder for lookups of `n` Gaussians.
    pub fn new(gpu: &'a Gpu, n: usize) -> Result<RegionFinder<'a>> {
        Ok(RegionFinder {
            gpu,
            pixel_bufs: None,
            pixels: 0,
            status: gpu.buffer("region-status", 4)?,
            out: gpu.buffer("region-lookup", (n.max(1) * 4) as u64)?,
            n,
            stats: RegionStats::default(),
        })
    }

    /// Per Gaussian, the region id of its center pixel in `centers` ([n], NO_LABEL: none) of
    /// the view labeled `map` (`width` pixels a row), with [`REGION_EDGE_BIT`] set where the
    /// pixel is on the region's edge; NO_LABEL where there is no pixel or it is unlabeled.
    pub fn regions_at(&mut self, map: &[u32], width: u32, centers: &Buffer) -> Result<Vec<u32>> {
        let pixel_groups = ids::FUSE_REGION_INIT.groups_for(map.len() as u32);
        if map.len() > u32::MAX as usize || pixel_groups[0] > MAX_GROUPS {
            // Past one dispatch's reach: a view of over 16.7M pixels.
            return self.on_host(map, width, centers);
        }
        let params = self.upload_view(map, width, centers.address_words(4)?)?;
        let mut rec = Recorder::new(self.gpu)?;
        rec.fill(&self.status, 0, 4, 0);
        rec.barrier();
        let m0 = rec.mark();
        for kernel in [
            ids::FUSE_REGION_INIT,
            ids::FUSE_REGION_MERGE,
            ids::FUSE_REGION_FLATTEN,
            ids::FUSE_REGION_CHECK,
        ] {
            rec.dispatch(kernel, &[], &params, pixel_groups)?;
            rec.barrier();
        }
        let lookup_groups = ids::FUSE_REGION_LOOKUP.groups_for(self.n as u32);
        rec.dispatch(ids::FUSE_REGION_LOOKUP, &[], &params, lookup_groups)?;
        let m1 = rec.mark();
        let t = rec.submit_and_wait()?;
        self.stats.gpu_ms += t.between(m0, m1).unwrap_or(0.0) * 1e-6;
        if self.gpu.download::<u32>(&self.status, 0, 1)?[0] == 0 {
            return Ok(self.gpu.download(&self.out, 0, self.n)?);
        }
        self.on_host(map, width, centers)
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
        let params = self.upload_view(map, width, self.out.address_words(4)?)?;
        let [_, _, region] = self.pixel_bufs.as_ref().expect("sized by upload_view");
        self.gpu.upload(region, 0, region_ids)?;
        let mut rec = Recorder::new(self.gpu)?;
        rec.fill(&self.status, 0, 4, 0);
        rec.barrier();
        let groups = ids::FUSE_REGION_CHECK.groups_for(map.len() as u32);
        rec.dispatch(ids::FUSE_REGION_CHECK, &[], &params, groups)?;
        rec.submit_and_wait()?;
        Ok(self.gpu.download::<u32>(&self.status, 0, 1)?[0] == 0)
    }

    fn on_host(&mut self, map: &[u32], width: u32, centers: &Buffer) -> Result<Vec<u32>> {
        self.stats.host_fallbacks += 1;
        let pixels: Vec<u32> = self.gpu.download(centers, 0, self.n)?;
        Ok(regions_on_host(map, width as usize, &pixels))
    }

    /// Uploads the view's labels (buffers grown to fit) and gives the kernels' parameters,
    /// for the center pixels at `centers_addr`.
    fn upload_view(
        &mut self,
        map: &[u32],
        width: u32,
        centers_addr: [u32; 2],
    ) -> Result<RegionParams> {
        self.size_pixel_buffers(map.len())?;
        let [labels, parent, region] = self.pixel_bufs.as_ref().expect("sized above");
        self.gpu.upload(labels, 0, map)?;
        Ok(RegionParams {
            labels_addr: labels.address_words(4)?,
            parent_addr: parent.address_words(4)?,
            region_addr: region.address_words(4)?,
            status_addr: self.status.address_words(4)?,
            pixels_addr: centers_addr,
            out_addr: self.out.address_words(4)?,
            width,
            height: (map.len() / width.max(1) as usize) as u32,
            n: self.n as u32,
        })
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
