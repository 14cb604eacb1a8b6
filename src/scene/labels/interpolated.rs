//! Label ids that look made by interpolation: a label map resized with bilinear (or bicubic)
//! filtering, or saved as JPEG, gets ids between two classes along their edges, classes the
//! segmenter never gave (between ids 1 and 3 a step of 2). Fused, they are phantom classes,
//! silently: a scene with no ceiling had 121 Gaussians labeled ceiling (id 2) from maps
//! resized 2x with bilinear filtering. Such an id lies in short runs with a lower id on one
//! side and a higher on the other; a class's own region is not a few pixels wide between
//! ids on either side of its own.

use super::LabelMap;
use crate::scene::classes::IGNORE_U16;

/// The longest run (pixels along a row or a column) counted as a step between two ids: a
/// 2x bilinear resize makes steps of one or two pixels, larger factors wider ones.
const MAX_STEP: usize = 5;

/// The share of crossings through steps from which maps look interpolated
/// ([`StepTally::looks_interpolated`]).
const STEP_SHARE: f64 = 0.2;

/// The share of short runs between two ids at least two apart that lie between them, from
/// which maps look interpolated: chance is about a third (runs of ids that have nothing to
/// do with their sides: blocks of random ids 0.33-0.37, a segmenter's maps 0.25-0.43), a
/// resize or JPEG makes most of them ids between (0.66-1.0).
const BETWEEN_SHARE: f64 = 0.5;

/// How many ids a warning names.
const SUSPECTS_NAMED: usize = 5;

/// An id is named from this many pixels on steps on, and maps are judged from this many
/// crossings through steps.
const MIN_PIXELS: u64 = 8;

/// Per label id, its pixels and those on steps, summed over the maps added.
#[derive(Clone, Debug, Default)]
pub struct StepTally {
    /// Per 16-bit label value (empty until a map is added; the last slot counts unlabeled
    /// pixels, as [`LabelMap::count_into`] fills it): its pixels.
    pixels: Vec<u64>,
    /// Per label value: its pixels on a step, and the (lower, higher) ids around one.
    on_steps: Vec<u64>,
    around: Vec<(u16, u16)>,
    /// Edges between two ids at least two apart (room for an id between) crossed through a
    /// step, and crossed directly (neither side a step).
    crossings: Crossings,
}

/// How the edges between ids at least two apart are crossed along rows and columns.
#[derive(Clone, Copy, Debug, Default)]
pub struct Crossings {
    pub through_steps: u64,
    pub direct: u64,
    /// Runs of at most [`MAX_STEP`] between two ids at least two apart (room for an id
    /// between): steps, and runs of an id outside the two.
    pub short_between_apart: u64,
}

/// The pixels on steps of a map being added (each once, though its row and its column may
/// both find it on one), and per id the ids around its last step found.
struct StepMarks {
    on_step: Vec<bool>,
    around: Vec<(u16, u16)>,
}

impl StepTally {
    /// Adds a map's ids: each pixel, and whether it lies on a step (a run of at most
    /// [`MAX_STEP`] pixels of its id, along its row or its column, between a lower id on
    /// one side and a higher on the other).
    pub fn add(&mut self, map: &LabelMap) {
        let slots = IGNORE_U16 as usize + 1;
        if self.pixels.is_empty() {
            (self.pixels, self.on_steps) = (vec![0; slots], vec![0; slots]);
            self.around = vec![(0, 0); slots];
        }
        map.count_into(&mut self.pixels);
        let (w, h) = (map.width as usize, map.height as usize);
        let mut marks = StepMarks {
            on_step: vec![false; w * h],
            around: std::mem::take(&mut self.around),
        };
        let c = &mut self.crossings;
        for y in 0..h {
            mark_steps(
                &map.labels,
                Line {
                    first: y * w,
                    stride: 1,
                    len: w,
                },
                &mut marks,
                c,
            );
        }
        for x in 0..w {
            mark_steps(
                &map.labels,
                Line {
                    first: x,
                    stride: w,
                    len: h,
                },
                &mut marks,
                c,
            );
        }
        for (&id, _) in map.labels.iter().zip(&marks.on_step).filter(|(_, &on)| on) {
            self.on_steps[id as usize] += 1;
        }
        self.around = marks.around;
    }

    /// How the maps added cross from id to id.
    pub fn crossings(&self) -> Crossings {
        self.crossings
    }

    /// Adds another tally's counts.
    pub fn merge(&mut self, other: StepTally) {
        self.crossings.through_steps += other.crossings.through_steps;
        self.crossings.direct += other.crossings.direct;
        self.crossings.short_between_apart += other.crossings.short_between_apart;
        if self.pixels.is_empty() {
            (self.pixels, self.on_steps, self.around) =
                (other.pixels, other.on_steps, other.around);
            return;
        }
        for (id, &on_steps) in other.on_steps.iter().enumerate() {
            self.pixels[id] += other.pixels[id];
            self.on_steps[id] += on_steps;
            if self.on_steps[id] == on_steps {
                self.around[id] = other.around[id]; // an example from the tally that has one
            }
        }
    }

    /// Whether the maps look interpolated: at least [`STEP_SHARE`] of their crossings from
    /// an id to one at least two apart go through a step (a segmenter's own maps: 0.1-5.2%,
    /// rooms of thousands of random ids included; resized with bilinear filtering 99.7-100%,
    /// saved as JPEG 23-90%), and the steps are more than chance makes of short runs
    /// ([`BETWEEN_SHARE`]): in maps of small blocks of random ids (2 to 5 pixels) 39-44% of
    /// the crossings go through a block whose id happens to lie between its sides'.
    pub fn looks_interpolated(&self) -> bool {
        let c = self.crossings;
        let crossed = c.through_steps + c.direct;
        let steps = c.through_steps as f64;
        c.through_steps >= MIN_PIXELS
            && steps >= STEP_SHARE * crossed as f64
            && steps >= BETWEEN_SHARE * c.short_between_apart as f64
    }

    /// The ids most likely made by interpolation, with an example of the ids around one
    /// of their steps, (id, lower, higher): those at least [`MIN_PIXELS`] of whose pixels
    /// lie on steps, the largest share of their pixels first, at most [`SUSPECTS_NAMED`].
    pub fn suspects(&self) -> Vec<(u16, u16, u16)> {
        let labeled = self.on_steps.len().saturating_sub(1); // not the unlabeled slot
        let mut stepped: Vec<(f64, u16)> = (0..labeled)
            .filter(|&id| self.on_steps[id] >= MIN_PIXELS)
            .map(|id| (self.on_steps[id] as f64 / self.pixels[id] as f64, id as u16))
            .collect();
        stepped.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        (stepped.into_iter().take(SUSPECTS_NAMED))
            .map(|(_, id)| (id, self.around[id as usize].0, self.around[id as usize].1))
            .collect()
    }

    /// A warning where the maps look interpolated, naming the likeliest ids; `of` names
    /// the maps.
    pub fn warning(&self, of: &str) -> Option<String> {
        if !self.looks_interpolated() {
            return None;
        }
        let suspects = self.suspects();
        let &(id, lower, higher) = suspects.first()?;
        let ids: Vec<String> = suspects.iter().map(|s| s.0.to_string()).collect();
        let c = self.crossings;
        Some(format!(
            "warning: {of} look resized with interpolation or saved as JPEG: {:.0}% of their \
             edges between two ids pass through a step of one to {MAX_STEP} pixels of an id \
             between them (id {id} between {lower} and {higher}), an id no segmenter gave \
             there, which would be fused as a class of its own (most stepped: {}). Resize \
             label maps with nearest neighbour and keep them PNG",
            100.0 * c.through_steps as f64 / (c.through_steps + c.direct) as f64,
            ids.join(", ")
        ))
    }
}

/// A row or a column of a map: pixel `first + k * stride` for k in 0..len.
#[derive(Clone, Copy)]
struct Line {
    first: usize,
    stride: usize,
    len: usize,
}

/// A run of one id along a line: its id, first position on the line and length, and
/// whether it is a step.
#[derive(Clone, Copy)]
struct Run {
    id: u16,
    at: usize,
    len: usize,
    step: bool,
}

/// Marks, along one line of pixels, the pixels of each run of at most [`MAX_STEP`] that
/// lies between a lower id and a higher one, and counts how the line crosses from id to
/// id. The runs are taken as the line is read: each is judged once the next one starts.
fn mark_steps(labels: &[u16], line: Line, marks: &mut StepMarks, crossings: &mut Crossings) {
    let id_at = |k: usize| labels[line.first + k * line.stride];
    let known = |v: u16| v != LabelMap::IGNORE;
    // The run before the last, and the last (complete once a new id starts).
    let (mut before, mut last): (Option<Run>, Option<Run>) = (None, None);
    let mut k = 0;
    while k <= line.len {
        let next = (k < line.len).then(|| id_at(k));
        let start = k;
        if let Some(id) = next {
            while k < line.len && id_at(k) == id {
                k += 1;
            }
        } else {
            k += 1;
        }
        if let Some(run) = last.as_mut() {
            if let (Some(b), Some(after)) = (before, next) {
                let (lower, higher) = (b.id.min(after), b.id.max(after));
                let all_known = known(run.id) && known(b.id) && known(after);
                if run.len <= MAX_STEP && all_known && higher - lower >= 2 {
                    crossings.short_between_apart += 1;
                }
                if run.len <= MAX_STEP && all_known && lower < run.id && run.id < higher {
                    run.step = true;
                    crossings.through_steps += 1;
                    for p in (run.at..run.at + run.len).map(|q| line.first + q * line.stride) {
                        marks.on_step[p] = true;
                    }
                    marks.around[run.id as usize] = (lower, higher);
                }
            }
            if let Some(b) = before {
                let apart = known(b.id) && known(run.id) && b.id.abs_diff(run.id) >= 2;
                if apart && !b.step && !run.step {
                    crossings.direct += 1;
                }
            }
        }
        before = last;
        last = next.map(|id| Run {
            id,
            at: start,
            len: k - start,
            step: false,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(w: u32, rows: &[&[u16]]) -> LabelMap {
        LabelMap::new(w, rows.len() as u32, rows.concat()).unwrap()
    }

    /// A bilinear 2x resize of an edge between ids 1 and 3 puts a 2 between them: the maps
    /// look interpolated and id 2 is named. Edges crossed directly, a thin 2 between two 1s
    /// and unlabeled pixels beside a run are no steps.
    #[test]
    fn steps_between_a_lower_and_a_higher_id_are_flagged() {
        let row: &[u16] = &[1, 1, 1, 2, 3, 3, 3];
        let mut tally = StepTally::default();
        tally.add(&map(7, &[row; 8]));
        assert!(tally.looks_interpolated());
        assert_eq!(tally.suspects(), [(2, 1, 3)]);
        let warning = tally.warning("x").unwrap();
        assert!(warning.contains("id 2 between 1 and 3") && warning.contains("100%"));

        let mut clean = StepTally::default();
        let direct: &[u16] = &[0, 0, 0, 0, 5, 5, 5, 5, 5, 5, 9, 9, 9];
        let thin: &[u16] = &[1, 1, 2, 1, 1, 1, 1];
        let ignored: &[u16] = &[1, 2, LabelMap::IGNORE, 3];
        clean.add(&map(13, &[direct; 8]));
        clean.add(&map(7, &[thin; 8]));
        clean.add(&map(4, &[ignored; 8]));
        let c = clean.crossings();
        assert_eq!((c.through_steps, c.direct), (0, 16));
        assert!(!clean.looks_interpolated() && clean.warning("x").is_none());
    }

    /// Along columns as along rows; steps among many edges crossed directly (a fifth or
    /// less of the crossings) are a segmenter's thin objects, not interpolation.
    #[test]
    fn columns_count_and_a_few_steps_among_direct_edges_do_not() {
        let mut tally = StepTally::default();
        let rows: Vec<Vec<u16>> = (0..9)
            .map(|y| vec![[4, 4, 4, 5, 6, 6, 6, 6, 6][y]; 9])
            .collect();
        let rows: Vec<&[u16]> = rows.iter().map(Vec::as_slice).collect();
        tally.add(&map(9, &rows));
        assert_eq!(tally.suspects(), [(5, 4, 6)]);
        assert!(tally.looks_interpolated());
        // 9 steps, then 48 direct crossings (3 a row): 16% through steps.
        let edges: &[u16] = &[0, 0, 9, 9, 0, 0, 9, 9];
        let mut more = StepTally::default();
        more.add(&map(8, &[edges; 16]));
        tally.merge(more);
        assert!(!tally.looks_interpolated());
    }

    /// Blocks of random ids a few pixels wide cross through many runs between their
    /// sides' ids, as many as chance gives: no warning. Resized 2x with a step between
    /// every two blocks of ids at least two apart, they warn.
    #[test]
    fn blocks_of_random_ids_are_not_interpolation() {
        let mut rng = crate::util::rng::Rng::new(5);
        let (blocks, side) = (40, 3);
        let ids: Vec<u16> = (0..blocks * blocks)
            .map(|_| rng.below(1000) as u16)
            .collect();
        let pixel = |x: usize, y: usize| ids[(y / side) * blocks + x / side];
        let w = blocks * side;
        let labels: Vec<u16> = (0..w * w).map(|p| pixel(p % w, p / w)).collect();
        let mut tally = StepTally::default();
        tally.add(&LabelMap::new(w as u32, w as u32, labels).unwrap());
        let c = tally.crossings();
        assert!(c.through_steps as f64 >= STEP_SHARE * (c.through_steps + c.direct) as f64);
        assert!(!tally.looks_interpolated() && tally.warning("x").is_none());

        // Each block's right column the mean of its id and the next block's.
        let resized: Vec<u16> = (0..w * w)
            .map(|p| {
                let (x, y) = (p % w, p / w);
                match x % side == side - 1 && x + 1 < w {
                    true => ((u32::from(pixel(x, y)) + u32::from(pixel(x + 1, y))) / 2) as u16,
                    false => pixel(x, y),
                }
            })
            .collect();
        let mut tally = StepTally::default();
        tally.add(&LabelMap::new(w as u32, w as u32, resized).unwrap());
        assert!(tally.looks_interpolated());
    }
}
