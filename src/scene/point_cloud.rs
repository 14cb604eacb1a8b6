//! Seeding Gaussians from a point cloud (an SfM `input.ply`), as INRIA 3DGS's
//! `GaussianModel.create_from_pcd` does: one isotropic Gaussian per point whose scale is the
//! root of the mean squared distance to its 3 nearest neighbours (clamped at 1e-7, like
//! `distCUDA2`), opacity 0.1, identity rotation, and the point's colour as the SH DC term
//! (`(rgb - 0.5) / SH_C0`; grey without colours). SH degree 0, like semsplat's own
//! `init.ply`.

use anyhow::{bail, Result};

use super::gaussians::Gaussians;
use super::ply::PointCloud;

const SH_C0: f32 = 0.282_094_8;
const INIT_OPACITY: f32 = 0.1;
/// Smallest mean squared neighbour distance (distCUDA2's clamp in INRIA's code).
const MIN_DIST2: f64 = 1e-7;
const NEIGHBOURS: usize = 3;

/// Gaussians seeded from `cloud` (see the module docs).
pub fn gaussians_from_point_cloud(cloud: &PointCloud) -> Result<Gaussians> {
    let n = cloud.points.len();
    if n == 0 {
        bail!("the point cloud has no points");
    }
    if let Some(bad) = cloud
        .points
        .iter()
        .position(|p| p.iter().any(|v| !v.is_finite()))
    {
        bail!(
            "point {bad} of the point cloud is not finite: {:?}",
            cloud.points[bad]
        );
    }
    let tree = KdTree::new(&cloud.points);
    let opacity = (INIT_OPACITY / (1.0 - INIT_OPACITY)).ln();
    let mut g = Gaussians {
        opacity_logits: vec![opacity; n],
        quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
        sh_degree: 0,
        ..Default::default()
    };
    for (i, p) in cloud.points.iter().enumerate() {
        let d2 = tree.mean_nearest_dist2(i, NEIGHBOURS).max(MIN_DIST2);
        g.means.push(*p);
        g.log_scales.push([(0.5 * d2.ln()) as f32; 3]);
        let rgb = cloud.colours.as_ref().map_or([0.5; 3], |c| c[i]);
        g.sh.extend(rgb.map(|v| (v - 0.5) / SH_C0));
    }
    Ok(g)
}

/// A 3-d tree over point indices (median splits on the widest axis), for nearest neighbours.
struct KdTree<'a> {
    points: &'a [[f32; 3]],
    /// Implicit tree: the node of `order[lo..hi]` is `order[(lo + hi) / 2]`, split on `axis`.
    order: Vec<usize>,
    axis: Vec<u8>,
}

impl<'a> KdTree<'a> {
    fn new(points: &'a [[f32; 3]]) -> Self {
        let mut tree = KdTree {
            points,
            order: (0..points.len()).collect(),
            axis: vec![0; points.len()],
        };
        tree.build(0, points.len());
        tree
    }

    fn build(&mut self, lo: usize, hi: usize) {
        if hi - lo <= 1 {
            return;
        }
        let pts = self.points;
        let extent = |a: usize| {
            let vals = self.order[lo..hi].iter().map(|&i| pts[i][a]);
            let (mn, mx) = vals.fold((f32::MAX, f32::MIN), |(mn, mx), v| (mn.min(v), mx.max(v)));
            mx - mn
        };
        let axis = (0..3)
            .max_by(|&a, &b| extent(a).total_cmp(&extent(b)))
            .unwrap();
        let mid = (lo + hi) / 2;
        self.order[lo..hi]
            .select_nth_unstable_by(mid - lo, |&a, &b| pts[a][axis].total_cmp(&pts[b][axis]));
        self.axis[mid] = axis as u8;
        self.build(lo, mid);
        self.build(mid + 1, hi);
    }

    /// Mean squared distance from point `i` to its `k` nearest other points (fewer when the
    /// cloud is smaller; 0 for a single point).
    fn mean_nearest_dist2(&self, i: usize, k: usize) -> f64 {
        let mut best: Vec<f64> = Vec::with_capacity(k + 1);
        self.search(0, self.order.len(), i, k, &mut best);
        if best.is_empty() {
            return 0.0;
        }
        best.iter().sum::<f64>() / best.len() as f64
    }

    fn search(&self, lo: usize, hi: usize, i: usize, k: usize, best: &mut Vec<f64>) {
        if lo >= hi {
            return;
        }
        let mid = (lo + hi) / 2;
        let node = self.order[mid];
        let (q, p) = (self.points[i], self.points[node]);
        if node != i {
            let d2: f64 = (0..3).map(|a| ((q[a] - p[a]) as f64).powi(2)).sum();
            if best.len() < k || d2 < best[best.len() - 1] {
                let at = best.partition_point(|&b| b <= d2);
                best.insert(at, d2);
                best.truncate(k);
            }
        }
        let axis = self.axis[mid] as usize;
        let diff = (q[axis] - p[axis]) as f64;
        let (near, far) = if diff < 0.0 {
            ((lo, mid), (mid + 1, hi))
        } else {
            ((mid + 1, hi), (lo, mid))
        };
        self.search(near.0, near.1, i, k, best);
        if best.len() < k || diff * diff < best[best.len() - 1] {
            self.search(far.0, far.1, i, k, best);
        }
    }
}
