//! Display colors of classes in palette previews and classes.json: fixed colors for the class
//! names the presets use (stable across rooms), distinct generated colors for any other name.

const NAMED: &[(&str, [u8; 3])] = &[
    ("floor", [152, 108, 72]),
    ("wall", [174, 199, 232]),
    ("ceiling", [220, 220, 200]),
    ("door", [140, 86, 75]),
    ("window", [23, 190, 207]),
    ("curtain", [219, 219, 141]),
    ("rug", [196, 156, 148]),
    ("desk", [255, 127, 14]),
    ("table", [255, 187, 120]),
    ("dining_table", [255, 187, 120]),
    ("coffee_table", [227, 119, 194]),
    ("side_table", [247, 182, 210]),
    ("chair", [44, 160, 44]),
    ("armchair", [152, 223, 138]),
    ("sofa", [214, 39, 40]),
    ("cushion", [255, 152, 150]),
    ("monitor", [31, 119, 180]),
    ("tv", [57, 59, 121]),
    ("tv_stand", [82, 84, 163]),
    ("speaker", [107, 110, 207]),
    ("cabinet", [148, 103, 189]),
    ("shelf", [197, 176, 213]),
    ("bookshelf", [197, 176, 213]),
    ("book", [188, 189, 34]),
    ("lamp", [255, 215, 0]),
    ("plant", [0, 128, 0]),
    ("vase", [112, 128, 144]),
    ("cup", [230, 85, 13]),
    ("bowl", [253, 141, 60]),
    ("picture", [158, 218, 229]),
    ("clock", [99, 121, 57]),
    ("ball", [214, 97, 107]),
    ("box", [140, 109, 49]),
    ("pillar", [127, 127, 127]),
];

/// The palette color for `name`; `index` picks a distinct color for names not listed.
pub fn class_color(name: &str, index: usize) -> [u8; 3] {
    if let Some((_, c)) = NAMED.iter().find(|(n, _)| *n == name) {
        return *c;
    }
    // Golden-angle hues with alternating lightness stay distinguishable for many classes.
    let hue = (index as f64 * 137.508).rem_euclid(360.0);
    let (s, v) = if index.is_multiple_of(2) {
        (0.65, 0.9)
    } else {
        (0.8, 0.65)
    };
    hsv_to_rgb(hue, s, v)
}

fn hsv_to_rgb(h: f64, s: f64, v: f64) -> [u8; 3] {
    let c = v * s;
    let x = c * (1.0 - ((h / 60.0).rem_euclid(2.0) - 1.0).abs());
    let m = v - c;
    let (r, g, b) = match (h / 60.0) as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    [r, g, b].map(|u| ((u + m) * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn named_and_generated_colors() {
        assert_eq!(class_color("chair", 3), [44, 160, 44]);
        let a = class_color("thing_a", 40);
        let b = class_color("thing_b", 41);
        assert_ne!(a, b);
    }
}
