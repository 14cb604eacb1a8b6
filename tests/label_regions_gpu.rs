//! Connected label regions on the GPU (src/fuse/regions_gpu.rs) against a flood fill
//! written independently (tests/common/regions.rs): region ids, edges, and the check that
//! would send an incomplete view to the host.

mod common;

use common::regions::{flood_regions, on_edge};
use common::{check_validation, gpu};
use semsplat::contract::REGION_EDGE_BIT;
use semsplat::fuse::regions_gpu::{regions_on_host, Observed, RegionFinder};
use semsplat::fuse::NO_LABEL;
use semsplat::util::Rng;

/// Per center pixel (NO_LABEL: none): the flood fill's region id, with REGION_EDGE_BIT
/// where the pixel is on its region's edge; NO_LABEL where unlabeled.
fn expected(map: &[u32], width: usize, centers: &[u32]) -> Vec<u32> {
    let regions = flood_regions(map, width);
    centers
        .iter()
        .map(|&p| match p {
            NO_LABEL => NO_LABEL,
            p if regions[p as usize] == NO_LABEL => NO_LABEL,
            p => {
                let edge = on_edge(&regions, width, p as usize);
                regions[p as usize] | if edge { REGION_EDGE_BIT } else { 0 }
            }
        })
        .collect()
}

/// Rectangles of random labels (0..classes, or unlabeled) painted over each other.
fn blocks(rng: &mut Rng, width: usize, height: usize, classes: u64) -> Vec<u32> {
    let mut map = vec![0u32; width * height];
    for _ in 0..(width * height / 40).max(3) {
        let (x0, y0) = (
            rng.below(width as u64) as usize,
            rng.below(height as u64) as usize,
        );
        let (w, h) = (1 + rng.below(12) as usize, 1 + rng.below(12) as usize);
        let label = match rng.below(classes + 1) {
            c if c == classes => NO_LABEL,
            c => c as u32,
        };
        for y in y0..(y0 + h).min(height) {
            for x in x0..(x0 + w).min(width) {
                map[y * width + x] = label;
            }
        }
    }
    map
}

/// One class winding through the image as a serpentine path one pixel wide, walls of
/// another between its rows: the region whose union spans the most of the image.
fn serpentine(width: usize, height: usize) -> Vec<u32> {
    let mut map = vec![1u32; width * height];
    for y in (0..height).step_by(2) {
        map[y * width..(y + 1) * width].fill(0);
        if y + 1 < height {
            // The opening to the next row alternates ends.
            let x = if y % 4 == 0 { width - 1 } else { 0 };
            map[(y + 1) * width + x] = 0;
        }
    }
    map
}

/// A segmenter's map: a few regions each spanning hundreds of pixels a row (a wall, a
/// floor), split by a slanted edge and columns, where a GPU's unions chain whole rows and the
/// finds' halving (glsl/fuse/label_regions.glsl) does most of its work.
fn wide_regions(width: usize, height: usize) -> Vec<u32> {
    (0..width * height)
        .map(|p| {
            let (x, y) = (p % width, p / width);
            let below_slant = y * width > x * height / 2 + width * height / 3;
            (x * 3 / width) as u32 + if below_slant { 3 } else { 0 }
        })
        .collect()
}

/// Every map's observations from the GPU, for every pixel as a center plus a Gaussian with
/// none, then for random centers; the host fallback's regions too.
fn check_maps(maps: &[(String, Vec<u32>, usize)]) -> usize {
    let gpu = gpu();
    let largest = maps.iter().map(|m| m.1.len()).max().unwrap();
    let n = largest + 1;
    let mut finder = RegionFinder::new(gpu, n).unwrap();
    let centers_buf = gpu.buffer("test-centers", (n * 4) as u64).unwrap();
    let mut rng = Rng::new(5);
    for (name, map, width) in maps {
        let mut centers: Vec<u32> = (0..map.len() as u32).collect();
        centers.resize(n, NO_LABEL);
        assert_eq!(
            regions_on_host(map, *width, &centers),
            expected(map, *width, &centers),
            "{name}: the host fallback"
        );
        // The observations compacted on the GPU: every pixel a center (each labeled one
        // observed, with its region and edge), then centers drawn at random (repeated
        // pixels, gaps of none).
        check_observations(&mut finder, &centers_buf, name, map, *width, &centers);
        let random: Vec<u32> = (0..n)
            .map(|_| match rng.below(4) {
                0 => NO_LABEL,
                _ => rng.below(map.len() as u64) as u32,
            })
            .collect();
        check_observations(&mut finder, &centers_buf, name, map, *width, &random);
    }
    check_validation(gpu);
    finder.stats.host_fallbacks
}

/// [`RegionFinder::observations`] for Gaussians centered on `centers`: in Gaussian order,
/// each one on a labeled pixel with that pixel, its label and the flood fill's region
/// (edge bit included), and no other.
fn check_observations(
    finder: &mut RegionFinder,
    centers_buf: &semsplat::gpu::Buffer,
    name: &str,
    map: &[u32],
    width: usize,
    centers: &[u32],
) {
    gpu().upload(centers_buf, 0, centers).unwrap();
    let got = finder
        .observations(map, width as u32, centers_buf, |o| o.to_vec())
        .unwrap();
    let regions = expected(map, width, centers);
    let want: Vec<Observed> = (0..centers.len())
        .filter(|&g| regions[g] != NO_LABEL)
        .map(|g| Observed {
            gaussian: g as u32,
            pixel: centers[g],
            label: map[centers[g] as usize],
            region: regions[g],
        })
        .collect();
    assert!(
        !want.is_empty() || map.iter().all(|&l| l == NO_LABEL),
        "{name}"
    );
    assert_eq!(got.len(), want.len(), "{name}: observations");
    for (got, want) in got.iter().zip(&want) {
        assert_eq!(got, want, "{name} (edge bit {REGION_EDGE_BIT:#x})");
    }
}

#[test]
fn gpu_regions_match_a_flood_fill_on_random_maps() {
    let mut rng = Rng::new(16);
    let mut maps = Vec::new();
    for (i, &(w, h, classes)) in [(37, 23, 3), (64, 48, 2), (160, 120, 5), (300, 7, 1)]
        .iter()
        .enumerate()
    {
        maps.push((
            format!("blocks {i} ({w}x{h})"),
            blocks(&mut rng, w, h, classes),
            w,
        ));
    }
    maps.push(("one label".into(), vec![3; 50 * 40], 50));
    maps.push(("wide regions".into(), wide_regions(640, 360), 640));
    maps.push(("unlabeled".into(), vec![NO_LABEL; 30 * 20], 30));
    let checker: Vec<u32> = (0..33 * 17)
        .map(|p| ((p % 33) + (p / 33)) as u32 % 2)
        .collect();
    maps.push(("checkerboard".into(), checker, 33));
    let column = blocks(&mut rng, 1, 200, 2);
    maps.push(("one column".into(), column, 1));
    let row = blocks(&mut rng, 200, 1, 2);
    maps.push(("one row".into(), row, 200));
    // A broken union would be caught by the check and redone on the host: none may be.
    assert_eq!(check_maps(&maps), 0, "views the GPU left to the host");
}

#[test]
fn gpu_regions_match_a_flood_fill_on_a_serpentine() {
    let maps = [
        ("serpentine 64x64".to_string(), serpentine(64, 64), 64),
        ("serpentine 512x384".to_string(), serpentine(512, 384), 512),
    ];
    let fallbacks = check_maps(&maps);
    // Either way the regions are right; say whether the GPU finished them itself.
    println!(
        "serpentines redone on the host: {fallbacks} of {}",
        maps.len()
    );
}

/// The check that sends a view to the host: silent on complete regions, and set by an id
/// that is not its region's root, by a region split in two, and by an id of another label.
#[test]
fn region_check_flags_incomplete_regions() {
    let gpu = gpu();
    let mut rng = Rng::new(7);
    let width = 40;
    let map = blocks(&mut rng, width, 30, 3);
    let ids = flood_regions(&map, width);
    let mut finder = RegionFinder::new(gpu, 1).unwrap();
    assert!(finder.regions_complete(&map, width as u32, &ids).unwrap());

    // Pixel p of a region of at least two pixels, not its root.
    let p = (0..map.len())
        .find(|&p| ids[p] != NO_LABEL && ids[p] != p as u32)
        .expect("a region of two pixels");
    // Another pixel of that label that is no root either.
    let q = (0..map.len())
        .find(|&q| q != p && map[q] == map[p] && ids[q] != q as u32)
        .expect("another non-root pixel");
    let mut not_root = ids.clone();
    not_root[p] = q as u32;
    assert!(!finder
        .regions_complete(&map, width as u32, &not_root)
        .unwrap());

    // The region's root alone keeps its id; p is made a root of its own.
    let mut split = ids.clone();
    split[p] = p as u32;
    assert!(!finder.regions_complete(&map, width as u32, &split).unwrap());

    let other = (0..map.len())
        .find(|&q| ids[q] == q as u32 && map[q] != map[p])
        .expect("a root of another label");
    let mut wrong_label = ids.clone();
    wrong_label[p] = other as u32;
    assert!(!finder
        .regions_complete(&map, width as u32, &wrong_label)
        .unwrap());
    check_validation(gpu);
}

/// The GPU's union-find as an algorithm, under the concurrency lavapipe does not give (its
/// invocations run nearly in scan order, each left neighbour already joined): region_merge's
/// unions and find_root's path halving (glsl/fuse/label_regions.glsl) transcribed as tasks,
/// one per pixel, each pausing before every memory step; a scheduler resumes a task drawn
/// at random from those resident (started in pixel order, as a GPU starts its workgroups),
/// so the steps of hundreds of tasks interleave, deterministically for a seed. Every
/// interleaving must give the flood fill's ids: a link only ever moves to a smaller pixel of
/// its region, and a union whose root was linked meanwhile goes on from there.
mod concurrent_model {
    use super::*;
    use std::cell::Cell;
    use std::future::Future;
    use std::pin::Pin;
    use std::task::{Context, Poll, Waker};

    /// Where a task stops so the scheduler can run another: once, before a memory step.
    struct Pause(bool);

    impl Future for Pause {
        type Output = ();
        fn poll(mut self: Pin<&mut Self>, _: &mut Context) -> Poll<()> {
            match std::mem::replace(&mut self.0, true) {
                true => Poll::Ready(()),
                false => Poll::Pending,
            }
        }
    }

    struct Links(Vec<Cell<u32>>);

    impl Links {
        async fn read(&self, p: u32) -> u32 {
            Pause(false).await;
            self.0[p as usize].get()
        }

        /// atomicMin: the link before.
        async fn lower(&self, p: u32, to: u32) -> u32 {
            Pause(false).await;
            let was = self.0[p as usize].get();
            self.0[p as usize].set(was.min(to));
            was
        }

        async fn find_root(&self, mut p: u32) -> u32 {
            let mut up = self.read(p).await;
            while up != p {
                let upup = self.read(up).await;
                if upup != up {
                    self.lower(p, upup).await;
                }
                p = upup;
                up = self.read(p).await;
            }
            p
        }

        async fn join(&self, mut a: u32, mut b: u32) {
            loop {
                a = self.find_root(a).await;
                b = self.find_root(b).await;
                if a == b {
                    return;
                }
                let (hi, lo) = (a.max(b), a.min(b));
                let was = self.lower(hi, lo).await;
                if was == hi {
                    return;
                }
                (a, b) = (was, lo);
            }
        }
    }

    type Task<'a> = Pin<Box<dyn Future<Output = ()> + 'a>>;

    /// Runs `tasks` to the end, `resident` at a time, one step of a random one at a time.
    fn run(tasks: Vec<Task>, resident: usize, rng: &mut Rng) {
        let mut cx = Context::from_waker(Waker::noop());
        let (mut waiting, mut live) = (tasks.into_iter(), Vec::new());
        loop {
            live.extend(waiting.by_ref().take(resident - live.len()));
            if live.is_empty() {
                return;
            }
            let i = rng.below(live.len() as u64) as usize;
            if live[i].as_mut().poll(&mut cx).is_ready() {
                drop(live.swap_remove(i));
            }
        }
    }

    fn regions(map: &[u32], width: usize, resident: usize, seed: u64) -> Vec<u32> {
        let links = Links(
            map.iter()
                .enumerate()
                .map(|(p, &l)| Cell::new(if l == NO_LABEL { NO_LABEL } else { p as u32 }))
                .collect(),
        );
        let labeled = || (0..map.len()).filter(|&p| map[p] != NO_LABEL);
        let mut rng = Rng::new(seed);
        let links = &links;
        let merges = labeled().map(|p| -> Task {
            Box::pin(async move {
                if p % width > 0 && map[p - 1] == map[p] {
                    links.join(p as u32, p as u32 - 1).await;
                }
                if p >= width && map[p - width] == map[p] {
                    links.join(p as u32, (p - width) as u32).await;
                }
            })
        });
        run(merges.collect(), resident, &mut rng);
        let region: Vec<Cell<u32>> = map.iter().map(|_| Cell::new(NO_LABEL)).collect();
        let region = &region;
        let flattens = labeled().map(|p| -> Task {
            Box::pin(async move { region[p].set(links.find_root(p as u32).await) })
        });
        run(flattens.collect(), resident, &mut rng);
        region.iter().map(Cell::get).collect()
    }

    #[test]
    fn unions_with_halving_give_the_flood_fills_ids_in_any_interleaving() {
        let mut rng = Rng::new(23);
        let maps = [
            ("wide regions", wide_regions(120, 60), 120),
            ("serpentine", serpentine(32, 24), 32),
            ("blocks", blocks(&mut rng, 48, 36, 3), 48),
            ("one label", vec![2; 60 * 20], 60),
        ];
        for (name, map, width) in &maps {
            let want = flood_regions(map, *width);
            for (resident, seed) in [(32, 1), (512, 2), (4096, 3)] {
                let got = regions(map, *width, resident, seed);
                assert!(got == want, "{name}: {resident} resident, seed {seed}");
            }
        }
    }
}
