//! A strip of same-sized images side by side with a title over each (e.g. RGB, true labels,
//! each method's labels), as one PNG.

use std::path::Path;

use anyhow::{anyhow, ensure, Result};
use plotters::prelude::*;

use crate::util::write_bytes_atomic;

const GAP: u32 = 8;
const TITLE_H: u32 = 34;
/// Narrowest panel drawn: smaller images are enlarged (nearest neighbour, a whole factor)
/// so a method's name fits over its panel and its labels can be told apart.
const MIN_PANEL_W: u32 = 192;

/// `panels`: (title, RGB8 pixels) of `w` x `h` images.
pub fn write_strip(path: &Path, w: u32, h: u32, panels: &[(&str, Vec<u8>)]) -> Result<()> {
    ensure!(!panels.is_empty(), "no panels");
    ensure!(
        panels.iter().all(|(_, p)| p.len() == (w * h * 3) as usize),
        "panels must be {w}x{h} RGB"
    );
    super::chart::register_fonts();
    let scale = MIN_PANEL_W.div_ceil(w).max(1);
    let (pw, ph) = (w * scale, h * scale);
    let total_w = panels.len() as u32 * (pw + GAP) + GAP;
    let total_h = ph + TITLE_H + GAP;
    let mut buf = vec![255u8; (total_w * total_h * 3) as usize];
    for (k, (_, pixels)) in panels.iter().enumerate() {
        let x0 = GAP + k as u32 * (pw + GAP);
        for y in 0..ph {
            let row = &pixels[((y / scale) * w * 3) as usize..((y / scale + 1) * w * 3) as usize];
            let dst = (((y + TITLE_H) * total_w + x0) * 3) as usize;
            for (x, out) in buf[dst..dst + (pw * 3) as usize].chunks_mut(3).enumerate() {
                let src = (x / scale as usize) * 3;
                out.copy_from_slice(&row[src..src + 3]);
            }
        }
    }
    {
        let root = BitMapBackend::with_buffer(&mut buf, (total_w, total_h)).into_drawing_area();
        // One size for every title: the largest at which each fits over its panel.
        let size = (panels.iter())
            .map(|(title, _)| super::chart::fitting_size(&root, title, 20.0, pw))
            .fold(20.0, f64::min);
        for (k, (title, _)) in panels.iter().enumerate() {
            let x0 = (GAP + k as u32 * (pw + GAP)) as i32;
            root.draw_text(
                title,
                &("sans-serif", size).into_font().color(&BLACK),
                (x0, 7),
            )
            .map_err(|e| anyhow!("drawing strip: {e:?}"))?;
        }
        root.present()
            .map_err(|e| anyhow!("drawing strip: {e:?}"))?;
    }
    let img = image::RgbImage::from_raw(total_w, total_h, buf)
        .ok_or_else(|| anyhow!("strip buffer size"))?;
    let mut png = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)?;
    write_bytes_atomic(path, &png)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Panels narrower than [`MIN_PANEL_W`] are enlarged by a whole factor, each source
    /// pixel a block of that side, beside each other in order.
    #[test]
    fn small_panels_are_enlarged_pixel_for_pixel() {
        let (w, h) = (40u32, 30u32);
        let panel = |seed: u32| -> Vec<u8> {
            (0..w * h * 3)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> (seed + 3)) as u8)
                .collect()
        };
        let panels = [("a", panel(1)), ("a longer title", panel(2))];
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("strip.png");
        write_strip(&path, w, h, &panels).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        let scale = 5; // ceil(192 / 40)
        assert_eq!(
            img.dimensions(),
            (2 * (w * scale + GAP) + GAP, h * scale + TITLE_H + GAP)
        );
        for (k, (_, pixels)) in panels.iter().enumerate() {
            let x0 = GAP + k as u32 * (w * scale + GAP);
            for (x, y) in [(0, 0), (w - 1, h - 1), (17, 9), (3, 28)] {
                let src = ((y * w + x) * 3) as usize;
                for (dx, dy) in [(0, 0), (scale - 1, scale - 1)] {
                    let got = img.get_pixel(x0 + x * scale + dx, TITLE_H + y * scale + dy);
                    assert_eq!(got.0, pixels[src..src + 3], "panel {k} ({x}, {y})");
                }
            }
        }
    }
}
