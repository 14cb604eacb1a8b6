//! Label-noise models imitating a 2D segmenter, applied to the true label maps: per-frame
//! flicker, consistent mislabeling of chosen objects, boundary warp, salt-and-pepper pixels and
//! missing (ignore) blobs. Seeded per view, so results do not depend on thread scheduling.
//! Everything applied is recorded and measured in a `NoiseReport` (labels_noisy/noise.json).

use serde::Serialize;

use super::noise_spec::NoiseSpec;
use super::raycast::{ViewTruth, IGNORE};
use super::room::Room;
use crate::scene::{Camera, Split};
use crate::util::Rng;

const NOISE_STREAM: u64 = 0x4E01_5E00;
/// Missing blobs: radii as a fraction of the smaller image side.
const BLOB_MIN: f64 = 0.03;
const BLOB_MAX: f64 = 0.15;
const MAX_BLOBS: usize = 20_000;

/// Noisy label maps (one per view, same order) and what was done to them.
#[derive(Clone, Debug, PartialEq)]
pub struct NoisyLabels {
    pub maps: Vec<Vec<u16>>,
    pub report: NoiseReport,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NoiseReport {
    /// The canonical spec string.
    pub spec: String,
    pub requested: NoiseSpec,
    /// The seed the noise streams were drawn from.
    pub seed: u64,
    pub consistent: Vec<ConsistentMislabel>,
    pub measured: MeasuredNoise,
    pub views: Vec<ViewNoise>,
}

/// An object given the same wrong class in a chosen fraction of the views that see it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ConsistentMislabel {
    pub instance: u32,
    pub instance_name: String,
    pub true_class: u32,
    pub true_class_name: String,
    pub wrong_class: u32,
    pub wrong_class_name: String,
    /// Train views in which the object covers at least one pixel (held-out views keep its
    /// true class).
    pub views_visible: usize,
    pub views_wrong: usize,
    pub rate: f64,
    pub wrong_views: Vec<String>,
}

/// A count out of a total and their ratio.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Rate {
    pub count: u64,
    pub total: u64,
    pub rate: f64,
}

impl Rate {
    fn new(count: u64, total: u64) -> Self {
        Rate {
            count,
            total,
            rate: if total == 0 {
                0.0
            } else {
                count as f64 / total as f64
            },
        }
    }
}

/// Rates measured on the output.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MeasuredNoise {
    /// Relabeled (view, visible object) pairs out of the eligible ones.
    pub flicker: Rate,
    /// Views where a consistent object is wrong, out of the views that see it (all objects).
    pub consistent: Rate,
    /// Pixels changed by the boundary warp, out of all pixels.
    pub boundary: Rate,
    /// Pixels set to a random class, out of all pixels.
    pub salt: Rate,
    /// Pixels covered by missing blobs, out of all pixels.
    pub missing: Rate,
}

/// What happened in one view.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ViewNoise {
    pub name: String,
    /// `[instance, new class]` pairs relabeled by flicker.
    pub flickered: Vec<[u32; 2]>,
    /// Consistently mislabeled instances wrong in this view.
    pub consistent: Vec<u32>,
    pub boundary_pixels: u64,
    pub salt_pixels: u64,
    pub missing_pixels: u64,
}

/// Pixel counts per instance for each view.
pub fn instance_pixel_counts(room: &Room, views: &[ViewTruth]) -> Vec<Vec<u32>> {
    views
        .iter()
        .map(|v| {
            let mut counts = vec![0u32; room.instances.len()];
            for &i in &v.instances {
                if let Some(c) = counts.get_mut(i as usize) {
                    *c += 1;
                }
            }
            counts
        })
        .collect()
}

/// Applies `spec` to every view's true labels. `scene_seed` is used unless the spec has a seed.
pub fn apply_noise(
    room: &Room,
    cameras: &[Camera],
    views: &[ViewTruth],
    spec: &NoiseSpec,
    scene_seed: u64,
) -> NoisyLabels {
    let seed = spec.seed.unwrap_or(scene_seed);
    let rng = Rng::new(seed).fork(NOISE_STREAM);
    let counts = instance_pixel_counts(room, views);
    let consistent = choose_consistent(room, cameras, &counts, spec, &mut rng.fork(0));
    let class_count = room.classes.classes.len() as u64;

    let mut maps = Vec::with_capacity(views.len());
    let mut reports = Vec::with_capacity(views.len());
    let mut tally = Tally::default();
    for (v, view) in views.iter().enumerate() {
        let mut rng = rng.fork(1 + v as u64);
        let mut report = ViewNoise {
            name: cameras[v].name.clone(),
            ..Default::default()
        };
        let class_of = view_classes(
            room,
            &counts[v],
            &consistent,
            spec.flicker,
            &mut rng,
            &mut report,
            &mut tally,
        );
        let mut labels: Vec<u16> = view
            .instances
            .iter()
            .map(|&i| {
                if i == IGNORE {
                    IGNORE
                } else {
                    class_of[i as usize]
                }
            })
            .collect();
        apply_pixel_noise(&mut labels, view, spec, class_count, &mut rng, &mut report);
        tally.add_view(labels.len() as u64, &report);
        maps.push(labels);
        reports.push(report);
    }
    let measured = tally.measured(&consistent);
    let report = NoiseReport {
        spec: spec.to_string(),
        requested: spec.clone(),
        seed,
        consistent,
        measured,
        views: reports,
    };
    NoisyLabels { maps, report }
}

/// Totals over the views, for the measured rates.
#[derive(Default)]
struct Tally {
    flicker_events: u64,
    /// (view, visible object) pairs flicker could relabel.
    flicker_pairs: u64,
    pixels: u64,
    boundary: u64,
    salt: u64,
    missing: u64,
}

impl Tally {
    fn add_view(&mut self, pixels: u64, report: &ViewNoise) {
        self.pixels += pixels;
        self.boundary += report.boundary_pixels;
        self.salt += report.salt_pixels;
        self.missing += report.missing_pixels;
    }

    fn measured(&self, consistent: &[ConsistentMislabel]) -> MeasuredNoise {
        let (wrong, visible) = consistent.iter().fold((0, 0), |(w, t), c| {
            (w + c.views_wrong as u64, t + c.views_visible as u64)
        });
        MeasuredNoise {
            flicker: Rate::new(self.flicker_events, self.flicker_pairs),
            consistent: Rate::new(wrong, visible),
            boundary: Rate::new(self.boundary, self.pixels),
            salt: Rate::new(self.salt, self.pixels),
            missing: Rate::new(self.missing, self.pixels),
        }
    }
}

/// Step 1, per-object class for one view: consistent mislabels, then flicker (with
/// probability `flicker` among the object's confusions). `counts`: the view's pixels per
/// instance.
fn view_classes(
    room: &Room,
    counts: &[u32],
    consistent: &[ConsistentMislabel],
    flicker: f64,
    rng: &mut Rng,
    report: &mut ViewNoise,
    tally: &mut Tally,
) -> Vec<u16> {
    let mut class_of: Vec<u16> = room.instances.iter().map(|i| i.class_id as u16).collect();
    for c in consistent {
        if c.wrong_views.contains(&report.name) {
            class_of[c.instance as usize] = c.wrong_class as u16;
            report.consistent.push(c.instance);
        }
    }
    for inst in &room.instances {
        // Draw for every instance so streams do not depend on visibility.
        let (u, pick) = (rng.f64(), rng.next_u64());
        let exempt = consistent.iter().any(|c| c.instance == inst.id);
        if counts[inst.id as usize] == 0 || exempt {
            continue;
        }
        tally.flicker_pairs += 1;
        let options = room.confusions.for_class(inst.class_id as usize);
        if u < flicker && !options.is_empty() {
            let class = options[(pick % options.len() as u64) as usize];
            class_of[inst.id as usize] = class as u16;
            report.flickered.push([inst.id, class]);
            tally.flicker_events += 1;
        }
    }
    class_of
}

/// Steps 2-4 on one view's labels: boundary warp, salt, missing blobs; the pixel counts go
/// into `report`.
fn apply_pixel_noise(
    labels: &mut [u16],
    view: &ViewTruth,
    spec: &NoiseSpec,
    class_count: u64,
    rng: &mut Rng,
    report: &mut ViewNoise,
) {
    if spec.boundary > 0 {
        report.boundary_pixels =
            warp_boundaries(labels, view.width, view.height, spec.boundary, rng);
    }
    if spec.salt > 0.0 && class_count > 1 {
        report.salt_pixels = salt_labels(labels, class_count, spec.salt, rng);
    }
    if spec.missing > 0.0 {
        report.missing_pixels = drop_blobs(labels, view.width, view.height, spec.missing, rng);
    }
}

/// Sets each pixel with probability `rate` to a different random class (an ignored pixel to
/// any class); returns how many were set.
fn salt_labels(labels: &mut [u16], class_count: u64, rate: f64, rng: &mut Rng) -> u64 {
    let mut salted = 0;
    for l in labels.iter_mut() {
        if rng.f64() < rate {
            let r = rng.below(if *l == IGNORE {
                class_count
            } else {
                class_count - 1
            }) as u16;
            // Skip over the current class so every salted pixel changes.
            *l = if *l != IGNORE && r >= *l { r + 1 } else { r };
            salted += 1;
        }
    }
    salted
}

/// Picks `spec.consistent_objects` objects among the most widely visible ones and the views in
/// which each is wrong (exactly round(q * visible views) of them).
fn choose_consistent(
    room: &Room,
    cameras: &[Camera],
    counts: &[Vec<u32>],
    spec: &NoiseSpec,
    rng: &mut Rng,
) -> Vec<ConsistentMislabel> {
    if spec.consistent <= 0.0 {
        return Vec::new();
    }
    // The train views: the rate is of the views a method lifts from (held-out views are
    // scored against the true labels, so mislabeling them would only make the rate a lie).
    let visible_views = |id: u32| -> Vec<usize> {
        (0..counts.len())
            .filter(|&v| cameras[v].split == Split::Train && counts[v][id as usize] > 0)
            .collect()
    };
    let mut candidates: Vec<(usize, u32)> = room
        .instances
        .iter()
        .filter(|i| !i.structural && !room.confusions.for_class(i.class_id as usize).is_empty())
        .map(|i| (visible_views(i.id).len(), i.id))
        .filter(|(n, _)| *n > 0)
        .collect();
    candidates.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    // Choose among the most visible objects so the rate is measured over many views.
    let pool_size = (4 * spec.consistent_objects).max(6).min(candidates.len());
    let mut pool: Vec<u32> = candidates[..pool_size].iter().map(|c| c.1).collect();
    let mut chosen = Vec::new();
    while chosen.len() < spec.consistent_objects && !pool.is_empty() {
        let id = pool.swap_remove(rng.below(pool.len() as u64) as usize);
        let inst = &room.instances[id as usize];
        let options = room.confusions.for_class(inst.class_id as usize);
        let wrong_class = options[rng.below(options.len() as u64) as usize];
        let mut views = visible_views(id);
        let wrong = wrong_view_count(spec.consistent, views.len());
        // Partial Fisher-Yates: the first `wrong` entries become a uniform random subset.
        for k in 0..wrong.min(views.len()) {
            let j = k + rng.below((views.len() - k) as u64) as usize;
            views.swap(k, j);
        }
        let mut wrong_views: Vec<usize> = views[..wrong].to_vec();
        wrong_views.sort_unstable();
        chosen.push(ConsistentMislabel {
            instance: id,
            instance_name: inst.name.clone(),
            true_class: inst.class_id,
            true_class_name: room.class_name(inst.class_id).to_string(),
            wrong_class,
            wrong_class_name: room.class_name(wrong_class).to_string(),
            views_visible: views.len(),
            views_wrong: wrong,
            rate: if views.is_empty() {
                0.0
            } else {
                wrong as f64 / views.len() as f64
            },
            wrong_views: wrong_views
                .iter()
                .map(|&v| cameras[v].name.clone())
                .collect(),
        });
    }
    chosen
}

/// How many of an object's `views` `consistent=rate` mislabels: the nearest whole number,
/// on the rate's side of half (0.6 of 4 views is 3, not a tie of 2: above half is the
/// majority-wrong case; 0.4 of 2 is none, not a tie) and at least one where that stays
/// below half (0.1 of 4 is 1: a rate above 0 mislabels).
fn wrong_view_count(rate: f64, views: usize) -> usize {
    let nearest = (rate * views as f64).round() as usize;
    let (over_half, under_half) = (views / 2 + 1, views.div_ceil(2).saturating_sub(1));
    match rate {
        r if r > 0.5 => nearest.max(over_half).min(views),
        r if r < 0.5 && r > 0.0 => nearest.clamp(1.min(under_half), under_half),
        _ => nearest,
    }
}

/// Smooth value noise in [-1, 1] on a lattice of `cell` pixels.
struct NoiseField {
    cols: usize,
    cell: f64,
    values: Vec<f64>,
}

impl NoiseField {
    fn new(width: u32, height: u32, cell: f64, rng: &mut Rng) -> Self {
        let cols = (width as f64 / cell).ceil() as usize + 2;
        let rows = (height as f64 / cell).ceil() as usize + 2;
        NoiseField {
            cols,
            cell,
            values: (0..cols * rows).map(|_| rng.range_f64(-1.0, 1.0)).collect(),
        }
    }

    fn at(&self, x: f64, y: f64) -> f64 {
        let (gx, gy) = (x / self.cell, y / self.cell);
        let (ix, iy) = (gx.floor() as usize, gy.floor() as usize);
        let s = |t: f64| t * t * (3.0 - 2.0 * t);
        let (fx, fy) = (s(gx - ix as f64), s(gy - iy as f64));
        let v = |cx: usize, cy: usize| self.values[cy * self.cols + cx];
        let top = v(ix, iy) * (1.0 - fx) + v(ix + 1, iy) * fx;
        let bottom = v(ix, iy + 1) * (1.0 - fx) + v(ix + 1, iy + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Moves label edges by a smooth random displacement of at most `k` px per axis: each pixel
/// takes the label found at its displaced position. A pixel can change only if a different
/// label lies within `k` px (Chebyshev), i.e. near an edge. Returns the changed pixel count.
fn warp_boundaries(labels: &mut [u16], width: u32, height: u32, k: u32, rng: &mut Rng) -> u64 {
    let cell = (4.0 * k as f64).max(8.0);
    let fx = NoiseField::new(width, height, cell, rng);
    let fy = NoiseField::new(width, height, cell, rng);
    let src = labels.to_vec();
    let (w, h, kf) = (width as i64, height as i64, k as f64);
    let mut changed = 0;
    for y in 0..h {
        for x in 0..w {
            let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
            // Interpolated noise rarely reaches +-1; the gain lets shifts use the full range.
            let dx = (1.6 * kf * fx.at(px, py)).round().clamp(-kf, kf) as i64;
            let dy = (1.6 * kf * fy.at(px, py)).round().clamp(-kf, kf) as i64;
            let (sx, sy) = ((x + dx).clamp(0, w - 1), (y + dy).clamp(0, h - 1));
            let i = (y * w + x) as usize;
            let l = src[(sy * w + sx) as usize];
            if l != src[i] {
                labels[i] = l;
                changed += 1;
            }
        }
    }
    changed
}

/// Sets random elliptical blobs to `IGNORE` until exactly round(m * pixels) are covered
/// (the last blob is cut short). Returns the covered pixel count.
fn drop_blobs(labels: &mut [u16], width: u32, height: u32, m: f64, rng: &mut Rng) -> u64 {
    let n = labels.len();
    let target = ((m * n as f64).round() as usize).min(n);
    let mut missing = vec![false; n];
    let mut covered = 0;
    let side = width.min(height) as f64;
    let (w, h) = (width as i64, height as i64);
    for _ in 0..MAX_BLOBS {
        if covered >= target {
            break;
        }
        let (cx, cy) = (
            rng.range_f64(0.0, width as f64),
            rng.range_f64(0.0, height as f64),
        );
        let ra = rng.range_f64(BLOB_MIN, BLOB_MAX) * side + 1.0;
        let rb = rng.range_f64(BLOB_MIN, BLOB_MAX) * side + 1.0;
        let angle = rng.range_f64(0.0, std::f64::consts::PI);
        let (sin, cos) = angle.sin_cos();
        let r = ra.max(rb);
        let (x0, x1) = (
            ((cx - r).floor() as i64).max(0),
            ((cx + r).ceil() as i64).min(w - 1),
        );
        let (y0, y1) = (
            ((cy - r).floor() as i64).max(0),
            ((cy + r).ceil() as i64).min(h - 1),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
                let (u, v) = (dx * cos + dy * sin, -dx * sin + dy * cos);
                let i = (y * w + x) as usize;
                if (u / ra).powi(2) + (v / rb).powi(2) <= 1.0 && !missing[i] && covered < target {
                    missing[i] = true;
                    covered += 1;
                }
            }
        }
    }
    // Only reachable for rates near 1: finish in scan order.
    for flag in missing.iter_mut() {
        if covered >= target {
            break;
        }
        if !*flag {
            *flag = true;
            covered += 1;
        }
    }
    for (l, &gone) in labels.iter_mut().zip(&missing) {
        if gone {
            *l = IGNORE;
        }
    }
    covered as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The count keeps to the rate's side of half, and a rate above 0 mislabels a view where
    /// one stays below half.
    #[test]
    fn wrong_view_counts_keep_the_rates_side_of_half() {
        for (rate, views, wrong) in [
            (0.6, 4, 3),
            (0.51, 4, 3),
            (0.6, 60, 36),
            (0.6, 5, 3),
            (1.0, 4, 4),
            (0.5, 4, 2),
            (0.5, 5, 3),
            (0.4, 2, 0),
            (0.4, 3, 1),
            (0.1, 4, 1),
            (0.1, 1, 0),
            (0.3, 60, 18),
            (0.0, 10, 0),
            (0.9, 1, 1),
        ] {
            assert_eq!(wrong_view_count(rate, views), wrong, "{rate} of {views}");
        }
    }

    #[test]
    fn boundary_warp_only_changes_pixels_near_edges() {
        let (w, h) = (80u32, 60u32);
        let mut labels: Vec<u16> = (0..w * h)
            .map(|i| if (i % w) < 40 { 1 } else { 2 })
            .collect();
        let original = labels.clone();
        let changed = warp_boundaries(&mut labels, w, h, 3, &mut Rng::new(1));
        assert!(changed > 0);
        for (i, (&a, &b)) in original.iter().zip(&labels).enumerate() {
            if a != b {
                let x = (i as u32 % w) as i64;
                assert!(
                    (x - 40).abs() <= 3 || (x - 39).abs() <= 3,
                    "pixel {x} changed"
                );
            }
        }
    }

    #[test]
    fn blobs_cover_exactly_the_requested_fraction() {
        for m in [0.0, 0.05, 0.3, 1.0] {
            let mut labels = vec![3u16; 64 * 48];
            let covered = drop_blobs(&mut labels, 64, 48, m, &mut Rng::new(2));
            let ignored = labels.iter().filter(|&&l| l == IGNORE).count();
            assert_eq!(covered as usize, ignored);
            assert_eq!(ignored, (m * 64.0 * 48.0).round() as usize);
        }
    }
}
