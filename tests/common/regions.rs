//! Independent transcriptions of a label map's connected regions, for the consensus tests.

use semsplat::fuse::NO_LABEL;

/// Connected regions by flood fill (an independent transcription of `label_regions`): a
/// region's id is the index of its first pixel in scan order.
pub fn flood_regions(labels: &[u32], w: usize) -> Vec<u32> {
    let h = labels.len() / w;
    let mut id = vec![NO_LABEL; labels.len()];
    for start in 0..labels.len() {
        if labels[start] == NO_LABEL || id[start] != NO_LABEL {
            continue;
        }
        let mut stack = vec![start];
        let next = start as u32;
        id[start] = next;
        while let Some(p) = stack.pop() {
            let (x, y) = (p % w, p / w);
            let mut near = Vec::new();
            if x > 0 {
                near.push(p - 1);
            }
            if x + 1 < w {
                near.push(p + 1);
            }
            if y > 0 {
                near.push(p - w);
            }
            if y + 1 < h {
                near.push(p + w);
            }
            for q in near {
                if labels[q] == labels[p] && id[q] == NO_LABEL {
                    id[q] = next;
                    stack.push(q);
                }
            }
        }
    }
    id
}

/// Whether pixel `pix` (of an image `w` pixels wide) has a 4-neighbour inside the image in
/// another region.
pub fn on_edge(regions: &[u32], w: usize, pix: usize) -> bool {
    let (w, h) = (w as i64, (regions.len() / w) as i64);
    let (x, y) = (pix as i64 % w, pix as i64 / w);
    [(-1, 0), (1, 0), (0, -1), (0, 1)].iter().any(|&(dx, dy)| {
        let (nx, ny) = (x + dx, y + dy);
        (0..w).contains(&nx)
            && (0..h).contains(&ny)
            && regions[(ny * w + nx) as usize] != regions[pix]
    })
}
