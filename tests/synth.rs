//! `semsplat synth`: determinism, exact ground truth, noise rates, surface Gaussians, files.
//! Small images (64x48) and the tiny preset keep this fast.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use glam::{DMat3, DQuat, DVec3};
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::classes::read_class_table;
use semsplat::scene::labels::read_label_png;
use semsplat::scene::ply::read_ply;
use semsplat::scene::{Gaussians, Split};
use semsplat::synth::furniture::{self, looks, Placement};
use semsplat::synth::primitives::Shape;
use semsplat::synth::raycast::{cast_pixel, pixel_ray};
use semsplat::synth::room_spec::{ObjectSpec, PartSpec, ShapeSpec};
use semsplat::synth::shading::to_rgb8;
use semsplat::synth::views::{look_at, ViewConfig};
use semsplat::synth::{
    self, generate, render_view, write_synth, NoiseSpec, Room, RoomSource, RoomSpec, SynthConfig,
    SynthScene, IGNORE,
};

fn small(preset: &str, seed: u64, train: usize, test: usize) -> SynthConfig {
    SynthConfig {
        seed,
        train_views: train,
        test_views: test,
        width: 64,
        height: 48,
        spacing: 0.08,
        init_spacing: 0.3,
        ..SynthConfig::preset(preset)
    }
}

fn with_noise(mut cfg: SynthConfig, spec: &str) -> SynthConfig {
    cfg.noise = Some(spec.parse().unwrap());
    cfg
}

/// Relative path -> bytes of every file under `dir`.
fn read_tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.insert(
                    path.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&path).unwrap(),
                );
            }
        }
    }
    out
}

fn write_to_temp(cfg: &SynthConfig) -> (tempfile::TempDir, SynthScene) {
    let dir = tempfile::tempdir().unwrap();
    let scene = generate(cfg).unwrap();
    write_synth(dir.path(), &scene).unwrap();
    (dir, scene)
}

#[test]
fn same_seed_same_bytes_different_seed_different_bytes() {
    let cfg = with_noise(
        small("tiny", 11, 3, 1),
        "flicker=0.3,boundary=2,consistent=0.6,salt=0.01,missing=0.05",
    );
    let (a, _) = write_to_temp(&cfg);
    let (b, _) = write_to_temp(&cfg);
    let (ta, tb) = (read_tree(a.path()), read_tree(b.path()));
    let names: Vec<_> = ta
        .keys()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    for expected in [
        "scene.ply",
        "init.ply",
        "cameras.json",
        "classes.json",
        "room.json",
        "instances.json",
        "instances/classes.json",
        "images/train_0000.png",
        "labels/test_0000.png",
        "labels_noisy/train_0002.png",
        "labels_noisy/noise.json",
    ] {
        assert!(
            names.iter().any(|n| n == expected),
            "{expected} missing from {names:?}"
        );
    }
    assert_eq!(ta.keys().collect::<Vec<_>>(), tb.keys().collect::<Vec<_>>());
    for (path, bytes) in &ta {
        assert!(
            bytes == &tb[path],
            "{} differs between identical runs",
            path.display()
        );
    }
    let (c, _) = write_to_temp(&SynthConfig {
        seed: 12,
        ..cfg.clone()
    });
    let tc = read_tree(c.path());
    for differs in [
        "scene.ply",
        "cameras.json",
        "images/train_0000.png",
        "labels_noisy/train_0000.png",
    ] {
        assert_ne!(
            ta[Path::new(differs)],
            tc[Path::new(differs)],
            "{differs} ignores the seed"
        );
    }
}

/// A 4 x 4 x 3 m room with one box whose front face (y = 2.9) faces the camera.
fn one_box_room() -> Room {
    let mut spec: RoomSpec = serde_json::from_str(r#"{"size": [4, 4, 3]}"#).unwrap();
    spec.objects.push(ObjectSpec {
        name: "crate".into(),
        class: "box".into(),
        parts: vec![PartSpec {
            shape: ShapeSpec::box_at(DVec3::new(2.0, 3.0, 0.5), DVec3::new(1.0, 0.2, 1.0), 0.0),
            material: looks::wood([180, 120, 60]),
        }],
    });
    Room::build(spec).unwrap()
}

#[test]
fn ray_cast_truth_matches_the_primitives_at_known_pixels() {
    let room = one_box_room();
    let box_class = room
        .classes
        .classes
        .iter()
        .find(|c| c.name == "box")
        .unwrap()
        .id;
    let floor_class = room
        .classes
        .classes
        .iter()
        .find(|c| c.name == "floor")
        .unwrap()
        .id;
    let cfg = ViewConfig {
        width: 64,
        height: 48,
        hfov_deg: 60.0,
        train: 1,
        test: 0,
    };
    let cam = look_at(
        "v".into(),
        Split::Train,
        &cfg,
        DVec3::new(2.0, 1.0, 0.5),
        DVec3::new(2.0, 3.0, 0.5),
    );
    let view = render_view(&room, &cam);

    // The center pixel sees the box's front face, 1.9 m ahead.
    let (cx, cy) = (32u32, 24u32);
    let center = (cy * 64 + cx) as usize;
    assert_eq!(view.labels[center] as u32, box_class);
    assert_eq!(view.instances[center] as usize, room.instances.len() - 1);
    let hit = cast_pixel(&room, &cam, cx, cy).unwrap();
    assert!((hit.point.y - 2.9).abs() < 1e-12, "{}", hit.point);
    assert!((hit.normal - DVec3::NEG_Y).length() < 1e-12);

    // A bottom-row pixel looks down onto the floor: intersect its ray with z = 0 analytically.
    let (px, py) = (10u32, 47u32);
    let (origin, dir) = pixel_ray(&cam, px as f64, py as f64);
    assert!(dir.z < 0.0);
    let expected = origin + dir * (-origin.z / dir.z);
    let hit = cast_pixel(&room, &cam, px, py).unwrap();
    assert!(
        (hit.point - expected).length() < 1e-9,
        "{} vs {expected}",
        hit.point
    );
    assert!(expected.y < 2.9, "the floor point lies in front of the box");
    let i = (py * 64 + px) as usize;
    assert_eq!(view.labels[i] as u32, floor_class);
    assert_eq!(view.instances[i], 0, "the floor is instance 0");
    let rgb = to_rgb8(room.color_at(hit.primitive, expected, hit.face));
    assert_eq!(&view.rgb[3 * i..3 * i + 3], &rgb);

    // Every pixel agrees with a fresh cast, and the image has both classes and the walls.
    let mut seen = std::collections::BTreeSet::new();
    for y in 0..48 {
        for x in 0..64 {
            let hit = cast_pixel(&room, &cam, x, y).unwrap();
            let i = (y * 64 + x) as usize;
            assert_eq!(
                view.labels[i] as u32,
                room.primitives[hit.primitive].class_id
            );
            seen.insert(view.labels[i]);
        }
    }
    assert!(seen.len() >= 3, "{seen:?}");
}

#[test]
fn pixels_that_see_nothing_are_ignored() {
    let room = one_box_room();
    let cfg = ViewConfig {
        width: 16,
        height: 12,
        hfov_deg: 60.0,
        train: 1,
        test: 0,
    };
    // Outside the room, looking away from it.
    let cam = look_at(
        "out".into(),
        Split::Train,
        &cfg,
        DVec3::new(10.0, 2.0, 1.5),
        DVec3::new(20.0, 2.0, 1.5),
    );
    let view = render_view(&room, &cam);
    assert!(view.labels.iter().all(|&l| l == IGNORE));
    assert!(view.instances.iter().all(|&l| l == IGNORE));
    assert!(view.rgb.iter().all(|&c| c == 0));
}

#[test]
fn gaussians_lie_on_their_primitives_with_sane_frames() {
    for preset in ["tiny", "office"] {
        // Every surface, seen or not: this test is about the sampler.
        let cfg = SynthConfig {
            spacing: 0.1,
            keep_hidden: true,
            ..small(preset, 5, 1, 0)
        };
        let scene = generate(&cfg).unwrap();
        let g = &scene.gaussians;
        let room = &scene.room;
        assert!(g.len() > 1000, "{preset}: {}", g.len());
        g.validate().unwrap();
        let classes = g.class_ids.as_ref().unwrap();
        let instances = g.instance_ids.as_ref().unwrap();
        let mut thin = 0;
        for i in 0..g.len() {
            let prim = &room.primitives[scene.gaussian_primitives[i] as usize];
            let p = DVec3::from_array(g.means[i].map(f64::from));
            assert!(
                prim.shape.sdf(p).abs() < 1e-5,
                "{preset}: Gaussian {i} off its surface by {}",
                prim.shape.sdf(p)
            );
            assert_eq!(classes[i], prim.class_id as i32);
            assert_eq!(instances[i], prim.instance as i32);
            // The flat axis (rotation's z column) is the outward surface normal.
            let [w, x, y, z] = g.quats[i].map(f64::from);
            let q = DQuat::from_xyzw(x, y, z, w);
            assert!((q.length() - 1.0).abs() < 1e-5);
            let normal = prim.shape.normal(p, prim.shape.nearest_face(p));
            let axes = DMat3::from_quat(q);
            assert!(
                (axes.z_axis - normal).length() < 1e-4,
                "{preset}: Gaussian {i} normal {} vs {normal}",
                axes.z_axis
            );
            let s = g.log_scales[i].map(f32::exp);
            // Flat: thinnest along the normal; discs on small faces shrink in-plane toward it.
            assert!(s[2] <= s[0].min(s[1]), "flat: {s:?}");
            thin += usize::from(s[2] < 0.2 * s[0].min(s[1]));
            // At most 0.7 x the spacing (thin parts get finer grids, so smaller discs).
            assert!(
                s[0].max(s[1]) <= 0.0735 && s[0].min(s[1]) > 0.0,
                "about the spacing: {s:?}"
            );
            // Not inside or behind anything: not in another solid, and in the room.
            assert!(
                room.interior_contains(p, -1e-4),
                "{preset}: Gaussian {i} outside the room at {p}"
            );
            for (k, other) in room.primitives.iter().enumerate() {
                if k != scene.gaussian_primitives[i] as usize {
                    assert!(other.shape.sdf(p) > -1e-4, "{preset}: Gaussian {i} at {p} of primitive {} ({:?}) buried in primitive {k} ({:?}) by {}", scene.gaussian_primitives[i], prim.shape, other.shape, other.shape.sdf(p));
                }
            }
        }
        assert!(
            thin > g.len() * 3 / 4,
            "{preset}: {thin} of {} flat",
            g.len()
        );
        // Colors are the lit texture colors: SH DC maps back to the surface color.
        let dc = &g.sh[..3];
        let c = room.color_at(
            scene.gaussian_primitives[0] as usize,
            DVec3::from_array(g.means[0].map(f64::from)),
            {
                let prim = &room.primitives[scene.gaussian_primitives[0] as usize];
                prim.shape
                    .nearest_face(DVec3::from_array(g.means[0].map(f64::from)))
            },
        );
        for k in 0..3 {
            assert!((0.282_094_79 * dc[k] as f64 + 0.5 - c[k]).abs() < 1e-3);
        }
    }
}

#[test]
fn hidden_faces_get_no_gaussians_and_density_scales_the_count() {
    let coarse = generate(&SynthConfig {
        spacing: 0.1,
        keep_hidden: true,
        ..small("tiny", 1, 1, 0)
    })
    .unwrap();
    let fine = generate(&SynthConfig {
        spacing: 0.05,
        keep_hidden: true,
        ..small("tiny", 1, 1, 0)
    })
    .unwrap();
    let ratio = fine.gaussians.len() as f64 / coarse.gaussians.len() as f64;
    assert!(
        (3.4..4.6).contains(&ratio),
        "halving the spacing gives {ratio}x Gaussians"
    );
    // Boxes rest on the floor: nothing is sampled on their bottoms, nor on the floor under them.
    let room = &coarse.room;
    let g = &coarse.gaussians;
    for name in ["box_0", "box_1"] {
        let inst = room.instances.iter().find(|i| i.name == name).unwrap();
        let b = room.instance_bounds(inst.id);
        let mut on_box = 0;
        for i in 0..g.len() {
            let p = DVec3::from_array(g.means[i].map(f64::from));
            if g.instance_ids.as_ref().unwrap()[i] == inst.id as i32 {
                on_box += 1;
                assert!(
                    p.z > 1e-3,
                    "{name}: Gaussian on the hidden bottom face at {p}"
                );
            }
            if g.instance_ids.as_ref().unwrap()[i] == 0 {
                // Floor Gaussians are never strictly under the box (inside its footprint).
                let prim = &room
                    .primitives
                    .iter()
                    .find(|q| q.instance == inst.id)
                    .unwrap()
                    .shape;
                assert!(
                    prim.sdf(p + DVec3::Z * 1e-3) > 0.0,
                    "floor Gaussian under {name} at {p}"
                );
            }
        }
        assert!(on_box > 20, "{name}: {on_box} Gaussians");
        assert!(b.min.z.abs() < 1e-9);
    }
}

#[test]
fn flicker_rate_matches_and_uses_look_alike_classes() {
    let scene = generate(&with_noise(small("office", 2, 40, 0), "flicker=0.3")).unwrap();
    let noisy = scene.noisy.as_ref().unwrap();
    let (mut pairs, mut relabeled) = (0, 0);
    for (v, view) in scene.views.iter().enumerate() {
        for inst in &scene.room.instances {
            let pixels: Vec<usize> = (0..view.instances.len())
                .filter(|&i| view.instances[i] as u32 == inst.id)
                .collect();
            if pixels.is_empty() {
                continue;
            }
            let first = noisy.maps[v][pixels[0]];
            assert!(
                pixels.iter().all(|&i| noisy.maps[v][i] == first),
                "an instance is relabeled as a whole"
            );
            pairs += 1;
            if first as u32 != inst.class_id {
                relabeled += 1;
                assert!(scene
                    .room
                    .confusions
                    .for_class(inst.class_id as usize)
                    .contains(&(first as u32)));
            }
        }
    }
    let rate = relabeled as f64 / pairs as f64;
    assert!(pairs > 200, "{pairs} pairs");
    assert!(
        (rate - 0.3).abs() < 0.07,
        "flicker measured {rate} over {pairs} pairs"
    );
    assert!((noisy.report.measured.flicker.rate - rate).abs() < 1e-12);
}

#[test]
fn salt_and_missing_rates_match() {
    let scene = generate(&with_noise(small("tiny", 3, 20, 5), "salt=0.05")).unwrap();
    let maps = &scene.noisy.as_ref().unwrap().maps;
    let (changed, total) = count_changes(&scene, maps);
    let rate = changed as f64 / total as f64;
    assert!((rate - 0.05).abs() < 0.005, "salt measured {rate}");

    let scene = generate(&with_noise(small("tiny", 3, 20, 5), "missing=0.1")).unwrap();
    let maps = &scene.noisy.as_ref().unwrap().maps;
    for (v, map) in maps.iter().enumerate() {
        let ignored = map.iter().filter(|&&l| l == IGNORE).count();
        assert_eq!(
            ignored,
            (0.1 * map.len() as f64).round() as usize,
            "view {v}"
        );
        // Only ignore is added: everything else is untouched.
        for (i, &l) in map.iter().enumerate() {
            assert!(l == IGNORE || l == scene.views[v].labels[i]);
        }
    }
}

fn count_changes(scene: &SynthScene, maps: &[Vec<u16>]) -> (usize, usize) {
    let mut changed = 0;
    let mut total = 0;
    for (view, map) in scene.views.iter().zip(maps) {
        changed += view.labels.iter().zip(map).filter(|(a, b)| a != b).count();
        total += map.len();
    }
    (changed, total)
}

#[test]
fn consistent_mislabel_hits_the_requested_fraction_of_views() {
    for q in [0.3, 0.7] {
        let scene = generate(&with_noise(
            small("office", 4, 30, 6),
            &format!("consistent={q}"),
        ))
        .unwrap();
        let noisy = scene.noisy.as_ref().unwrap();
        assert_eq!(noisy.report.consistent.len(), 1);
        let c = &noisy.report.consistent[0];
        assert_ne!(c.true_class, c.wrong_class);
        let (mut visible, mut wrong) = (0, 0);
        for (v, view) in scene.views.iter().enumerate() {
            let pixels: Vec<usize> = (0..view.instances.len())
                .filter(|&i| view.instances[i] as u32 == c.instance)
                .collect();
            if pixels.is_empty() {
                continue;
            }
            let label = noisy.maps[v][pixels[0]] as u32;
            // Held-out views keep the object's class: the rate is of the views lifted from.
            if scene.cameras[v].split != Split::Train {
                assert_eq!(label, c.true_class, "held-out view {v}");
                continue;
            }
            visible += 1;
            if label == c.wrong_class {
                wrong += 1;
                assert!(c.wrong_views.contains(&scene.cameras[v].name));
            } else {
                assert_eq!(label, c.true_class);
            }
        }
        assert_eq!((visible, wrong), (c.views_visible, c.views_wrong));
        assert!(
            visible >= 8,
            "the chosen object is widely visible ({visible} views)"
        );
        let rate = wrong as f64 / visible as f64;
        assert!(
            (rate - q).abs() <= 0.5 / visible as f64 + 1e-12,
            "q = {q}: measured {rate}"
        );
        // Only the chosen object changes (no other noise requested), and the per-view report agrees.
        let views_reported: usize = noisy.report.views.iter().map(|v| v.consistent.len()).sum();
        assert_eq!(views_reported, wrong);
        for (view, map) in scene.views.iter().zip(&noisy.maps) {
            for (i, (&truth, &label)) in view.labels.iter().zip(map).enumerate() {
                assert!(truth == label || view.instances[i] as u32 == c.instance);
            }
        }
    }
}

#[test]
fn boundary_noise_changes_only_pixels_near_true_edges() {
    let k = 2i64;
    let scene = generate(&with_noise(small("office", 6, 10, 0), "boundary=2")).unwrap();
    let maps = &scene.noisy.as_ref().unwrap().maps;
    let (changed, total) = count_changes(&scene, maps);
    assert!(
        changed > 0 && (changed as f64) < 0.2 * total as f64,
        "{changed} of {total}"
    );
    for (view, map) in scene.views.iter().zip(maps) {
        let (w, h) = (view.width as i64, view.height as i64);
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                if map[i] == view.labels[i] {
                    continue;
                }
                let near_edge = (-k..=k).any(|dy| {
                    (-k..=k).any(|dx| {
                        let (sx, sy) = (x + dx, y + dy);
                        (0..w).contains(&sx)
                            && (0..h).contains(&sy)
                            && view.labels[(sy * w + sx) as usize] != view.labels[i]
                    })
                });
                assert!(
                    near_edge,
                    "pixel ({x}, {y}) changed but no edge within {k} px"
                );
                // The new label is one found nearby.
                assert!((-k..=k).any(|dy| (-k..=k).any(|dx| {
                    let (sx, sy) = ((x + dx).clamp(0, w - 1), (y + dy).clamp(0, h - 1));
                    view.labels[(sy * w + sx) as usize] == map[i]
                })));
            }
        }
    }
}

#[test]
fn written_files_read_back_as_generated() {
    let cfg = with_noise(small("tiny", 8, 3, 2), "flicker=0.2,missing=0.05");
    let (dir, scene) = write_to_temp(&cfg);
    let d = dir.path();
    let ply = read_ply(&d.join("scene.ply")).unwrap();
    assert_eq!(ply.len(), scene.gaussians.len());
    assert_eq!(ply.class_ids, scene.gaussians.class_ids);
    assert_eq!(ply.instance_ids, scene.gaussians.instance_ids);
    assert_eq!(ply.means, scene.gaussians.means);
    let init = read_ply(&d.join("init.ply")).unwrap();
    assert_eq!(init.len(), scene.init_points.len());
    assert!(init.class_ids.is_none() && init.len() > 100);
    let cams = load_cameras(&d.join("cameras.json")).unwrap();
    assert_eq!(cams.len(), 5);
    assert_eq!(cams.iter().filter(|c| c.split == Split::Test).count(), 2);
    for (a, b) in cams.iter().zip(&scene.cameras) {
        assert_eq!(
            (&a.name, a.split, a.width, a.height),
            (&b.name, b.split, b.width, b.height)
        );
        assert!((a.center() - b.center()).length() < 1e-9);
    }
    assert_eq!(
        read_class_table(&d.join("classes.json")).unwrap(),
        scene.room.classes
    );
    for (i, cam) in scene.cameras.iter().enumerate() {
        let file = format!("{}.png", cam.name);
        let labels = read_label_png(&d.join("labels").join(&file)).unwrap();
        assert_eq!(labels.labels, scene.views[i].labels);
        let instances = read_label_png(&d.join("instances").join(&file)).unwrap();
        assert_eq!(instances.labels, scene.views[i].instances);
        let noisy = read_label_png(&d.join("labels_noisy").join(&file)).unwrap();
        assert_eq!(noisy.labels, scene.noisy.as_ref().unwrap().maps[i]);
        let rgb = image::open(d.join("images").join(&file)).unwrap().to_rgb8();
        assert_eq!((rgb.width(), rgb.height()), (64, 48));
        assert_eq!(rgb.as_raw(), &scene.views[i].rgb);
        assert!(d.join("vis/labels").join(&file).is_file());
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("labels_noisy/noise.json")).unwrap()).unwrap();
    assert_eq!(report["spec"], "flicker=0.2,missing=0.05");
    assert_eq!(report["seed"], 8);
    assert!(report["measured"]["missing"]["rate"].as_f64().unwrap() > 0.04);

    // room.json reproduces the scene exactly.
    let again = generate(&SynthConfig {
        room: RoomSource::File(d.join("room.json")),
        ..cfg.clone()
    })
    .unwrap();
    assert_eq!(again.views, scene.views);
    assert_eq!(again.gaussians, scene.gaussians);
    // To the bit: the cameras (placed from the room's floats as read back) and the room
    // written again (without float_roundtrip a float read back was one ULP off).
    assert_eq!(again.cameras, scene.cameras);
    let redone = tempfile::tempdir().unwrap();
    write_synth(redone.path(), &again).unwrap();
    for file in ["cameras.json", "room.json"] {
        assert_eq!(
            std::fs::read(redone.path().join(file)).unwrap(),
            std::fs::read(d.join(file)).unwrap(),
            "{file}"
        );
    }

    // Rewriting with fewer views and no noise leaves no stale files behind.
    let fewer = SynthConfig {
        train_views: 1,
        test_views: 0,
        noise: None,
        ..cfg
    };
    write_synth(d, &generate(&fewer).unwrap()).unwrap();
    let pngs: Vec<_> = read_tree(d)
        .into_keys()
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    assert_eq!(pngs.len(), 4, "{pngs:?}"); // images, labels, instances, vis/labels
    assert!(!d.join("labels_noisy/noise.json").exists());
}

#[test]
fn presets_have_the_promised_shape() {
    let office = generate(&small("office", 0, 1, 0)).unwrap();
    let living = generate(&small("living", 0, 1, 0)).unwrap();
    assert!((9..=13).contains(&office.room.classes.classes.len()));
    assert!(living.room.classes.classes.len() >= 20);
    assert!(living.room.instances.len() > 2 * office.room.instances.len());
    // Two chairs share a class.
    let chair = office
        .room
        .classes
        .classes
        .iter()
        .find(|c| c.name == "chair")
        .unwrap()
        .id;
    assert!(
        office
            .room
            .instances
            .iter()
            .filter(|i| i.class_id == chair)
            .count()
            >= 2
    );
    // Default density: 50k..300k Gaussians for the office (estimated at the default spacing).
    let estimate = synth::surface_sampling::estimated_samples(&office.room, synth::DEFAULT_SPACING);
    assert!((50_000.0..600_000.0).contains(&estimate), "{estimate}");
}

#[test]
fn bad_configs_are_clear_errors() {
    let base = small("tiny", 0, 1, 0);
    for (cfg, needle) in [
        (
            SynthConfig {
                train_views: 0,
                ..base.clone()
            },
            "train view",
        ),
        (
            SynthConfig {
                width: 0,
                ..base.clone()
            },
            "image size",
        ),
        (
            SynthConfig {
                height: 0,
                ..base.clone()
            },
            "image size",
        ),
        (
            SynthConfig {
                hfov_deg: 179.0,
                ..base.clone()
            },
            "field of view",
        ),
        (
            SynthConfig {
                spacing: 0.0,
                ..base.clone()
            },
            "spacing",
        ),
        (
            SynthConfig {
                spacing: f64::NAN,
                ..base.clone()
            },
            "spacing",
        ),
        (
            SynthConfig {
                room: RoomSource::Preset("castle".into()),
                ..base.clone()
            },
            "office, living, tiny",
        ),
    ] {
        let err = generate(&cfg).map(|_| ()).unwrap_err();
        assert!(format!("{err:#}").contains(needle), "{err:#}");
    }
    // A large room at a fine init grid: bounded before any point is sampled (it took
    // memory until the allocation failed).
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big.json");
    std::fs::write(&big, r#"{"size": [200, 200, 200]}"#).unwrap();
    let cfg = SynthConfig {
        room: RoomSource::File(big),
        spacing: 1.0,
        init_spacing: 0.01,
        ..base.clone()
    };
    let err = format!("{:#}", generate(&cfg).map(|_| ()).unwrap_err());
    assert!(
        err.contains("--init-spacing 0.01 m would give") && err.contains("of 'wall_"),
        "{err}"
    );
    let err = RoomSource::from_arg("castle").unwrap_err().to_string();
    assert!(err.contains("office, living, tiny"), "{err}");
    assert!(RoomSource::from_arg("missing_room.json")
        .unwrap_err()
        .to_string()
        .contains("does not exist"));
    assert!("flicker=2".parse::<NoiseSpec>().is_err());
}

#[test]
fn furniture_builders_place_parts_by_yaw() {
    // A chair turned 90 degrees: its backrest (local +y) moves to world -x of the origin.
    let chair = furniture::chair(
        "c",
        Placement::at(1.0, 1.0, 0.0, 90.0),
        &looks::plain([1, 2, 3]),
        &looks::metal(),
    );
    let back = &chair.parts[1].shape;
    let ShapeSpec::Box {
        center, yaw_deg, ..
    } = back
    else {
        panic!("backrest is a box")
    };
    // Local +y rotated by +90 degrees about z is world -x.
    assert!(
        center[0] < 1.0 - 0.15 && (center[1] - 1.0).abs() < 1e-9,
        "{center:?}"
    );
    assert_eq!(*yaw_deg, 90.0);
}

fn semsplat() -> Command {
    Command::new(env!("CARGO_BIN_EXE_semsplat"))
}

#[test]
fn cli_writes_a_room_and_rejects_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("room");
    let small_args = [
        "--width",
        "32",
        "--height",
        "24",
        "--views",
        "2",
        "--test-views",
        "1",
        "--spacing",
        "0.2",
    ];
    let status = semsplat()
        .args(["synth", "--preset", "tiny", "--out"])
        .arg(&out)
        .args(small_args)
        .args(["--noise", "flicker=0.5,salt=0.01"])
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    assert!(out.join("labels_noisy/train_0001.png").is_file());
    assert!(out.join("images/test_0000.png").is_file());
    // Rerunning into an earlier output is fine, and removes only the files synth names (a
    // user's own image in its folders stays); a foreign non-empty folder needs --force.
    std::fs::copy(
        out.join("images/test_0000.png"),
        out.join("images/IMG_0001.png"),
    )
    .unwrap();
    let rerun = semsplat()
        .args(["synth", "--preset", "tiny", "--out"])
        .arg(&out)
        .args(small_args)
        .output()
        .unwrap();
    assert!(rerun.status.success());
    assert!(
        !out.join("labels_noisy/train_0001.png").exists(),
        "stale noisy labels removed"
    );
    assert!(
        out.join("images/IMG_0001.png").is_file(),
        "the user's image stays"
    );
    std::fs::write(dir.path().join("notes.txt"), "mine").unwrap();
    for (args, needle) in [
        (vec!["--views", "0"], "train view"),
        (vec!["--width", "0"], "--width"),
        (vec!["--noise", "flicker=lots"], "not a number"),
        (vec!["--noise", "blur=1"], "unknown noise key"),
        (vec!["--noise", "salt=1.5"], "[0, 1]"),
        (vec!["--preset", "castle"], "unknown preset"),
        (vec![], "not empty"),
    ] {
        let o = semsplat()
            .args(["synth", "--out"])
            .arg(dir.path())
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
    let help = semsplat().args(["synth", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    for needle in [
        "flicker=P",
        "consistent=Q",
        "labels_noisy/noise.json",
        "room.json",
        "living",
        "--test-views",
    ] {
        assert!(help.contains(needle), "--help lacks {needle}");
    }
}

/// Near the end of its surface (a face edge, or where another solid covers it) a Gaussian
/// shrinks so that 1.5 standard deviations stay on the surface: it does not spill over a
/// silhouette or across a junction. Away from edges it keeps 0.7 x the spacing.
#[test]
fn gaussians_shrink_at_the_end_of_their_surface() {
    let spacing = 0.1;
    let scene = generate(&SynthConfig {
        spacing,
        keep_hidden: true,
        ..small("office", 3, 1, 0)
    })
    .unwrap();
    let g = &scene.gaussians;
    let (mut shrunk, mut full, mut checked) = (0, 0, 0);
    for i in 0..g.len() {
        let prim = &scene.room.primitives[scene.gaussian_primitives[i] as usize];
        // Flat faces only: on a box or quad a point past the face's edge is off the shape.
        if !matches!(prim.shape, Shape::Box(_) | Shape::Quad(_)) {
            continue;
        }
        let p = DVec3::from_array(g.means[i].map(f64::from));
        let [w, x, y, z] = g.quats[i].map(f64::from);
        let axes = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w));
        let s = g.log_scales[i].map(|v| f64::from(v).exp());
        for (axis, sigma) in [(axes.x_axis, s[0]), (axes.y_axis, s[1])] {
            for sign in [-1.0, 1.0] {
                let q = p + axis * (sign * 1.5 * sigma);
                // Still on this primitive's surface (the covered-region search walks in
                // steps of a quarter spacing, hence the tolerance) ...
                assert!(
                    prim.shape.sdf(q).abs() < 0.13 * spacing,
                    "Gaussian {i} spills {} m off its face",
                    prim.shape.sdf(q)
                );
                // ... and not inside another solid or outside the room.
                assert!(
                    scene.room.interior_contains(q, -0.13 * spacing),
                    "Gaussian {i} spills out of the room at {q}"
                );
                checked += 1;
            }
            if sigma < 0.69 * spacing {
                shrunk += 1;
            } else {
                full += 1;
            }
        }
    }
    assert!(checked > 10_000, "{checked}");
    assert!(
        shrunk > 500 && full > 2 * shrunk,
        "shrunk {shrunk} axes, full {full}"
    );
}

/// Gaussian `i`'s center and the points one standard deviation out along its in-plane axes.
fn probe_points(g: &Gaussians, i: usize) -> [DVec3; 5] {
    let p = DVec3::from_array(g.means[i].map(f64::from));
    let [w, x, y, z] = g.quats[i].map(f64::from);
    let axes = DMat3::from_quat(DQuat::from_xyzw(x, y, z, w));
    let s = g.log_scales[i].map(|v| f64::from(v).exp());
    [
        p,
        p + axes.x_axis * s[0],
        p - axes.x_axis * s[0],
        p + axes.y_axis * s[1],
        p - axes.y_axis * s[1],
    ]
}

/// By default only Gaussians some camera sees are kept (their center or a point one standard
/// deviation out); `keep_hidden` keeps the rest too.
#[test]
fn gaussians_no_camera_sees_are_left_out() {
    use semsplat::synth::visibility::point_seen;
    let cfg = SynthConfig {
        spacing: 0.1,
        ..small("office", 2, 3, 1)
    };
    let seen = generate(&cfg).unwrap();
    let all = generate(&SynthConfig {
        keep_hidden: true,
        ..cfg
    })
    .unwrap();
    assert!(
        seen.gaussians.len() < all.gaussians.len() * 3 / 4,
        "{} of {} kept from four views",
        seen.gaussians.len(),
        all.gaussians.len()
    );
    let seen_by_a_camera = |s: &SynthScene, i: usize| {
        probe_points(&s.gaussians, i)
            .iter()
            .any(|&q| s.cameras.iter().any(|c| point_seen(&s.room, c, q)))
    };
    let g = &seen.gaussians;
    for i in 0..g.len() {
        assert!(
            seen_by_a_camera(&seen, i),
            "kept Gaussian {i} is seen by no camera"
        );
    }
    // The kept ones are exactly those of the full set that pass the test (same order).
    let kept: Vec<[f32; 3]> = (0..all.gaussians.len())
        .filter(|&i| seen_by_a_camera(&all, i))
        .map(|i| all.gaussians.means[i])
        .collect();
    assert_eq!(kept, g.means);
}

/// Rendering the Gaussians (with the CPU reference rasterizer) approximates the ray-cast truth:
/// opaque, close in color, and the blended one-hot classes agree with the label maps.
#[test]
fn gaussians_render_close_to_the_ray_cast_truth() {
    use semsplat::render::reference::{render, RenderSettings, SemanticMode};
    use semsplat::scene::SemanticLogits;
    let cfg = SynthConfig {
        spacing: 0.05,
        width: 96,
        height: 72,
        ..small("office", 1, 3, 0)
    };
    let scene = generate(&cfg).unwrap();
    let mut g = scene.gaussians.clone();
    let channels = scene.room.classes.classes.len();
    let mut logits = vec![0.0f32; g.len() * channels];
    for (i, &c) in g.class_ids.as_ref().unwrap().iter().enumerate() {
        logits[i * channels + c as usize] = 1.0;
    }
    g.semantics = Some(SemanticLogits { channels, logits });
    let settings = RenderSettings {
        semantic_mode: SemanticMode::RawLogits,
        ..RenderSettings::default()
    };
    for (cam, view) in scene.cameras.iter().zip(&scene.views) {
        let img = render(&g, cam, &settings);
        let n = img.rgb.len();
        let mut se = 0.0;
        let mut agree = 0;
        for i in 0..n {
            for c in 0..3 {
                let d = img.rgb[i][c] - view.rgb[3 * i + c] as f64 / 255.0;
                se += d * d;
            }
            let sem = &img.sem_norm[i * channels..(i + 1) * channels];
            let best = (0..channels)
                .max_by(|&a, &b| sem[a].total_cmp(&sem[b]))
                .unwrap();
            agree += usize::from(best as u16 == view.labels[i]);
        }
        let psnr = -10.0 * (se / (3 * n) as f64).log10();
        let mean_alpha = img.alpha.iter().sum::<f64>() / n as f64;
        let agreement = agree as f64 / n as f64;
        assert!(mean_alpha > 0.99, "{}: mean alpha {mean_alpha}", cam.name);
        assert!(psnr > 20.0, "{}: PSNR {psnr:.1} dB", cam.name);
        assert!(
            agreement > 0.85,
            "{}: labels agree on {agreement:.3}",
            cam.name
        );
    }
}
