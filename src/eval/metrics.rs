//! Segmentation metrics: pixel accuracy and mean IoU over the classes present in the ground
//! truth (ignore pixels excluded), per class too, and per-Gaussian accuracy.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::scene::classes::ClassTable;
use crate::scene::labels::list_some;

/// Counts of (true class, predicted class) over labeled pixels; a prediction of `None`
/// (nothing rendered there) counts against the true class.
#[derive(Clone, Debug, Default)]
pub struct Confusion {
    counts: BTreeMap<(u32, Option<u32>), u64>,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ClassIou {
    pub id: u32,
    /// From the class table, when the caller has one ([`SegmentationScores::name_classes`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    pub iou: f64,
    /// Ground-truth pixels of this class.
    pub pixels: u64,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct SegmentationScores {
    pub pixel_accuracy: f64,
    pub miou: f64,
    /// Classes present in the ground truth, by id.
    pub per_class: Vec<ClassIou>,
    pub labeled_pixels: u64,
}

impl SegmentationScores {
    /// Names every class of `per_class` from `table` (ids it does not list stay unnamed).
    pub fn name_classes(&mut self, table: &ClassTable) {
        for c in &mut self.per_class {
            c.name = table.get(c.id).map(|info| info.name.clone());
        }
    }

    /// What a user should know of these scores, of a scene whose Gaussians hold
    /// `scene_classes` (-1: none): the true classes a class table given (`named`: after
    /// [`SegmentationScores::name_classes`]) does not name, and a scene that holds none of
    /// the true classes (every labeled pixel scored wrong: other label maps, or other ids).
    pub fn notes(&self, scene_classes: &[i32], named: bool) -> Vec<String> {
        let ids = |classes: &mut dyn Iterator<Item = u32>| {
            list_some(&classes.map(|id| id.to_string()).collect::<Vec<_>>())
        };
        let held: std::collections::BTreeSet<u32> = (scene_classes.iter())
            .filter_map(|&c| u32::try_from(c).ok())
            .collect();
        if !self.per_class.is_empty() && self.per_class.iter().all(|c| !held.contains(&c.id)) {
            // Then no true class is the scene's, and whether a table names them is moot.
            return vec![format!(
                "note: no Gaussian holds a class the label maps use (theirs: {}; the scene's: \
                 {}): every labeled pixel is scored wrong; check that the maps are of this \
                 scene's classes",
                ids(&mut self.per_class.iter().map(|c| c.id)),
                ids(&mut held.iter().copied()),
            )];
        }
        let unnamed = self.per_class.iter().filter(|c| c.name.is_none());
        match named && unnamed.clone().next().is_some() {
            true => vec![format!(
                "note: the label maps use class ids the class table does not list: {}; they are \
                 scored without names",
                ids(&mut unnamed.map(|c| c.id))
            )],
            false => Vec::new(),
        }
    }
}

impl Confusion {
    /// Adds one view. `ignore` marks unlabeled ground-truth pixels (left out entirely).
    /// Predictions are user class ids of any width up to 32 bits (never cut to the 16 bits
    /// of a label map: a predicted id 65537 is not truth id 1).
    pub fn add<P: Into<u32> + Copy>(&mut self, truth: &[u16], pred: &[Option<P>], ignore: u16) {
        assert_eq!(truth.len(), pred.len(), "one prediction per pixel");
        for (&t, &p) in truth.iter().zip(pred) {
            if t != ignore {
                *self
                    .counts
                    .entry((t as u32, p.map(Into::into)))
                    .or_insert(0) += 1;
            }
        }
    }

    pub fn scores(&self) -> SegmentationScores {
        let mut tp: BTreeMap<u32, u64> = BTreeMap::new();
        let mut truth_total: BTreeMap<u32, u64> = BTreeMap::new();
        let mut pred_total: BTreeMap<u32, u64> = BTreeMap::new();
        let mut labeled = 0;
        for (&(t, p), &n) in &self.counts {
            labeled += n;
            *truth_total.entry(t).or_insert(0) += n;
            if let Some(p) = p {
                *pred_total.entry(p).or_insert(0) += n;
                if p == t {
                    *tp.entry(t).or_insert(0) += n;
                }
            }
        }
        let correct: u64 = tp.values().sum();
        let per_class: Vec<ClassIou> = truth_total
            .iter()
            .map(|(&id, &pixels)| {
                let tp = tp.get(&id).copied().unwrap_or(0);
                let fp = pred_total.get(&id).copied().unwrap_or(0) - tp;
                let fn_ = pixels - tp;
                ClassIou {
                    id,
                    name: None,
                    iou: tp as f64 / (tp + fp + fn_) as f64,
                    pixels,
                }
            })
            .collect();
        let miou = if per_class.is_empty() {
            0.0
        } else {
            per_class.iter().map(|c| c.iou).sum::<f64>() / per_class.len() as f64
        };
        SegmentationScores {
            pixel_accuracy: if labeled == 0 {
                0.0
            } else {
                correct as f64 / labeled as f64
            },
            miou,
            per_class,
            labeled_pixels: labeled,
        }
    }
}

/// Fraction of Gaussians whose predicted class equals the true one (unseen = wrong);
/// Gaussians without a true class (< 0) are left out.
pub fn gaussian_accuracy(pred: &[i32], truth: &[i32]) -> f64 {
    let (mut right, mut total) = (0usize, 0usize);
    for (&p, &t) in pred.iter().zip(truth) {
        if t >= 0 {
            total += 1;
            right += usize::from(p == t);
        }
    }
    if total == 0 {
        0.0
    } else {
        right as f64 / total as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A class the table does not name makes a note, and so does a scene that holds none of
    /// the true classes (then that one alone); no table given, a scene holding one of them
    /// makes neither.
    #[test]
    fn notes_name_unnamed_classes_and_a_scene_of_other_classes() {
        let mut c = Confusion::default();
        c.add(&[1, 1, 2, 2], &[Some(5u32), None, Some(5), Some(5)], 255);
        let mut scores = c.scores();
        let table = ClassTable::from_json_str(r#"[{"id": 1, "name": "wall"}]"#).unwrap();
        scores.name_classes(&table);
        let notes = scores.notes(&[2, 5], true);
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].contains("does not list: 2;"), "{}", notes[0]);
        // No true class held: that note alone.
        let notes = scores.notes(&[-1, 5], true);
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].contains("theirs: 1, 2; the scene's: 5"),
            "{}",
            notes[0]
        );
        assert!(scores.notes(&[2, 5], false).is_empty());
    }

    #[test]
    fn miou_over_present_classes_with_ignore_and_misses() {
        // truth: 0 0 1 1 | 255 (ignored) ; pred: 0 1 1 none | 2
        let mut c = Confusion::default();
        c.add(
            &[0, 0, 1, 1, 255],
            &[Some(0u16), Some(1), Some(1), None, Some(2)],
            255,
        );
        let s = c.scores();
        // class 0: tp 1, fp 0, fn 1 -> 1/2; class 1: tp 1, fp 1, fn 1 -> 1/3.
        // Class 2 appears only as a prediction on an ignored pixel: not counted at all.
        assert_eq!(s.labeled_pixels, 4);
        assert_eq!(s.pixel_accuracy, 0.5);
        assert_eq!(
            s.per_class,
            vec![
                ClassIou {
                    id: 0,
                    name: None,
                    iou: 0.5,
                    pixels: 2
                },
                ClassIou {
                    id: 1,
                    name: None,
                    iou: 1.0 / 3.0,
                    pixels: 2
                },
            ]
        );
        assert!((s.miou - (0.5 + 1.0 / 3.0) / 2.0).abs() < 1e-12);
    }

    #[test]
    fn predicted_classes_absent_from_truth_only_cost_precision() {
        // A class predicted but never true adds false positives to no class's IoU mean
        // entry of its own, yet lowers the IoU of the class it overwrote.
        let mut c = Confusion::default();
        c.add(&[3, 3, 3, 3], &[Some(3u16), Some(3), Some(7), Some(7)], 255);
        let s = c.scores();
        assert_eq!(s.per_class.len(), 1);
        assert_eq!(s.per_class[0].iou, 0.5);
        assert_eq!(s.miou, 0.5);
    }

    #[test]
    fn predictions_above_16_bits_are_not_cut() {
        // 65537 cut to 16 bits would be 1, the true class: it must count as a miss.
        let mut c = Confusion::default();
        c.add(&[1, 1], &[Some(65_537u32), Some(1u32)], 255);
        let mut s = c.scores();
        assert_eq!(s.pixel_accuracy, 0.5);
        assert_eq!(s.per_class.len(), 1);
        assert_eq!(s.per_class[0].iou, 0.5);
        s.name_classes(&ClassTable::from_ids([1]));
        assert_eq!(s.per_class[0].name.as_deref(), Some("class_1"));
    }

    #[test]
    fn gaussian_accuracy_counts_unseen_as_wrong() {
        assert_eq!(gaussian_accuracy(&[1, -1, 2, 2], &[1, 1, 2, -1]), 2.0 / 3.0);
    }
}
