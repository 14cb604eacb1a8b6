//! Whether a method follows a consistently mislabeled object, and whether its confidence
//! flags the object.

use serde::Serialize;

use std::collections::HashMap;

use super::MethodScore;
use crate::dataset::CompactClasses;
use crate::fuse::consensus_decide::SegmentVotes;
use crate::synth::SynthScene;

/// How a method treated one consistently mislabeled object (Gaussian Semantics' limitation: a
/// majority of wrong views wins), and whether its confidence flags it.
#[derive(Clone, Debug, Serialize)]
pub struct MislabelFollow {
    pub object: String,
    pub true_class: String,
    pub wrong_class: String,
    /// Fraction of the train views that showed the object with the wrong class.
    pub wrong_view_rate: f64,
    /// How many train views showed it with the wrong class (of those that showed it).
    pub wrong_views: usize,
    /// Fraction of the object's Gaussians assigned the wrong class.
    pub assigned_wrong: f64,
    /// Mean confidence on the object's Gaussians, and on every other seen Gaussian.
    pub confidence_on_object: f64,
    pub confidence_elsewhere: f64,
    /// Methods that flag segments (segment consensus): whether a flagged segment (close or
    /// bimodal vote split) lies mostly on the object, and how many flagged segments lie
    /// mostly on no mislabeled object (false flags, scene-wide). None for the others.
    pub flagged: Option<bool>,
    pub false_flags: Option<usize>,
    /// Methods that flag segments, where a flagged segment lies on the object: of the views
    /// the report lists under the wrong class for those segments (`fuse --report`'s
    /// `views_by_class`, the frames a user would check), how many did show the object with
    /// the wrong class, and how many did not. None otherwise.
    pub wrong_views_named: Option<usize>,
    pub other_views_named: Option<usize>,
}

/// For every consistently mislabeled object of the scene's noise: what `score` assigned.
pub fn mislabel_follow(s: &SynthScene, score: &MethodScore) -> Vec<MislabelFollow> {
    let (Some(noisy), Some(input_instances)) = (&s.noisy, &s.gaussians.instance_ids) else {
        return Vec::new();
    };
    let instances = score
        .lifted
        .as_ref()
        .map_or(input_instances, |l| &l.instances);
    let planted: Vec<i32> = noisy
        .report
        .consistent
        .iter()
        .map(|m| m.instance as i32)
        .collect();
    let flags = score
        .segments
        .as_ref()
        .map(|(segments, of)| flagged_instances(segments, of, instances));
    let false_flags = flags.as_ref().map(|f| {
        f.iter()
            .filter(|(_, i)| !i.is_some_and(|i| planted.contains(&i)))
            .count()
    });
    let compact = CompactClasses::from_table(&s.room.classes).ok();
    noisy
        .report
        .consistent
        .iter()
        .map(|m| {
            let on_object = |i: usize| instances[i] == m.instance as i32;
            let mean = |sel: &dyn Fn(usize) -> bool| {
                let v: Vec<f64> = (0..instances.len())
                    .filter(|&i| sel(i) && score.classes[i] >= 0)
                    .map(|i| score.confidence[i] as f64)
                    .collect();
                v.iter().sum::<f64>() / v.len().max(1) as f64
            };
            let members: Vec<usize> = (0..instances.len()).filter(|&i| on_object(i)).collect();
            let wrong = members
                .iter()
                .filter(|&&i| score.classes[i] == m.wrong_class as i32)
                .count();
            let wrong_compact = compact.as_ref().and_then(|c| c.compact_of(m.wrong_class));
            let named = match (&flags, &score.segments, wrong_compact) {
                (Some(f), Some((segments, _)), Some(wrong)) => {
                    let on_it: Vec<&SegmentVotes> = f
                        .iter()
                        .filter(|&&(_, i)| i == Some(m.instance as i32))
                        .map(|&(seg, _)| &segments[seg as usize])
                        .collect();
                    let named = views_named(&on_it, wrong as u32, &m.wrong_views, s);
                    (!on_it.is_empty()).then_some(named)
                }
                _ => None,
            };
            MislabelFollow {
                object: m.instance_name.clone(),
                true_class: m.true_class_name.clone(),
                wrong_class: m.wrong_class_name.clone(),
                wrong_view_rate: m.rate,
                wrong_views: m.views_wrong,
                assigned_wrong: wrong as f64 / members.len().max(1) as f64,
                confidence_on_object: mean(&on_object),
                confidence_elsewhere: mean(&|i| !on_object(i)),
                flagged: flags
                    .as_ref()
                    .map(|f| f.iter().any(|&(_, i)| i == Some(m.instance as i32))),
                false_flags,
                wrong_views_named: named.map(|n| n.0),
                other_views_named: named.map(|n| n.1),
            }
        })
        .collect()
}

/// Of the views `segments` list under compact class `wrong` ([`SegmentVotes::view_classes`],
/// each view once): how many are among `wrong_views` (camera names), and how many are not.
fn views_named(
    segments: &[&SegmentVotes],
    wrong: u32,
    wrong_views: &[String],
    s: &SynthScene,
) -> (usize, usize) {
    let mut views: Vec<u32> = segments
        .iter()
        .flat_map(|seg| seg.view_classes.iter())
        .filter(|&&(_, class)| class == wrong)
        .map(|&(view, _)| view)
        .collect();
    views.sort_unstable();
    views.dedup();
    let mislabeled = |v: &&u32| wrong_views.contains(&s.cameras[**v as usize].name);
    let right = views.iter().filter(mislabeled).count();
    (right, views.len() - right)
}

/// Per flagged segment, by id: the segment and the instance more than half of its Gaussians
/// belong to (None: no such instance). `segment_of` gives each Gaussian's segment.
fn flagged_instances(
    segments: &[SegmentVotes],
    segment_of: &[u32],
    instances: &[i32],
) -> Vec<(u32, Option<i32>)> {
    let mut members: HashMap<u32, HashMap<i32, usize>> = HashMap::new();
    for (g, &seg) in segment_of.iter().enumerate() {
        if segments[seg as usize].flagged {
            *members
                .entry(seg)
                .or_default()
                .entry(instances[g])
                .or_default() += 1;
        }
    }
    let mut flagged: Vec<(u32, Option<i32>)> = members
        .into_iter()
        .map(|(seg, counts)| {
            let total: usize = counts.values().sum();
            let majority = counts
                .into_iter()
                .find(|&(i, c)| i >= 0 && 2 * c > total)
                .map(|(i, _)| i);
            (seg, majority)
        })
        .collect();
    flagged.sort_unstable();
    flagged
}
