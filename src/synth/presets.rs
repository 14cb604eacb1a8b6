//! Built-in rooms. Layouts are fixed per preset; the seed jitters free-standing objects
//! (a few centimeters, a few degrees), colors and small clutter, within gaps that keep
//! objects from colliding.

use glam::DVec3;

use super::furniture::{self as f, looks, Placement, Wall};
use super::materials::{Material, Pattern};
use super::room_spec::{ClassSpec, ObjectSpec, RoomSpec};
use crate::util::Rng;

/// Built-in preset names with a one-line description (for `--help` and errors).
pub const PRESETS: &[(&str, &str)] = &[
    ("office", "6 x 5 m office, 12 classes: desks, monitors, chairs, shelf, cabinet, plant, lamp"),
    ("living", "7 x 6 m living room, 28 classes, cluttered: sofa, tables, tv, bookshelf with books, small items"),
    ("tiny", "3 x 3 m test room, 6 classes: two boxes, a ball, a pillar (fast tests)"),
];

/// The preset's room for `seed`, or `None` for an unknown name.
pub fn preset(name: &str, seed: u64) -> Option<RoomSpec> {
    let mut rng = Rng::new(seed).fork(0x5EED_F00D);
    match name {
        "office" => Some(office(&mut rng)),
        "living" => Some(living(&mut rng)),
        "tiny" => Some(tiny(&mut rng)),
        _ => None,
    }
}

pub fn preset_names() -> String {
    PRESETS
        .iter()
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

fn classes(names: &[&str]) -> Vec<ClassSpec> {
    names
        .iter()
        .map(|n| ClassSpec {
            name: n.to_string(),
            color: None,
        })
        .collect()
}

/// A color scaled by a random factor in [1 - amount, 1 + amount].
fn vary(rng: &mut Rng, c: [u8; 3], amount: f64) -> [u8; 3] {
    let k = rng.range_f64(1.0 - amount, 1.0 + amount);
    c.map(|x| (x as f64 * k).round().clamp(0.0, 255.0) as u8)
}

fn jitter(rng: &mut Rng, amount: f64) -> f64 {
    rng.range_f64(-amount, amount)
}

fn room(
    size: [f64; 3],
    floor: Material,
    walls: Material,
    ceiling: Material,
    class_names: &[&str],
) -> RoomSpec {
    RoomSpec {
        size,
        floor,
        walls,
        ceiling,
        classes: classes(class_names),
        confusions: Default::default(),
        objects: Vec::new(),
    }
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

fn office(rng: &mut Rng) -> RoomSpec {
    let carpet = Material::new(vary(rng, [112, 118, 128], 0.05), Pattern::Checker, 0.5)
        .with_color2([96, 100, 110]);
    let walls = Material::new(vary(rng, [222, 218, 206], 0.03), Pattern::Noise, 0.7)
        .with_color2([204, 198, 184]);
    let mut r = room(
        [6.0, 5.0, 2.8],
        carpet,
        walls,
        Material::plain([238, 238, 234]),
        &[
            "floor", "wall", "ceiling", "door", "window", "desk", "chair", "monitor", "cabinet",
            "shelf", "plant", "lamp",
        ],
    );
    let size = DVec3::from_array(r.size);
    let o = &mut r.objects;
    office_desks(rng, size, o);
    office_furniture(rng, size, o);
    office_openings(rng, size, o);
    r
}

/// Two desks against the Y1 wall, each with a monitor and a chair.
fn office_desks(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let desk_top = looks::wood(vary(rng, [176, 138, 96], 0.06));
    let desk_body = looks::plain(vary(rng, [210, 210, 205], 0.04));
    for (i, x) in [1.8, 4.3].into_iter().enumerate() {
        let desk_size = v(1.6, 0.8, 0.75);
        let desk = Wall::Y1.placement(size, x + jitter(rng, 0.1), 0.0, desk_size.y + 0.02);
        o.push(f::desk(
            &format!("desk_{i}"),
            desk,
            desk_size,
            &desk_top,
            &desk_body,
        ));
        let monitor = desk.child(v(jitter(rng, 0.25), 0.15, desk_size.z), jitter(rng, 12.0));
        o.push(f::screen(
            &format!("monitor_{i}"),
            "monitor",
            monitor,
            0.6,
            0.36,
            &looks::plain([40, 40, 44]),
            &looks::screen_panel(),
        ));
        let seat = looks::fabric(vary(rng, [52, 70, 120], 0.15));
        let chair = desk.child(
            v(jitter(rng, 0.15), -0.85 + jitter(rng, 0.05), 0.0),
            180.0 + jitter(rng, 20.0),
        );
        o.push(f::chair(
            &format!("chair_{i}"),
            chair,
            &seat,
            &looks::metal(),
        ));
    }
}

/// A free-standing chair, the cabinet, the shelf, a plant and a floor lamp.
fn office_furniture(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let seat = looks::fabric(vary(rng, [120, 52, 50], 0.15));
    let chair = Placement::at(
        1.3 + jitter(rng, 0.1),
        1.5 + jitter(rng, 0.1),
        0.0,
        rng.range_f64(0.0, 360.0),
    );
    o.push(f::chair("chair_2", chair, &seat, &looks::metal()));
    let cabinet_size = v(0.9, 0.5, 1.1);
    let cabinet = Wall::X1.placement(size, 1.0 + jitter(rng, 0.1), 0.0, cabinet_size.y);
    o.push(f::cabinet(
        "cabinet_0",
        cabinet,
        cabinet_size,
        &looks::plain(vary(rng, [150, 156, 164], 0.05)),
        &looks::metal(),
    ));
    let shelf = Wall::X0.placement(size, 2.5 + jitter(rng, 0.15), 0.0, 0.35);
    o.push(
        f::shelf(
            "shelf_0",
            "shelf",
            shelf,
            v(1.2, 0.35, 1.9),
            5,
            &looks::wood(vary(rng, [150, 110, 72], 0.06)),
        )
        .0,
    );
    let plant = Placement::at(0.45 + jitter(rng, 0.05), 0.45 + jitter(rng, 0.05), 0.0, 0.0);
    o.push(f::plant(
        "plant_0",
        plant,
        0.18,
        1.1,
        &looks::plain(vary(rng, [168, 86, 52], 0.08)),
        &looks::leaves(),
    ));
    let lamp = Placement::at(5.55 + jitter(rng, 0.05), 4.45 + jitter(rng, 0.05), 0.0, 0.0);
    o.push(f::lamp(
        "lamp_0",
        lamp,
        1.65,
        0.2,
        &looks::metal(),
        &looks::fabric(vary(rng, [236, 220, 180], 0.04)),
    ));
}

/// The door and two windows.
fn office_openings(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let door = Wall::Y0.placement(size, 1.5 + jitter(rng, 0.1), 0.0, 0.05);
    o.push(f::door(
        "door_0",
        door,
        0.9,
        2.05,
        &looks::wood(vary(rng, [120, 84, 60], 0.06)),
        &looks::metal(),
    ));
    let frame = looks::plain([236, 236, 236]);
    let window = Wall::X1.placement(size, 3.0 + jitter(rng, 0.1), 0.9, 0.04);
    o.push(f::framed_panel(
        "window_0",
        "window",
        window,
        1.4,
        1.2,
        &frame,
        &looks::glass(),
    ));
    let window = Wall::Y0.placement(size, 4.2 + jitter(rng, 0.1), 0.9, 0.04);
    o.push(f::framed_panel(
        "window_1",
        "window",
        window,
        1.6,
        1.2,
        &frame,
        &looks::glass(),
    ));
}

const LIVING_CLASSES: &[&str] = &[
    "floor",
    "wall",
    "ceiling",
    "door",
    "window",
    "curtain",
    "rug",
    "sofa",
    "armchair",
    "cushion",
    "coffee_table",
    "side_table",
    "dining_table",
    "chair",
    "tv_stand",
    "tv",
    "speaker",
    "bookshelf",
    "book",
    "lamp",
    "plant",
    "vase",
    "cup",
    "bowl",
    "picture",
    "clock",
    "ball",
    "box",
];

fn living(rng: &mut Rng) -> RoomSpec {
    let floor = looks::wood(vary(rng, [164, 122, 84], 0.05));
    let walls = Material::new(vary(rng, [226, 214, 190], 0.03), Pattern::Noise, 0.6)
        .with_color2([208, 194, 168]);
    let mut r = room(
        [7.0, 6.0, 2.7],
        floor,
        walls,
        Material::plain([240, 238, 232]),
        LIVING_CLASSES,
    );
    let size = DVec3::from_array(r.size);
    let o = &mut r.objects;

    living_sofa_and_rug(rng, size, o);
    living_coffee_table(rng, o);
    living_armchair_corner(rng, o);
    living_media_wall(rng, size, o);
    living_bookshelf(rng, size, o);
    living_boxes(rng, o);
    living_dining_corner(rng, o);
    living_plants_and_ball(rng, o);
    living_openings(rng, size, o);
    living_pictures(rng, size, o);
    r
}

/// The sofa against the Y1 wall with its cushions, and the rug in front of it.
fn living_sofa_and_rug(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let sofa = Wall::Y1.placement(size, 3.2 + jitter(rng, 0.1), 0.0, 0.92);
    o.push(f::sofa(
        "sofa_0",
        "sofa",
        sofa,
        2.2,
        &looks::fabric(vary(rng, [96, 110, 122], 0.1)),
    ));
    for (i, x) in [-0.6, 0.0, 0.6].into_iter().enumerate() {
        let color = [[196, 80, 60], [220, 190, 90], [80, 130, 160]][i];
        let cushion = sofa.child(v(x + jitter(rng, 0.05), 0.175, 0.42), jitter(rng, 8.0));
        o.push(f::block(
            &format!("cushion_{i}"),
            "cushion",
            cushion,
            v(0.42, 0.15, 0.38),
            &looks::fabric(vary(rng, color, 0.1)),
        ));
    }
    let rug = Placement::at(3.2, 3.7, 0.0, jitter(rng, 3.0));
    o.push(f::block(
        "rug_0",
        "rug",
        rug,
        v(2.6, 1.8, 0.01),
        &looks::stripes(vary(rng, [170, 60, 56], 0.08), [210, 190, 150], 0.2),
    ));
}

/// The coffee table on the rug with a cup, a bowl, a vase and two stacked books.
fn living_coffee_table(rng: &mut Rng, o: &mut Vec<ObjectSpec>) {
    let coffee = Placement::at(
        3.2 + jitter(rng, 0.08),
        3.9 + jitter(rng, 0.05),
        0.0,
        jitter(rng, 4.0),
    );
    o.push(f::table(
        "coffee_table_0",
        "coffee_table",
        coffee,
        v(1.1, 0.6, 0.42),
        &looks::wood(vary(rng, [120, 80, 52], 0.06)),
        &looks::wood([90, 60, 40]),
    ));
    let top = 0.42;
    o.push(f::vessel(
        "cup_0",
        "cup",
        coffee.child(v(-0.3 + jitter(rng, 0.04), -0.1, top), 0.0),
        0.04,
        0.1,
        &looks::plain(vary(rng, [236, 236, 228], 0.03)),
    ));
    o.push(f::vessel(
        "bowl_0",
        "bowl",
        coffee.child(v(0.22, 0.08 + jitter(rng, 0.03), top), 0.0),
        0.1,
        0.06,
        &looks::plain(vary(rng, [70, 120, 170], 0.1)),
    ));
    o.push(f::vessel(
        "vase_0",
        "vase",
        coffee.child(v(-0.05, 0.14, top), 0.0),
        0.055,
        0.24,
        &looks::fabric(vary(rng, [60, 140, 130], 0.1)),
    ));
    let stack = coffee.child(v(0.36, -0.12, top), jitter(rng, 10.0));
    o.push(f::block(
        "book_0",
        "book",
        stack,
        v(0.22, 0.16, 0.03),
        &looks::plain(vary(rng, [150, 40, 40], 0.1)),
    ));
    o.push(f::block(
        "book_1",
        "book",
        stack.child(v(0.0, 0.0, 0.03), 15.0 + jitter(rng, 10.0)),
        v(0.2, 0.14, 0.025),
        &looks::plain(vary(rng, [40, 70, 140], 0.1)),
    ));
}

/// The armchair with its cushion, the side table with a table lamp, and a floor lamp.
fn living_armchair_corner(rng: &mut Rng, o: &mut Vec<ObjectSpec>) {
    let armchair = Placement::at(
        1.2 + jitter(rng, 0.05),
        3.6 + jitter(rng, 0.1),
        0.0,
        90.0 + jitter(rng, 8.0),
    );
    o.push(f::sofa(
        "armchair_0",
        "armchair",
        armchair,
        0.95,
        &looks::fabric(vary(rng, [130, 96, 70], 0.1)),
    ));
    o.push(f::block(
        "cushion_3",
        "cushion",
        armchair.child(v(0.0, 0.175, 0.42), jitter(rng, 10.0)),
        v(0.4, 0.14, 0.36),
        &looks::fabric(vary(rng, [230, 220, 200], 0.05)),
    ));
    let side = Placement::at(1.6 + jitter(rng, 0.05), 5.3 + jitter(rng, 0.05), 0.0, 0.0);
    o.push(f::round_table(
        "side_table_0",
        "side_table",
        side,
        0.25,
        0.55,
        &looks::wood(vary(rng, [140, 100, 66], 0.06)),
        &looks::metal(),
    ));
    o.push(f::lamp(
        "lamp_0",
        side.child(v(jitter(rng, 0.05), jitter(rng, 0.05), 0.55), 0.0),
        0.45,
        0.12,
        &looks::metal(),
        &looks::fabric([240, 226, 190]),
    ));
    let floor_lamp = Placement::at(4.75 + jitter(rng, 0.04), 5.5 + jitter(rng, 0.04), 0.0, 0.0);
    o.push(f::lamp(
        "lamp_1",
        floor_lamp,
        1.6,
        0.2,
        &looks::metal(),
        &looks::fabric(vary(rng, [236, 214, 170], 0.05)),
    ));
}

/// Media wall: tv stand, tv, two speakers and a clock.
fn living_media_wall(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let stand_size = v(1.6, 0.45, 0.5);
    let stand = Wall::Y0.placement(size, 3.2, 0.0, stand_size.y);
    o.push(f::block(
        "tv_stand_0",
        "tv_stand",
        stand,
        stand_size,
        &looks::wood(vary(rng, [70, 56, 48], 0.08)),
    ));
    o.push(f::screen(
        "tv_0",
        "tv",
        stand.child(v(0.0, 0.05, stand_size.z), jitter(rng, 3.0)),
        1.2,
        0.7,
        &looks::plain([30, 30, 32]),
        &looks::screen_panel(),
    ));
    for (i, x) in [2.1, 4.3].into_iter().enumerate() {
        let place = Wall::Y0.placement(size, x, 0.0, 0.25);
        let mut b = f::PartsBuilder::new(place);
        b.slab(
            0.0,
            0.0,
            0.0,
            v(0.25, 0.25, 0.95),
            &looks::plain([44, 40, 38]),
        );
        b.rod(
            v(0.0, -0.13, 0.3),
            0.08,
            0.02,
            DVec3::Y,
            &looks::plain([20, 20, 20]),
        );
        b.rod(
            v(0.0, -0.13, 0.7),
            0.05,
            0.02,
            DVec3::Y,
            &looks::plain([20, 20, 20]),
        );
        o.push(b.finish(&format!("speaker_{i}"), "speaker"));
    }
    let clock = Wall::Y0.placement(size, 3.2 + jitter(rng, 0.1), 1.95, 0.04);
    o.push(f::clock(
        "clock_0",
        clock,
        0.18,
        &looks::plain([246, 244, 236]),
        &looks::plain([60, 50, 44]),
    ));
}

/// Bookshelf filled with books (many small, partly hidden instances).
fn living_bookshelf(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let shelf_size = v(1.4, 0.35, 1.9);
    let shelf = Wall::X1.placement(size, 4.2, 0.0, shelf_size.y);
    let (shelf_object, tops) = f::shelf(
        "bookshelf_0",
        "bookshelf",
        shelf,
        shelf_size,
        5,
        &looks::wood(vary(rng, [110, 76, 50], 0.06)),
    );
    o.push(shelf_object);
    let mut book = 2;
    for &z in &tops[..tops.len() - 1] {
        let mut x = -0.5 * shelf_size.x + 0.03 + rng.range_f64(0.0, 0.1);
        while x < 0.5 * shelf_size.x - 0.12 {
            if rng.bool(0.15) {
                x += rng.range_f64(0.08, 0.2);
                continue;
            }
            let (w, h, d) = (
                rng.range_f64(0.03, 0.06),
                rng.range_f64(0.18, 0.3),
                rng.range_f64(0.17, 0.24),
            );
            let color = [
                [150, 40, 40],
                [40, 70, 140],
                [40, 110, 60],
                [200, 160, 60],
                [90, 60, 110],
                [220, 220, 210],
            ][rng.below(6) as usize];
            let place = shelf.child(v(x + 0.5 * w, -0.5 * shelf_size.y + 0.5 * d + 0.02, z), 0.0);
            o.push(f::block(
                &format!("book_{book}"),
                "book",
                place,
                v(w, d, h),
                &looks::plain(vary(rng, color, 0.12)),
            ));
            book += 1;
            x += w + rng.range_f64(0.0, 0.01);
        }
    }
}

/// Two stacked boxes.
fn living_boxes(rng: &mut Rng, o: &mut Vec<ObjectSpec>) {
    let box0 = Placement::at(
        6.2 + jitter(rng, 0.03),
        3.1 + jitter(rng, 0.03),
        0.0,
        jitter(rng, 10.0),
    );
    o.push(f::block(
        "box_0",
        "box",
        box0,
        v(0.4, 0.35, 0.3),
        &looks::plain(vary(rng, [176, 140, 96], 0.06)),
    ));
    o.push(f::block(
        "box_1",
        "box",
        box0.child(v(0.0, 0.0, 0.3), jitter(rng, 25.0)),
        v(0.28, 0.22, 0.18),
        &looks::plain(vary(rng, [200, 70, 70], 0.1)),
    ));
}

/// Dining corner: table with a bowl and two cups, four chairs.
fn living_dining_corner(rng: &mut Rng, o: &mut Vec<ObjectSpec>) {
    let dining = Placement::at(
        5.5 + jitter(rng, 0.05),
        1.7 + jitter(rng, 0.05),
        0.0,
        jitter(rng, 3.0),
    );
    o.push(f::table(
        "dining_table_0",
        "dining_table",
        dining,
        v(1.4, 0.9, 0.75),
        &looks::wood(vary(rng, [186, 146, 104], 0.05)),
        &looks::wood([120, 90, 64]),
    ));
    o.push(f::vessel(
        "bowl_1",
        "bowl",
        dining.child(v(jitter(rng, 0.1), jitter(rng, 0.08), 0.75), 0.0),
        0.14,
        0.08,
        &looks::plain(vary(rng, [236, 230, 214], 0.04)),
    ));
    for (i, (x, y)) in [(-0.4, -0.2), (0.42, 0.18)].into_iter().enumerate() {
        let cup = dining.child(v(x + jitter(rng, 0.04), y + jitter(rng, 0.04), 0.75), 0.0);
        o.push(f::vessel(
            &format!("cup_{}", i + 1),
            "cup",
            cup,
            0.04,
            0.1,
            &looks::plain(vary(rng, [200, 90, 60], 0.15)),
        ));
    }
    let seat = looks::wood(vary(rng, [150, 110, 76], 0.06));
    for (i, (x, y, yaw)) in [
        (-0.35, -0.85, 180.0),
        (0.35, -0.85, 180.0),
        (-0.35, 0.85, 0.0),
        (0.35, 0.85, 0.0),
    ]
    .into_iter()
    .enumerate()
    {
        let chair = dining.child(
            v(x + jitter(rng, 0.04), y + jitter(rng, 0.04), 0.0),
            yaw + jitter(rng, 10.0),
        );
        o.push(f::chair(
            &format!("chair_{i}"),
            chair,
            &seat,
            &looks::wood([110, 80, 56]),
        ));
    }
}

/// Two potted plants and a ball.
fn living_plants_and_ball(rng: &mut Rng, o: &mut Vec<ObjectSpec>) {
    let pot = looks::plain(vary(rng, [176, 90, 56], 0.08));
    o.push(f::plant(
        "plant_0",
        Placement::at(0.45, 0.45, 0.0, 0.0),
        0.2,
        1.2,
        &pot,
        &looks::leaves(),
    ));
    o.push(f::plant(
        "plant_1",
        Placement::at(6.5 + jitter(rng, 0.05), 5.5, 0.0, 0.0),
        0.16,
        0.9,
        &pot,
        &looks::leaves(),
    ));
    o.push(f::ball(
        "ball_0",
        Placement::at(2.0 + jitter(rng, 0.15), 2.3 + jitter(rng, 0.15), 0.0, 0.0),
        0.11,
        &looks::fabric(vary(rng, [220, 60, 50], 0.1)),
    ));
}

/// Door, windows and curtains.
fn living_openings(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let door = Wall::X0.placement(size, 5.0, 0.0, 0.05);
    o.push(f::door(
        "door_0",
        door,
        0.9,
        2.05,
        &looks::plain(vary(rng, [236, 232, 220], 0.02)),
        &looks::metal(),
    ));
    let frame = looks::plain([240, 240, 240]);
    o.push(f::framed_panel(
        "window_0",
        "window",
        Wall::Y0.placement(size, 5.5, 0.9, 0.04),
        1.5,
        1.3,
        &frame,
        &looks::glass(),
    ));
    o.push(f::framed_panel(
        "window_1",
        "window",
        Wall::X0.placement(size, 2.5, 0.9, 0.04),
        1.4,
        1.3,
        &frame,
        &looks::glass(),
    ));
    let curtain = looks::stripes(vary(rng, [186, 160, 120], 0.06), [160, 132, 96], 0.12);
    for (i, x) in [4.65, 6.4].into_iter().enumerate() {
        o.push(f::block(
            &format!("curtain_{i}"),
            "curtain",
            Wall::Y0.placement(size, x, 0.25, 0.08),
            v(0.35, 0.08, 2.3),
            &curtain,
        ));
    }
}

/// Three pictures, one per wall.
fn living_pictures(rng: &mut Rng, size: DVec3, o: &mut Vec<ObjectSpec>) {
    let art = [
        ([200, 120, 60], [60, 90, 160]),
        ([80, 150, 90], [230, 210, 120]),
        ([150, 60, 110], [240, 200, 200]),
    ];
    let pictures = [
        (Wall::Y1, 3.2, 1.3, 1.2, 0.7),
        (Wall::X1, 1.7, 1.3, 0.8, 0.6),
        (Wall::X0, 4.0, 1.4, 0.5, 0.6),
    ];
    for (i, (wall, along, z, w, h)) in pictures.into_iter().enumerate() {
        let place = wall.placement(size, along + jitter(rng, 0.05), z, 0.04);
        let canvas = looks::canvas(vary(rng, art[i].0, 0.1), art[i].1);
        o.push(f::framed_panel(
            &format!("picture_{i}"),
            "picture",
            place,
            w,
            h,
            &looks::wood([60, 44, 32]),
            &canvas,
        ));
    }
}

fn tiny(rng: &mut Rng) -> RoomSpec {
    let floor = Material::new([150, 150, 156], Pattern::Checker, 0.5).with_color2([110, 110, 118]);
    let walls = Material::new([210, 206, 196], Pattern::Noise, 0.5).with_color2([190, 184, 170]);
    let mut r = room(
        [3.0, 3.0, 2.4],
        floor,
        walls,
        Material::plain([236, 236, 232]),
        &["floor", "wall", "ceiling", "box", "ball", "pillar"],
    );
    let o = &mut r.objects;
    let b0 = Placement::at(
        0.9 + jitter(rng, 0.05),
        2.0 + jitter(rng, 0.05),
        0.0,
        jitter(rng, 20.0),
    );
    o.push(f::block(
        "box_0",
        "box",
        b0,
        v(0.5, 0.5, 0.5),
        &looks::wood(vary(rng, [190, 140, 90], 0.08)),
    ));
    let b1 = Placement::at(
        2.1 + jitter(rng, 0.05),
        2.1 + jitter(rng, 0.05),
        0.0,
        30.0 + jitter(rng, 20.0),
    );
    o.push(f::block(
        "box_1",
        "box",
        b1,
        v(0.4, 0.6, 0.3),
        &looks::plain(vary(rng, [60, 90, 170], 0.1)),
    ));
    let ball = Placement::at(1.5 + jitter(rng, 0.05), 1.0 + jitter(rng, 0.05), 0.0, 0.0);
    o.push(f::ball(
        "ball_0",
        ball,
        0.25,
        &looks::fabric(vary(rng, [210, 60, 50], 0.1)),
    ));
    let pillar = Placement::at(2.3, 0.7, 0.0, 0.0);
    o.push(f::vessel(
        "pillar_0",
        "pillar",
        pillar,
        0.15,
        1.2,
        &looks::stripes([200, 200, 200], [120, 120, 120], 0.1),
    ));
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::room::Room;
    use glam::DVec3;

    #[test]
    fn presets_build_with_expected_class_counts() {
        for (name, classes) in [("office", 12), ("living", 28), ("tiny", 6)] {
            let room = Room::build(preset(name, 1).unwrap()).unwrap();
            assert_eq!(room.classes.classes.len(), classes, "{name}");
            // Every listed class is used by some instance.
            for c in &room.classes.classes {
                assert!(
                    room.instances.iter().any(|i| i.class_id == c.id),
                    "{name}: unused class {}",
                    c.name
                );
            }
        }
        assert!(preset("nope", 1).is_none());
    }

    #[test]
    fn seed_jitters_layout_deterministically() {
        assert_eq!(preset("office", 3), preset("office", 3));
        assert_ne!(preset("office", 3), preset("office", 4));
    }

    /// Volume points of each object that lie more than 1 cm inside another object, as
    /// "a <-> b" pairs (intended overlaps aside, objects must not interpenetrate).
    fn overlaps(room: &Room) -> Vec<String> {
        let mut found = Vec::new();
        let objects: Vec<_> = room.instances.iter().filter(|i| !i.structural).collect();
        for a in &objects {
            let parts_a: Vec<_> = room
                .primitives
                .iter()
                .filter(|p| p.instance == a.id)
                .collect();
            let b_box = room.instance_bounds(a.id);
            let step = 0.025;
            let n = ((b_box.max - b_box.min) / step).ceil().as_uvec3();
            'search: for other in &objects {
                if other.id <= a.id {
                    continue;
                }
                let ob = room.instance_bounds(other.id);
                if !(b_box.min.cmple(ob.max).all() && ob.min.cmple(b_box.max).all()) {
                    continue;
                }
                let parts_b: Vec<_> = room
                    .primitives
                    .iter()
                    .filter(|p| p.instance == other.id)
                    .collect();
                for ix in 0..=n.x {
                    for iy in 0..=n.y {
                        for iz in 0..=n.z {
                            let p = b_box.min + DVec3::new(ix as f64, iy as f64, iz as f64) * step;
                            let deep = |parts: &[&crate::synth::room::Primitive]| {
                                parts.iter().any(|q| q.shape.sdf(p) < -0.01)
                            };
                            if deep(&parts_a) && deep(&parts_b) {
                                found.push(format!("{} <-> {}", a.name, other.name));
                                continue 'search;
                            }
                        }
                    }
                }
            }
        }
        found
    }

    #[test]
    fn objects_do_not_interpenetrate_except_where_intended() {
        // The check itself finds a planted collision.
        let mut spec = preset("tiny", 0).unwrap();
        let mut clash = spec.objects[0].clone();
        clash.name = "clash".into();
        spec.objects.push(clash);
        assert_eq!(
            overlaps(&Room::build(spec).unwrap()),
            vec!["box_0 <-> clash".to_string()]
        );
        // Curtains hang over window frames on purpose.
        let intended = |pair: &str| pair.contains("curtain_") && pair.contains("window_");
        for seed in 0..2 {
            for name in ["office", "living", "tiny"] {
                let room = Room::build(preset(name, seed).unwrap()).unwrap();
                let bad: Vec<String> = overlaps(&room)
                    .into_iter()
                    .filter(|p| !intended(p))
                    .collect();
                assert!(bad.is_empty(), "{name} seed {seed}: {bad:?}");
            }
        }
    }
}
