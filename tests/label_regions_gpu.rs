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
