//! The instance-oracle bound of a noisy-label experiment: every Gaussian takes the majority of
//! the noisy labels over its true instance. No method sees the true instance masks, so this
//! is the best any method that decides one class per object could do with these labels (a
//! method may beat it only where the noise splits an object, which per-object noise does not).

use std::collections::HashMap;

use anyhow::{ensure, Result};

use super::score::{held_out_segmentation, MethodScore};
use crate::eval::metrics::gaussian_accuracy;
use crate::gpu::Gpu;
use crate::scene::labels::LabelMap;
use crate::scene::Split;
use crate::synth::SynthScene;

/// Name of the oracle in tables, charts and JSON.
pub const ORACLE_NAME: &str = "oracle (instance majority)";

/// Per Gaussian (user class id, -1: none) the instance-majority class of the scene's noisy
/// train labels (the true labels where the scene has no noise).
///
/// Each train view casts one vote per instance it shows: the noisy class covering most of
/// the instance's true mask in that view (a tie within a view splits its vote equally).
/// The instance takes the class with most view votes; ties go to the class with more
/// labelled pixels over all views, and an instance still tied, or never seen, or a Gaussian
/// without an instance, gets -1 (counted wrong). Class ids never break ties.
pub fn instance_oracle_classes(s: &SynthScene) -> Result<Vec<i32>> {
    let Some(instances) = &s.gaussians.instance_ids else {
        anyhow::bail!("the scene's Gaussians carry no instance ids");
    };
    // instance -> class -> (view votes, pixels)
    let mut votes: HashMap<u16, HashMap<u16, (u64, u64)>> = HashMap::new();
    for (i, cam) in s.cameras.iter().enumerate() {
        if cam.split != Split::Train {
            continue;
        }
        let labels = s.noisy.as_ref().map_or(&s.views[i].labels, |n| &n.maps[i]);
        let view_instances = &s.views[i].instances;
        ensure!(
            labels.len() == view_instances.len(),
            "view {i}: label map and instance map differ in size"
        );
        add_view_votes(&mut votes, view_instances, labels);
    }
    let decided: HashMap<u16, i32> = votes
        .iter()
        .map(|(&inst, classes)| (inst, majority(classes)))
        .collect();
    Ok(instances
        .iter()
        .map(|&inst| {
            u16::try_from(inst)
                .ok()
                .and_then(|inst| decided.get(&inst).copied())
                .unwrap_or(-1)
        })
        .collect())
}

/// The oracle scored like a method: held-out mIoU of its classes rendered from the input
/// Gaussians, and per-Gaussian accuracy against the truth.
pub fn score_instance_oracle(gpu: &Gpu, s: &SynthScene) -> Result<MethodScore> {
    let classes = instance_oracle_classes(s)?;
    let seg = held_out_segmentation(gpu, s, &s.gaussians, &classes)?;
    let truth = s.gaussians.class_ids.clone().unwrap_or_default();
    Ok(MethodScore {
        method: ORACLE_NAME,
        key: "oracle",
        seconds: 0.0,
        miou: seg.miou,
        pixel_accuracy: seg.pixel_accuracy,
        gaussian_accuracy: gaussian_accuracy(&classes, &truth),
        peak_device_bytes: 0,
        per_class: seg.per_class,
        confidence: vec![1.0; classes.len()],
        classes,
        lifted: None,
        image_quality: None,
        segments: None,
    })
}

/// One view's vote in integer units, so that split votes add up exactly (divisible by every
/// count of tied classes up to 16).
const VOTE: u64 = 720_720;

/// One view's votes: per instance on screen, its pixel count per noisy class, then one vote
/// shared among the classes with the most pixels.
fn add_view_votes(
    votes: &mut HashMap<u16, HashMap<u16, (u64, u64)>>,
    view_instances: &[u16],
    labels: &[u16],
) {
    let mut pixels: HashMap<u16, HashMap<u16, u64>> = HashMap::new();
    for (&inst, &label) in view_instances.iter().zip(labels) {
        if inst != LabelMap::IGNORE && label != LabelMap::IGNORE {
            *pixels.entry(inst).or_default().entry(label).or_insert(0) += 1;
        }
    }
    for (inst, counts) in pixels {
        let top = counts.values().copied().max().unwrap_or(0);
        let winners = counts.values().filter(|&&n| n == top).count() as u64;
        let entry = votes.entry(inst).or_default();
        for (class, n) in counts {
            let e = entry.entry(class).or_insert((0, 0));
            e.1 += n;
            if n == top {
                e.0 += VOTE / winners;
            }
        }
    }
}

/// The class with most view votes, then most pixels; -1 when still tied.
fn majority(classes: &HashMap<u16, (u64, u64)>) -> i32 {
    let Some(best) = classes.values().max() else {
        return -1;
    };
    let mut at_best = classes.iter().filter(|(_, v)| *v == best);
    match (at_best.next(), at_best.next()) {
        (Some((&class, _)), None) => class as i32,
        _ => -1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: u16 = LabelMap::IGNORE;

    #[test]
    fn ties_split_a_view_and_fall_to_pixels_then_to_undecided() {
        let mut votes = HashMap::new();
        // Instance 1: view A 2 px of class 5, 2 px of class 7 (split vote); view B 1 px of 7.
        add_view_votes(&mut votes, &[1, 1, 1, 1, N, 1], &[5, 5, 7, 7, 5, N]);
        add_view_votes(&mut votes, &[1, 2], &[7, 5]);
        assert_eq!(votes[&1][&5], (VOTE / 2, 2));
        assert_eq!(votes[&1][&7], (VOTE / 2 + VOTE, 3));
        assert_eq!(majority(&votes[&1]), 7);
        assert_eq!(majority(&votes[&2]), 5);
        // Equal votes: more pixels wins, whatever the class ids.
        let tied = HashMap::from([(2, (VOTE, 9)), (9, (VOTE, 10))]);
        assert_eq!(majority(&tied), 9);
        let tied = HashMap::from([(9, (VOTE, 9)), (2, (VOTE, 10))]);
        assert_eq!(majority(&tied), 2);
        // Equal votes and pixels: undecided, not the lower id.
        let tied = HashMap::from([(2, (VOTE, 10)), (9, (VOTE, 10))]);
        assert_eq!(majority(&tied), -1);
    }
}
