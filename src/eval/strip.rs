//! A strip of same-sized images side by side with a title over each (e.g. RGB, true labels,
//! each method's labels), as one PNG.

use std::path::Path;

use anyhow::{anyhow, ensure, Result};
use plotters::prelude::*;

use crate::util::write_bytes_atomic;

const GAP: u32 = 8;
const TITLE_H: u32 = 34;

/// `panels`: (title, RGB8 pixels) of `w` x `h` images.
pub fn write_strip(path: &Path, w: u32, h: u32, panels: &[(&str, Vec<u8>)]) -> Result<()> {
    ensure!(!panels.is_empty(), "no panels");
    ensure!(
        panels.iter().all(|(_, p)| p.len() == (w * h * 3) as usize),
        "panels must be {w}x{h} RGB"
    );
    super::chart::register_fonts();
    let total_w = panels.len() as u32 * (w + GAP) + GAP;
    let total_h = h + TITLE_H + GAP;
    let mut buf = vec![255u8; (total_w * total_h * 3) as usize];
    for (k, (_, pixels)) in panels.iter().enumerate() {
        let x0 = GAP + k as u32 * (w + GAP);
        for y in 0..h {
            let src = &pixels[(y * w * 3) as usize..((y + 1) * w * 3) as usize];
            let dst = (((y + TITLE_H) * total_w + x0) * 3) as usize;
            buf[dst..dst + src.len()].copy_from_slice(src);
        }
    }
    {
        let root = BitMapBackend::with_buffer(&mut buf, (total_w, total_h)).into_drawing_area();
        for (k, (title, _)) in panels.iter().enumerate() {
            let x0 = (GAP + k as u32 * (w + GAP)) as i32;
            let size = super::chart::fitting_size(&root, title, 20.0, w);
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
