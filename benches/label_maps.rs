//! Criterion: reading one 1920x1080 label map as fusion does (decoded, checked, its ids
//! made compact class indices), wall time, for the three forms a segmenter writes: 8-bit
//! gray ids (the common case, read a byte an id), 16-bit gray ids and a colour-coded RGB map
//! (read pixel by pixel). Fusion reads one map per view on worker threads while the GPU
//! runs the views before it; on a GPU a view takes a few milliseconds, so this is what keeps
//! it waiting or not.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use semsplat::dataset::CompactClasses;
use semsplat::scene::classes::ClassTable;
use semsplat::scene::labels::{
    read_label_png_as, write_label_png, write_palette_png, LabelFormat, LabelMap,
};

const W: u32 = 1920;
const H: u32 = 1080;

/// Blocks of 40x40 pixels with ids from `ids`, like a segmenter's regions.
fn blocks(ids: &[u16]) -> LabelMap {
    let labels = (0..W * H)
        .map(|i| {
            let (x, y) = (i % W / 40, i / W / 40);
            ids[((x * 7 + y * 13) % ids.len() as u32) as usize]
        })
        .collect();
    LabelMap::new(W, H, labels).expect("a whole map")
}

fn label_maps(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let small: Vec<u16> = (0..20).collect();
    let wide: Vec<u16> = (0..20).map(|i| 300 + 50 * i).collect();
    let table = ClassTable::from_ids(small.iter().map(|&i| u32::from(i)));
    let gray8 = dir.path().join("gray8.png");
    let gray16 = dir.path().join("gray16.png");
    let rgb = dir.path().join("rgb.png");
    write_label_png(&gray8, &blocks(&small)).expect("written");
    write_label_png(&gray16, &blocks(&wide)).expect("written");
    write_palette_png(&rgb, &blocks(&small), &table).expect("written");
    let mut group = c.benchmark_group("label_map_1080p");
    group.sample_size(20);
    group.throughput(Throughput::Elements(u64::from(W * H)));
    let format = LabelFormat::default();
    for (name, path, ids, given) in [
        ("gray8", &gray8, &small, None),
        ("gray16", &gray16, &wide, None),
        ("rgb_colour_coded", &rgb, &small, Some(&table)),
    ] {
        let classes = CompactClasses::from_ids(ids.iter().map(|&i| u32::from(i))).expect("ids");
        group.bench_function(BenchmarkId::from_parameter(name), |b| {
            b.iter(|| {
                let map = read_label_png_as(path, &format, given).expect("a label map");
                classes.compact_labels(&map.labels)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, label_maps);
criterion_main!(benches);
