//! Label maps and images in the forms other tools write them: palette PNGs (VOC, DAVIS,
//! XMem: the index is the class id), colour-coded RGB through the class table, 3-channel
//! gray, gray+alpha, sub-byte gray; `--ignore-id` and the binary-mask warning; labels at
//! another resolution than the cameras; rig subfolders; huge headers refused before
//! decoding; JPEG images; eval with ids above 16 bits and named classes.

mod common;

use common::cli::{arg_in, ok, read_json, semsplat};

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3};
use semsplat::dataset::{Dataset, DatasetPaths};
use semsplat::scene::cameras_json::write_semsplat_cameras;
use semsplat::scene::classes::{write_class_table, ClassInfo, ClassTable};
use semsplat::scene::images::load_view_image;
use semsplat::scene::labels::{
    label_size_fit, read_label_png, read_label_png_as, LabelDir, LabelFormat, LabelMap,
    MissingLabels, SizeFit,
};
use semsplat::scene::ply::{read_ply, write_ply};
use semsplat::scene::{Camera, Split};

const IGN: u16 = LabelMap::IGNORE;

/// Writes a PNG the way other tools do, with the `png` crate (no conversion on our side).
fn write_png(
    path: &Path,
    (w, h): (u32, u32),
    color: png::ColorType,
    depth: png::BitDepth,
    palette: Option<Vec<u8>>,
    data: &[u8],
) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let file = std::fs::File::create(path).unwrap();
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(color);
    enc.set_depth(depth);
    if let Some(p) = palette {
        enc.set_palette(p);
    }
    enc.write_header().unwrap().write_image_data(data).unwrap();
}

/// A VOC-style 256-entry palette (bit-interleaved colours, so index i is not colour i).
fn voc_palette() -> Vec<u8> {
    let mut pal = Vec::with_capacity(768);
    for i in 0..256u32 {
        let (mut r, mut g, mut b, mut c) = (0u8, 0u8, 0u8, i);
        for j in 0..8 {
            r |= ((c & 1) as u8) << (7 - j);
            g |= (((c >> 1) & 1) as u8) << (7 - j);
            b |= (((c >> 2) & 1) as u8) << (7 - j);
            c >>= 3;
        }
        pal.extend([r, g, b]);
    }
    pal
}

fn camera(name: &str, (w, h): (u32, u32)) -> Camera {
    Camera {
        name: name.into(),
        width: w,
        height: h,
        fx: w as f64,
        fy: w as f64,
        cx: w as f64 / 2.0,
        cy: h as f64 / 2.0,
        rotation: DMat3::IDENTITY,
        translation: DVec3::new(0.0, 0.0, 3.0),
        split: Split::Train,
    }
}

fn err<T>(r: anyhow::Result<T>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn palette_pngs_give_their_indices_not_their_colours() {
    let dir = tempfile::tempdir().unwrap();
    // 8-bit palette as VOC/DAVIS/XMem write it; 255 is VOC's "void" boundary.
    let p8 = dir.path().join("voc.png");
    write_png(
        &p8,
        (3, 2),
        png::ColorType::Indexed,
        png::BitDepth::Eight,
        Some(voc_palette()),
        &[0, 1, 2, 255, 7, 1],
    );
    assert_eq!(read_label_png(&p8).unwrap().labels, [0, 1, 2, IGN, 7, 1]);
    let zero_ignored = LabelFormat::with_ignore_id(Some(0));
    assert_eq!(
        read_label_png_as(&p8, &zero_ignored, None).unwrap().labels,
        [IGN, 1, 2, 255, 7, 1]
    );
    // 4-bit palette (PIL writes small palettes with fewer bits): packed, rows padded.
    let p4 = dir.path().join("small.png");
    let palette: Vec<u8> = voc_palette()[..16 * 3].to_vec();
    write_png(
        &p4,
        (3, 2),
        png::ColorType::Indexed,
        png::BitDepth::Four,
        Some(palette),
        &[0x3A, 0x50, 0x0F, 0x10],
    );
    assert_eq!(read_label_png(&p4).unwrap().labels, [3, 10, 5, 0, 15, 1]);
    // 1-bit gray (PIL mode "1" masks).
    let p1 = dir.path().join("mask.png");
    write_png(
        &p1,
        (10, 1),
        png::ColorType::Grayscale,
        png::BitDepth::One,
        None,
        &[0b1010_0000, 0b0100_0000],
    );
    assert_eq!(
        read_label_png(&p1).unwrap().labels,
        [1, 0, 1, 0, 0, 0, 0, 0, 0, 1]
    );
}

fn rgb_table() -> ClassTable {
    let class = |id, name: &str, color| ClassInfo {
        id,
        name: name.into(),
        color,
    };
    ClassTable {
        classes: vec![
            class(0, "road", [128, 64, 128]),
            class(1, "car", [0, 0, 142]),
            class(7, "building", [70, 70, 70]),
        ],
    }
}

/// A colour-coded map saved with a palette (PIL's `quantize`, an editor's indexed mode)
/// holds the table's colours at indices of its own: with the table, each index reads as
/// its colour's class (black: unlabeled). A palette whose colours are the table's at their
/// own ids, or that holds a colour no class has, reads by index as before.
#[test]
fn palette_pngs_of_the_tables_colours_at_other_indices_read_through_the_colours() {
    let dir = tempfile::tempdir().unwrap();
    let table = rgb_table();
    let colour = |id: u32| table.get(id).unwrap().color;
    let indexed = |name: &str, palette: Vec<[u8; 3]>, pixels: &[u8]| {
        let path = dir.path().join(name);
        let bytes = palette.into_iter().flatten().collect();
        write_png(
            &path,
            (3, 2),
            png::ColorType::Indexed,
            png::BitDepth::Eight,
            Some(bytes),
            pixels,
        );
        let as_ids = read_label_png(&path).unwrap().labels;
        let through_table = (read_label_png_as(&path, &LabelFormat::default(), Some(&table)))
            .unwrap()
            .labels;
        (as_ids, through_table)
    };
    // Quantized: building at index 0, black (no class's colour) at 1, road at 2, car at 3.
    let quantized = vec![colour(7), [0, 0, 0], colour(0), colour(1)];
    let (ids, classes) = indexed("quantized.png", quantized.clone(), &[0, 1, 2, 3, 3, 0]);
    assert_eq!(
        ids,
        [0, 1, 2, 3, 3, 0],
        "without a table the index is the id"
    );
    assert_eq!(classes, [7, IGN, 0, 1, 1, 7]);
    // The table's colours at their own ids: the same by index and by colour.
    let mut own = vec![[0, 0, 0]; 8];
    (own[0], own[1], own[7]) = (colour(0), colour(1), colour(7));
    let (ids, classes) = indexed("own.png", own, &[0, 1, 7, 7, 1, 0]);
    assert_eq!(
        (ids.as_slice(), classes.as_slice()),
        (&[0, 1, 7, 7, 1, 0][..], &ids[..])
    );
    // A used colour no class has: a palette of its own (DAVIS), read by index.
    let mut davis = quantized;
    davis[2] = [200, 0, 0];
    let (_, classes) = indexed("davis.png", davis, &[0, 2, 2, 3, 3, 0]);
    assert_eq!(classes, [0, 2, 2, 3, 3, 0]);
}

#[test]
fn colour_coded_maps_read_through_the_class_table() {
    let dir = tempfile::tempdir().unwrap();
    let table = rgb_table();
    let p = dir.path().join("city.png");
    #[rustfmt::skip]
    let rgb = [128, 64, 128,  0, 0, 142,  70, 70, 70,  0, 0, 0];
    write_png(
        &p,
        (2, 2),
        png::ColorType::Rgb,
        png::BitDepth::Eight,
        None,
        &rgb,
    );
    let format = LabelFormat::default();
    let map = read_label_png_as(&p, &format, Some(&table)).unwrap();
    // Black is no class's colour: unlabeled, as semsplat's own palette images write it.
    assert_eq!(map.labels, [0, 1, 7, IGN]);

    // A gray-only map whose grays are table colours but not table ids is colour-coded.
    let gray = dir.path().join("gray_coded.png");
    write_png(
        &gray,
        (2, 1),
        png::ColorType::Rgb,
        png::BitDepth::Eight,
        None,
        &[70, 70, 70, 70, 70, 70],
    );
    let map = read_label_png_as(&gray, &format, Some(&table)).unwrap();
    assert_eq!(map.labels, [7, 7]);

    // Runs of one colour (looked up once a run), across rows and around a transparent pixel.
    let runs = dir.path().join("runs.png");
    #[rustfmt::skip]
    let rgba = [
        128, 64, 128, 255,  128, 64, 128, 255,  0, 0, 142, 255,
        0, 0, 142, 255,     0, 0, 142, 0,       0, 0, 142, 255,
    ];
    write_png(
        &runs,
        (3, 2),
        png::ColorType::Rgba,
        png::BitDepth::Eight,
        None,
        &rgba,
    );
    let map = read_label_png_as(&runs, &format, Some(&table)).unwrap();
    assert_eq!(map.labels, [0, 0, 1, 1, IGN, 1]);

    // An unknown colour names itself, the pixel and the file.
    let bad = dir.path().join("bad.png");
    write_png(
        &bad,
        (2, 1),
        png::ColorType::Rgba,
        png::BitDepth::Eight,
        None,
        &[0, 0, 142, 255, 1, 2, 3, 255],
    );
    let e = err(read_label_png_as(&bad, &format, Some(&table)));
    assert!(
        e.contains("(1, 2, 3)") && e.contains("pixel (1, 0)") && e.contains("bad.png"),
        "{e}"
    );
    // Without a table, the error says a class table is needed.
    let e = err(read_label_png(&p));
    assert!(e.contains("class table") && e.contains("city.png"), "{e}");
}

#[test]
fn gray_rgb_and_gray_alpha_pngs_hold_ids() {
    let dir = tempfile::tempdir().unwrap();
    // A 3x1 RGB map of `pixels`, read with `table` (None: ids only).
    let read_rgb_3x1 = |name: &str, pixels: &[u8], table: Option<&ClassTable>| {
        let p = dir.path().join(name);
        write_png(
            &p,
            (3, 1),
            png::ColorType::Rgb,
            png::BitDepth::Eight,
            None,
            pixels,
        );
        read_label_png_as(&p, &LabelFormat::default(), table)
            .unwrap()
            .labels
    };
    let gray = [0, 0, 0, 3, 3, 3, 255, 255, 255];
    assert_eq!(read_rgb_3x1("rgb_gray.png", &gray, None), [0, 3, IGN]);
    // With a table listing those ids, they stay ids (not colours).
    let ids = ClassTable::from_ids([0, 3]);
    assert_eq!(read_rgb_3x1("rgb_gray.png", &gray, Some(&ids)), [0, 3, IGN]);

    // A colour-coded view showing only gray classes: ADE20K's wall is 120-120-120 while
    // its id 120 is a pot. Every gray but black being a class's colour, it reads by colour
    // (black, no class's colour, unlabeled); each map is decided on its own.
    let ade = ClassTable::from_json_str(
        r#"[{"id": 1, "name": "wall", "color": [120, 120, 120]},
            {"id": 120, "name": "pot", "color": [255, 31, 0]}]"#,
    )
    .unwrap();
    let wall_only = [120, 120, 120, 120, 120, 120, 0, 0, 0];
    assert_eq!(
        read_rgb_3x1("wall_only.png", &wall_only, Some(&ade)),
        [1, 1, IGN]
    );
    // A gray that is no class's colour keeps the map's values ids.
    let mixed = [120, 120, 120, 1, 1, 1, 0, 0, 0];
    assert_eq!(read_rgb_3x1("mixed.png", &mixed, Some(&ade)), [120, 1, 0]);

    // Gray + alpha: transparent pixels are unlabeled.
    let la = dir.path().join("la.png");
    write_png(
        &la,
        (3, 1),
        png::ColorType::GrayscaleAlpha,
        png::BitDepth::Eight,
        None,
        &[2, 255, 5, 0, 255, 255],
    );
    assert_eq!(read_label_png(&la).unwrap().labels, [2, IGN, IGN]);
    let la16 = dir.path().join("la16.png");
    write_png(
        &la16,
        (2, 1),
        png::ColorType::GrayscaleAlpha,
        png::BitDepth::Sixteen,
        None,
        &[0x03, 0xE8, 0xFF, 0xFF, 0x00, 0x07, 0x00, 0x00],
    );
    assert_eq!(read_label_png(&la16).unwrap().labels, [1000, IGN]);
}

/// A label folder with a cameras.json beside it; returns (cameras.json, labels folder).
fn dataset_dir(root: &Path, cams: &[Camera]) -> (PathBuf, PathBuf) {
    let cameras = root.join("cameras.json");
    write_semsplat_cameras(&cameras, cams).unwrap();
    let labels = root.join("labels");
    std::fs::create_dir_all(&labels).unwrap();
    (cameras, labels)
}

/// `labels/NAME.png`: a 4x3 8-bit gray map of `px`.
fn write_gray_4x3(labels: &Path, name: &str, px: &[u8]) {
    let p = labels.join(format!("{name}.png"));
    write_png(
        &p,
        (4, 3),
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
        None,
        px,
    );
}

fn open(cameras: &Path, labels: &Path, ignore_id: Option<u16>) -> anyhow::Result<Dataset> {
    Dataset::open(&DatasetPaths {
        cameras,
        labels,
        class_table: None,
        train_only: false,
        format: LabelFormat::with_ignore_id(ignore_id),
    })
}

#[test]
fn binary_masks_warn_and_ignore_id_keeps_the_object() {
    let dir = tempfile::tempdir().unwrap();
    let cams = [camera("a", (4, 3)), camera("b", (4, 3))];
    let (cameras, labels) = dataset_dir(dir.path(), &cams);
    // SAM-style masks: 0 background, 255 object.
    for (name, object) in [("a", 1usize), ("b", 6)] {
        let mut px = vec![0u8; 12];
        px[object] = 255;
        write_gray_4x3(&labels, name, &px);
    }
    let d = open(&cameras, &labels, None).unwrap();
    assert_eq!(d.classes.user_ids(), [0]);
    let warning = d.warnings.join("\n");
    assert!(
        warning.contains("only two values") && warning.contains("--ignore-id"),
        "{warning}"
    );
    // An ignore id the masks do not use keeps both values as classes, silently.
    let d = open(&cameras, &labels, Some(1000)).unwrap();
    assert_eq!(d.classes.user_ids(), [0, 255]);
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
    // ADE20K/ScanNet style: 0 ignored, 255 is a class (and the folder is still flagged).
    let d = open(&cameras, &labels, Some(0)).unwrap();
    assert_eq!(d.classes.user_ids(), [255]);
    assert_eq!(d.warnings.len(), 1);
    // Its remedy names an id that is neither of the two values (not the 0 given).
    assert!(
        d.warnings[0].contains("(e.g. --ignore-id 1000)"),
        "{}",
        d.warnings[0]
    );

    // An ignore id that is a class of the table is refused.
    write_class_table(
        &labels.join("classes.json"),
        &ClassTable::from_ids([0, 255]),
    )
    .unwrap();
    let e = err(open(&cameras, &labels, Some(0)));
    assert!(e.contains("--ignore-id 0") && e.contains("class_0"), "{e}");
    std::fs::remove_file(labels.join("classes.json")).unwrap();

    // inspect flags the folder as a problem (exit status 1), and --ignore-id validates.
    let out = semsplat(&["inspect", labels.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        !out.status.success() && stdout.contains("only two values"),
        "{stdout}"
    );
    let out = semsplat(&["inspect", labels.to_str().unwrap(), "--ignore-id", "1000"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let out = semsplat(&["inspect", labels.to_str().unwrap(), "--ignore-id", "70000"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("70000"),
        "{stderr}"
    );

    // Masks on a transparent background: no --ignore-id brings the background back, so the
    // warning names the alpha channel instead of suggesting one (which looped).
    for (name, object) in [("a", 1usize), ("b", 6)] {
        let mut px = vec![0u8; 24]; // gray + alpha: transparent black
        px[2 * object..2 * object + 2].copy_from_slice(&[255, 255]);
        let path = labels.join(format!("{name}.png"));
        let (color, depth) = (png::ColorType::GrayscaleAlpha, png::BitDepth::Eight);
        write_png(&path, (4, 3), color, depth, None, &px);
    }
    let d = open(&cameras, &labels, Some(1000)).unwrap();
    assert_eq!(d.classes.user_ids(), [255]);
    let warning = d.warnings.join("\n");
    assert!(
        warning.contains("alpha channel") && !warning.contains("--ignore-id 1"),
        "{warning}"
    );
}

/// Maps resized with bilinear filtering (a 2 between every 1 and 3) warn when a fusion or
/// training opens them, naming the id; the same maps resized with nearest neighbour do not.
#[test]
fn interpolated_label_maps_warn_naming_the_stepped_id() {
    let dir = tempfile::tempdir().unwrap();
    let cams = [camera("a", (8, 8)), camera("b", (8, 8))];
    let (cameras, labels) = dataset_dir(dir.path(), &cams);
    let gray_8x8 = |name: &str, row: [u8; 8]| {
        let (color, depth) = (png::ColorType::Grayscale, png::BitDepth::Eight);
        let path = labels.join(format!("{name}.png"));
        write_png(&path, (8, 8), color, depth, None, &row.repeat(8));
    };
    gray_8x8("a", [1, 1, 1, 2, 3, 3, 3, 3]);
    gray_8x8("b", [1, 1, 2, 2, 3, 3, 3, 3]);
    let d = open(&cameras, &labels, None).unwrap();
    let warning = d.warnings.join("\n");
    assert!(
        warning.contains("look resized with interpolation")
            && warning.contains("id 2 between 1 and 3"),
        "{warning}"
    );
    gray_8x8("a", [1, 1, 1, 1, 3, 3, 3, 3]);
    gray_8x8("b", [1, 1, 1, 3, 3, 3, 3, 3]);
    let d = open(&cameras, &labels, None).unwrap();
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
}

#[test]
fn labels_at_another_resolution_scale_the_intrinsics_or_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    // 4946x3286 / 8 rounds to 618x411 (3DGS's images_8): within a pixel of the ratio.
    let cams = [camera("a", (4946, 3286)), camera("b", (4946, 3286))];
    let (cameras, labels) = dataset_dir(dir.path(), &cams);
    for name in ["a", "b"] {
        let map = LabelMap::filled(618, 411, 2);
        semsplat::scene::labels::write_label_png(&labels.join(format!("{name}.png")), &map)
            .unwrap();
    }
    let d = open(&cameras, &labels, None).unwrap();
    let c = &d.cameras[0];
    assert_eq!((c.width, c.height), (618, 411));
    let (sx, sy) = (618.0 / 4946.0, 411.0 / 3286.0);
    assert!((c.fx - 4946.0 * sx).abs() < 1e-9 && (c.cx - 2473.0 * sx).abs() < 1e-9);
    assert!((c.fy - 4946.0 * sy).abs() < 1e-9 && (c.cy - 1643.0 * sy).abs() < 1e-9);
    assert_eq!(d.warnings.len(), 1, "said once: {:?}", d.warnings);
    assert!(d.warnings[0].contains("618x411") && d.warnings[0].contains("4946x3286"));

    // Another aspect ratio: a clear error naming both sizes.
    let map = LabelMap::filled(618, 300, 2);
    semsplat::scene::labels::write_label_png(&labels.join("b.png"), &map).unwrap();
    let e = err(open(&cameras, &labels, None));
    assert!(
        e.contains("618x300") && e.contains("4946x3286") && e.contains("b.png"),
        "{e}"
    );
    assert!(
        e.contains("the aspect ratios differ") && e.contains("nearest neighbour"),
        "{e}"
    );
    // The aspect ratio of 4946x3286 to within a pixel, but under a 32nd of it (it passed as a
    // scaled copy), and a pixel off on each side: refused, each with its reason.
    for ((w, h), why) in [
        ((154, 102), "under a 32nd of the camera's side"),
        ((4945, 3285), "a pixel off on a side is a crop or pad"),
    ] {
        let map = LabelMap::filled(w, h, 2);
        semsplat::scene::labels::write_label_png(&labels.join("b.png"), &map).unwrap();
        let e = err(open(&cameras, &labels, None));
        assert!(e.contains(&format!("{w}x{h}")) && e.contains(why), "{e}");
    }
    assert_eq!(label_size_fit((4946, 3286), (155, 103)), SizeFit::Scaled);
}

#[test]
fn rig_subfolders_match_by_relative_path_then_unique_stem() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let gray = |p: &Path, v: u8| {
        write_png(
            p,
            (4, 3),
            png::ColorType::Grayscale,
            png::BitDepth::Eight,
            None,
            &[v; 12],
        )
    };
    gray(&root.join("cam0/00001.png"), 1);
    gray(&root.join("cam1/00001.png"), 2);
    gray(&root.join("cam0/00002.png"), 3);
    let cams = [
        camera("cam0/00001", (4, 3)),
        camera("cam1/00001", (4, 3)),
        camera("00002", (4, 3)),
    ];
    let dir_labels = LabelDir::open(root, &cams, None, MissingLabels::Error).unwrap();
    let firsts: Vec<u16> = dir_labels.iter().map(|r| r.unwrap().1.labels[0]).collect();
    assert_eq!(firsts, [1, 2, 3]);

    // The error of opening the folder for one 4x3 camera named `name`.
    let open_for =
        |name: &str, missing| err(LabelDir::open(root, &[camera(name, (4, 3))], None, missing));
    // A bare stem matching two subfolders is ambiguous.
    let e = open_for("00001", MissingLabels::Error);
    assert!(
        e.contains("cam0/00001.png") && e.contains("cam1/00001.png") && e.contains("several"),
        "{e}"
    );
    // Nothing matches: the error lists expected and found names.
    let e = open_for("frame_9", MissingLabels::Skip);
    assert!(
        e.contains("frame_9.png") && e.contains("cam0/00001.png"),
        "{e}"
    );
    // A camera named by a bare stem (its image cam0/00002) with a stray map of that stem
    // at the top beside the mirrored one: both could be its own, refused naming both
    // (the top one had been read, silently).
    gray(&root.join("00002.png"), 9);
    let e = open_for("00002", MissingLabels::Skip);
    assert!(
        e.contains("00002.png, cam0/00002.png") && e.contains("mirrors the image's path"),
        "{e}"
    );
}

/// A PNG whose header claims `w` x `h` 8-bit gray, followed by a token IDAT: tiny on disk.
fn huge_header_png(path: &Path, w: u32, h: u32) {
    fn chunk(out: &mut Vec<u8>, kind: &[u8], data: &[u8]) {
        out.extend((data.len() as u32).to_be_bytes());
        let start = out.len();
        out.extend(kind);
        out.extend(data);
        let crc = crc32(&out[start..]);
        out.extend(crc.to_be_bytes());
    }
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 0, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &[0x78, 0x9c, 0x03, 0x00]);
    chunk(&mut png, b"IEND", &[]);
    std::fs::write(path, png).unwrap();
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn huge_label_headers_are_refused_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v0.png");
    huge_header_png(&p, 30000, 30000);
    assert!(std::fs::metadata(&p).unwrap().len() < 100);
    // Over the pixel limit: refused from the header alone (a decode would fail instead
    // with "cannot decode", the IDAT being a token).
    let e = err(read_label_png(&p));
    assert!(
        e.contains("30000x30000")
            && e.contains("refused from its header")
            && !e.contains("decode PNG"),
        "{e}"
    );
    // Under the limit but not its camera's size: the size check comes before decoding.
    huge_header_png(&p, 16000, 11000);
    let labels = LabelDir::open(
        dir.path(),
        &[camera("v0", (4, 3))],
        None,
        MissingLabels::Error,
    )
    .unwrap();
    let e = err(labels.load(0));
    assert!(
        e.contains("16000x11000") && e.contains("4x3") && !e.contains("decode PNG"),
        "{e}"
    );
}

#[test]
fn jpeg_images_load() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (16u32, 8u32);
    let img =
        image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 4) as u8, (y * 8) as u8, 200]));
    std::fs::create_dir_all(dir.path().join("cam0")).unwrap();
    let path = dir.path().join("cam0/00001.jpg");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut file, 95)
        .encode_image(&img)
        .unwrap();
    drop(file);
    let rgb = load_view_image(dir.path(), &camera("cam0/00001", (w, h))).unwrap();
    assert_eq!(rgb.len(), (w * h * 3) as usize);
    // Lossy, but close: within 8/255 per channel at quality 95 on a smooth image.
    for (got, want) in rgb.iter().zip(img.as_raw()) {
        assert!(
            (got - *want as f32 / 255.0).abs() < 8.0 / 255.0,
            "{got} vs {want}"
        );
    }
    let e = err(load_view_image(
        dir.path(),
        &camera("cam0/00001", (w, h + 1)),
    ));
    assert!(e.contains("16x8") && e.contains("16x9"), "{e}");

    // A rig whose image stems are unique names its cameras by stem (`00001`): the image is
    // found in its subfolder, as the label maps are; a stem in two subfolders is an error.
    let by_stem = load_view_image(dir.path(), &camera("00001", (w, h))).unwrap();
    assert_eq!(by_stem, rgb);
    std::fs::create_dir_all(dir.path().join("cam1")).unwrap();
    std::fs::copy(&path, dir.path().join("cam1/00001.jpg")).unwrap();
    let e = err(load_view_image(dir.path(), &camera("00001", (w, h))));
    assert!(e.contains("2 images"), "{e}");
}

// ---------------------------------------------------------------------------------------
// End to end through the CLI (lavapipe): palette labels, JPEG images, named eval classes,
// class ids above 16 bits.

/// The synth room's label maps re-saved as VOC-style palette PNGs and its images as JPEG.
fn palette_labels_and_jpegs(d: &Path) {
    let pal = d.join("labels_pal");
    for entry in std::fs::read_dir(d.join("labels")).unwrap() {
        let p = entry.unwrap().path();
        let map = read_label_png(&p).unwrap();
        let idx: Vec<u8> = map
            .labels
            .iter()
            .map(|&l| if l == IGN { 255 } else { l as u8 })
            .collect();
        let out = pal.join(p.file_name().unwrap());
        write_png(
            &out,
            (map.width, map.height),
            png::ColorType::Indexed,
            png::BitDepth::Eight,
            Some(voc_palette()),
            &idx,
        );
    }
    let jpg = d.join("images_jpg");
    std::fs::create_dir_all(&jpg).unwrap();
    for entry in std::fs::read_dir(d.join("images")).unwrap() {
        let p = entry.unwrap().path();
        let img = image::open(&p).unwrap().to_rgb8();
        img.save(jpg.join(p.with_extension("jpg").file_name().unwrap()))
            .unwrap();
    }
}

/// The tiny synth room in `d`: four train views and one held-out view at 48x32.
fn synth_four_view_room(d: &Path) {
    ok(&[
        "synth",
        "--preset",
        "tiny",
        "--out",
        &arg_in(d, ""),
        "--views",
        "4",
        "--test-views",
        "1",
        "--width",
        "48",
        "--height",
        "32",
    ]);
}

/// `fuse` of the room's scene from the palette labels into `fused.ply`.
fn fuse_palette_labels(d: &Path) {
    ok(&[
        "fuse",
        "--scene",
        &arg_in(d, "scene.ply"),
        "--cameras",
        &arg_in(d, "cameras.json"),
        "--labels",
        &arg_in(d, "labels_pal"),
        "--classes",
        &arg_in(d, "classes.json"),
        "--out",
        &arg_in(d, "fused.ply"),
    ]);
}

/// eval of the fused scene against the palette labels and the JPEG images: good scores and
/// the classes named from the table.
fn check_eval_scores_jpegs_and_names_classes(d: &Path) {
    ok(&[
        "eval",
        "--scene",
        &arg_in(d, "fused.ply"),
        "--cameras",
        &arg_in(d, "cameras.json"),
        "--labels",
        &arg_in(d, "labels_pal"),
        "--views",
        "all",
        "--images",
        &arg_in(d, "images_jpg"),
        "--json",
        &arg_in(d, "eval.json"),
    ]);
    let eval = read_json(&d.join("eval.json"));
    let miou = eval["miou"].as_f64().unwrap();
    assert!(miou > 0.5, "{eval}");
    assert!(
        eval["image_quality"]["psnr"].as_f64().unwrap() > 10.0,
        "{eval}"
    );
    let names: Vec<&str> = eval["per_class"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert!(
        names.contains(&"floor") && names.contains(&"wall"),
        "{names:?}"
    );
}

/// The same classes shifted by 2^16: cut to 16 bits they would score exactly as before.
fn check_class_ids_above_16_bits_are_not_cut(d: &Path) {
    let mut g = read_ply(&d.join("fused.ply")).unwrap();
    for c in g.class_ids.as_mut().unwrap() {
        if *c >= 0 {
            *c += 65536;
        }
    }
    write_ply(&d.join("shifted.ply"), &g).unwrap();
    ok(&[
        "eval",
        "--scene",
        &arg_in(d, "shifted.ply"),
        "--cameras",
        &arg_in(d, "cameras.json"),
        "--labels",
        &arg_in(d, "labels_pal"),
        "--views",
        "all",
        "--json",
        &arg_in(d, "shifted.json"),
    ]);
    let shifted = read_json(&d.join("shifted.json"));
    assert_eq!(shifted["miou"].as_f64(), Some(0.0), "{shifted}");
    assert_eq!(shifted["pixel_accuracy"].as_f64(), Some(0.0), "{shifted}");
}

/// train reads the JPEG images (a couple of iterations: the format path, not quality).
fn check_train_reads_jpegs(d: &Path) {
    ok(&[
        "train",
        "--images",
        &arg_in(d, "images_jpg"),
        "--labels",
        &arg_in(d, "labels_pal"),
        "--cameras",
        &arg_in(d, "cameras.json"),
        "--init",
        &arg_in(d, "init.ply"),
        "--out",
        &arg_in(d, "trained.ply"),
        "--train-only",
        "--iters",
        "2",
        "--max-gaussians",
        "4000",
    ]);
    assert!(read_ply(&d.join("trained.ply"))
        .unwrap()
        .class_ids
        .is_some());
}

#[test]
fn palette_labels_and_jpeg_images_through_fuse_train_and_eval() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_four_view_room(d);
    palette_labels_and_jpegs(d);
    fuse_palette_labels(d);
    check_eval_scores_jpegs_and_names_classes(d);
    check_class_ids_above_16_bits_are_not_cut(d);
    check_train_reads_jpegs(d);
}

/// The maps are read on every core to find the classes present; a failure is the first
/// failing map in the folder's order, as one at a time would report it.
#[test]
fn the_first_bad_map_in_order_is_the_one_reported() {
    let dir = tempfile::tempdir().unwrap();
    let names = ["a", "b", "c", "d", "e", "f", "g", "h"];
    let cams: Vec<Camera> = names.iter().map(|n| camera(n, (4, 3))).collect();
    let (cameras, labels) = dataset_dir(dir.path(), &cams);
    write_class_table(&labels.join("classes.json"), &ClassTable::from_ids([0, 1])).unwrap();
    for (i, name) in names.iter().enumerate() {
        // Maps c and f hold id 9, which the class table does not have.
        let id = if i == 2 || i == 5 { 9 } else { 1 };
        write_gray_4x3(&labels, name, &[0u8, id, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0]);
    }
    for _ in 0..3 {
        let e = err(open(&cameras, &labels, None));
        assert!(
            e.contains("c.png") && !e.contains("f.png") && e.contains("9"),
            "{e}"
        );
    }
}

/// A class table naming class 255 with 8-bit maps: 255 is their default "no label", as a
/// table's "void" means it; the user is told so, and --ignore-id counts it as a class.
#[test]
fn a_table_class_at_the_default_ignore_value_is_ignored_and_said_so() {
    let dir = tempfile::tempdir().unwrap();
    let (cameras, labels) = dataset_dir(dir.path(), &[camera("a", (4, 3))]);
    write_gray_4x3(&labels, "a", &[0, 255, 255, 0, 0, 0, 1, 1, 0, 0, 0, 0]);
    let table = ClassTable::from_ids([0, 1, 255]);
    let table_path = dir.path().join("classes.json");
    write_class_table(&table_path, &table).unwrap();
    let open_with = |ignore_id| {
        Dataset::open(&DatasetPaths {
            cameras: &cameras,
            labels: &labels,
            class_table: Some(&table_path),
            train_only: false,
            format: LabelFormat::with_ignore_id(ignore_id),
        })
        .unwrap()
    };
    let data = open_with(None);
    assert_eq!(data.classes.user_ids(), [0, 1]);
    let note = data.warnings.join("\n");
    assert!(
        note.contains("class 255") && note.contains("--ignore-id"),
        "{note}"
    );
    let data = open_with(Some(1000));
    assert_eq!(data.classes.user_ids(), [0, 1, 255]);
    assert!(data.warnings.iter().all(|w| !w.contains("class 255")));

    // `inspect` says the same of the label folder read through the table, and of the table.
    let (labels_arg, table_arg) = (labels.to_str().unwrap(), table_path.to_str().unwrap());
    for args in [vec![labels_arg, "--classes", table_arg], vec![table_arg]] {
        let out = semsplat(&[&["inspect"][..], &args].concat());
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains("class 255") && text.contains("--ignore-id"),
            "{args:?}: {text}"
        );
        let out = semsplat(&[&["inspect"][..], &args, &["--ignore-id", "1000"]].concat());
        assert!(
            !String::from_utf8_lossy(&out.stdout).contains("class 255"),
            "{args:?}"
        );
    }

    // 16-bit maps count 255 as a class: no note.
    let px16: Vec<u16> = vec![0, 255, 255, 0, 0, 0, 1, 1, 0, 0, 0, 0];
    let map16 = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, px16).unwrap();
    map16.save(labels.join("a.png")).unwrap();
    let data = open_with(None);
    assert_eq!(data.classes.user_ids(), [0, 1, 255]);
    assert!(data.warnings.iter().all(|w| !w.contains("class 255")));
}

#[test]
fn sixteen_bit_maps_with_255_apart_from_the_other_ids_warn() {
    let dir = tempfile::tempdir().unwrap();
    let (cameras, labels) = dataset_dir(dir.path(), &[camera("a", (4, 3))]);
    let write16 = |px: Vec<u16>| {
        let map = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, px).unwrap();
        map.save(labels.join("a.png")).unwrap();
    };
    // Code that wrote 255 for "no label" into 16-bit maps: 255 is a class there.
    write16(vec![0, 255, 255, 0, 0, 0, 1, 1, 0, 0, 2, 2]);
    let d = open(&cameras, &labels, None).unwrap();
    assert_eq!(d.classes.user_ids(), [0, 1, 2, 255]);
    let warning = d.warnings.join("\n");
    assert!(
        warning.contains("255 as a class")
            && warning.contains("every other id is 2 or less")
            && warning.contains("--ignore-id 255"),
        "{warning}"
    );
    // The remedy it names drops 255, silently.
    let d = open(&cameras, &labels, Some(255)).unwrap();
    assert_eq!(d.classes.user_ids(), [0, 1, 2]);
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
    // inspect flags the folder (exit status 1).
    let out = semsplat(&["inspect", labels.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        !out.status.success() && stdout.contains("255 as a class"),
        "{stdout}"
    );
    // Ids running up to 255 (a 256-class segmenter's output) are ordinary classes.
    write16(
        (0..12)
            .map(|i| if i == 0 { 255 } else { 200 + i })
            .collect(),
    );
    let d = open(&cameras, &labels, None).unwrap();
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
}

/// Colour-coded true maps are decoded through the label folder's own table, not the fused
/// scene's sidecar, which holds only the classes its fusion's maps used: a class only the
/// held-out view shows is scored and named (its colour had been refused as no class's).
#[test]
fn eval_decodes_colours_with_the_label_folders_table() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    common::cli::synth_tiny(&d.join("room"), 4, (48, 36));
    let table = semsplat::scene::classes::read_class_table(&d.join("room/classes.json")).unwrap();
    let colour = |id: u16| {
        table
            .classes
            .iter()
            .find(|c| u32::from(id) == c.id)
            .unwrap()
            .color
    };
    // The test view's most common class but the wall, unlabeled (black) in the train views.
    let test_map = read_label_png(&d.join("room/labels/test_0000.png")).unwrap();
    let held = (0..table.len() as u16)
        .filter(|&id| table.contains(u32::from(id)) && id != 1)
        .max_by_key(|&id| test_map.labels.iter().filter(|&&l| l == id).count())
        .unwrap();
    for entry in std::fs::read_dir(d.join("room/labels")).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_owned();
        if !name.ends_with(".png") {
            continue;
        }
        let map = read_label_png(&path).unwrap();
        let train = name.starts_with("train");
        let rgb: Vec<u8> = (map.labels.iter())
            .flat_map(|&id| match id == held && train || id == IGN {
                true => [0, 0, 0],
                false => colour(id),
            })
            .collect();
        let (color, depth) = (png::ColorType::Rgb, png::BitDepth::Eight);
        write_png(
            &d.join("rgb").join(&name),
            (48, 36),
            color,
            depth,
            None,
            &rgb,
        );
    }
    std::fs::copy(d.join("room/classes.json"), d.join("rgb/classes.json")).unwrap();
    let (scene, cameras) = (arg_in(d, "room/scene.ply"), arg_in(d, "room/cameras.json"));
    let labels = arg_in(d, "rgb");
    let fused = arg_in(d, "fused.ply");
    let inputs = ["--cameras", &cameras, "--labels", &labels];
    ok(&[
        &["fuse", "--scene", &scene, "--train-only"],
        &inputs[..],
        &["--out", &fused],
    ]
    .concat());
    let sidecar =
        ClassTable::from_json_str(&std::fs::read_to_string(d.join("fused.classes.json")).unwrap())
            .unwrap();
    assert!(
        !sidecar.contains(u32::from(held)),
        "the fusion saw class {held}"
    );
    let json = arg_in(d, "eval.json");
    ok(&[
        &["eval", "--scene", &fused],
        &inputs[..],
        &["--json", &json],
    ]
    .concat());
    let eval = read_json(&d.join("eval.json"));
    let name = &table
        .classes
        .iter()
        .find(|c| c.id == u32::from(held))
        .unwrap()
        .name;
    let scored = eval["per_class"]
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["name"] == **name);
    assert!(scored, "{eval}");
}
