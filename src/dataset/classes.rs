//! Compact class indices: the classes a dataset's label maps actually use, numbered
//! 0..C-1 ("model no more than the scene needs"), and the conversion between them and
//! the user's class ids (one function each way).

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{bail, Result};

use crate::scene::classes::{ClassInfo, ClassTable, IGNORE_U16};
use crate::scene::labels::{LabelDir, LabelMap, StepTally};
use crate::util::parallel::parallel_map_on;

/// A pixel without a label, as a compact class index (fusion's label maps and training's
/// label buffers; the kernels read the same value from shared_constants.txt). It differs
/// from [`LabelMap::IGNORE`](crate::scene::labels::LabelMap::IGNORE), the 16-bit user-id
/// value of unlabeled pixels: compact indices are u32 (what the kernels read), and any
/// index >= C is skipped by the kernels, so the widest value can never be a class.
pub use crate::contract::NO_LABEL;

/// The classes actually present in a scene, numbered 0..C-1 in increasing user-id order:
/// kernels see compact indices, files and reports see the user's ids.
#[derive(Clone, PartialEq, Eq)]
pub struct CompactClasses {
    /// Compact index -> user id, sorted ascending.
    user_ids: Vec<u32>,
    /// User id -> compact index, dense over every 16-bit id (`u16::MAX`: not a class): a
    /// label map is millions of lookups (a 1080p map took 7.4 ms through an ordered map on
    /// the development VM).
    compact: Vec<u16>,
}

impl std::fmt::Debug for CompactClasses {
    /// The user ids alone: the dense table is derived from them.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CompactClasses")
            .field("user_ids", &self.user_ids)
            .finish()
    }
}

impl CompactClasses {
    /// From the ids seen (e.g. in label maps); the ignore values and duplicates are dropped.
    pub fn from_ids(ids: impl IntoIterator<Item = u32>) -> Result<CompactClasses> {
        let set: BTreeSet<u32> = ids.into_iter().filter(|&id| id != IGNORE_U16).collect();
        if set.len() >= IGNORE_U16 as usize {
            bail!(
                "too many classes ({}); at most {} are supported",
                set.len(),
                IGNORE_U16 - 1
            );
        }
        if let Some(&bad) = set.iter().find(|&&id| id > IGNORE_U16) {
            bail!("class id {bad} is out of range (ids must be below {IGNORE_U16})");
        }
        let user_ids: Vec<u32> = set.into_iter().collect();
        let mut compact = vec![u16::MAX; IGNORE_U16 as usize + 1];
        for (i, &id) in user_ids.iter().enumerate() {
            compact[id as usize] = i as u16;
        }
        Ok(CompactClasses { user_ids, compact })
    }

    /// Every class of a table, present or not.
    pub fn from_table(table: &ClassTable) -> Result<CompactClasses> {
        Self::from_ids(table.classes.iter().map(|c| c.id))
    }

    /// The number of compact classes C.
    pub fn len(&self) -> usize {
        self.user_ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.user_ids.is_empty()
    }

    /// Compact index of a user id, if present.
    pub fn compact_of(&self, user_id: u32) -> Option<u16> {
        let compact = self.compact.get(user_id as usize).copied();
        compact.filter(|&c| c != u16::MAX)
    }

    /// A label map of user ids as compact class indices: [`NO_LABEL`] where the pixel is
    /// ignored or its id is not one of the classes (user id -> compact index).
    pub fn compact_labels(&self, labels: &[u16]) -> Vec<u32> {
        labels
            .iter()
            .map(|&l| match self.compact[l as usize] {
                u16::MAX => NO_LABEL,
                compact => u32::from(compact),
            })
            .collect()
    }

    /// User id of a compact index, if in range.
    pub fn user_of(&self, compact: usize) -> Option<u32> {
        self.user_ids.get(compact).copied()
    }

    /// The user ids in compact order.
    pub fn user_ids(&self) -> &[u32] {
        &self.user_ids
    }

    /// Dense lookup from a 16-bit label value to its compact index; ids not present and the
    /// ignore value map to `u16::MAX` (a u16 table: [`NO_LABEL`] does not fit, and no
    /// compact index reaches `u16::MAX` since C < 65535).
    pub fn label_lut(&self) -> &[u16] {
        &self.compact
    }

    /// The table restricted to the present classes, in compact order (for the PLY sidecar).
    pub fn table(&self, names: &ClassTable) -> ClassTable {
        let classes = self
            .user_ids
            .iter()
            .map(|&id| ClassInfo {
                id,
                name: names.name_of(id),
                color: names.color_of(id),
            })
            .collect();
        ClassTable { classes }
    }
}

/// The user class id of each compact class index, -1 for none (compact index -> user id).
/// `user_ids` gives the user id of each compact index: [`CompactClasses::user_ids`], or the
/// rows of a saved evidence matrix's class table.
pub fn user_classes(
    user_ids: &[u32],
    compact: impl IntoIterator<Item = Option<usize>>,
) -> Vec<i32> {
    compact
        .into_iter()
        .map(|c| c.and_then(|c| user_ids.get(c)).map_or(-1, |&id| id as i32))
        .collect()
}

/// What reading one label map takes at most a pixel: its decoded samples (16-bit RGBA: 8
/// bytes) and its ids (2).
const READ_BYTES_PER_PIXEL: u64 = 10;

/// What the maps that [`classes_in_labels`] reads at once may take together.
const CLASS_PASS_BYTES: u64 = 1 << 30;

/// The compact classes present in `dir`'s label maps, their table (names and colors from
/// `given`, defaults otherwise) and the number of ignored pixels. Reads every map once.
pub fn classes_in_labels(dir: &LabelDir, given: Option<&ClassTable>) -> Result<ClassesFound> {
    // Every map read once, on every core (hundreds of 1080p maps are seconds on one), each
    // thread's map dropped once counted, and no more maps at once than fit in
    // CLASS_PASS_BYTES. After a map fails, later ones are skipped and the first failure in
    // the folder's order is reported, as a loop's would be.
    let largest = (0..dir.len())
        .filter_map(|i| dir.size(i))
        .map(|(w, h)| u64::from(w) * u64::from(h) * READ_BYTES_PER_PIXEL)
        .max()
        .unwrap_or(1);
    let at_once = (CLASS_PASS_BYTES / largest.max(1)).max(1) as usize;
    let failed_at = AtomicUsize::new(usize::MAX);
    // Interpolated ids are looked for in four maps spread over the folder: a resize or a
    // JPEG export treats every map alike, and the look costs about what the read does
    // (inspect, which looks at every map: a capture's 190 1080p maps 1.1 -> 2.4 s).
    let looked_at = |i: usize| i.is_multiple_of((dir.len() / 4).max(1));
    let per_map = parallel_map_on(at_once, dir.len(), |i| {
        if i > failed_at.load(Ordering::Relaxed) {
            return None;
        }
        let map = dir.load(i);
        if map.is_err() {
            failed_at.fetch_min(i, Ordering::Relaxed);
        }
        Some(map.map(|map| {
            let ignored = map
                .labels
                .iter()
                .filter(|&&l| l == LabelMap::IGNORE)
                .count();
            let mut steps = StepTally::default();
            if looked_at(i) {
                steps.add(&map);
            }
            (map.present_ids(), ignored as u64, steps)
        }))
    });
    let mut present = BTreeSet::new();
    let (mut ignored, mut steps) = (0u64, StepTally::default());
    for counted in per_map.into_iter().flatten() {
        let (ids, ignored_pixels, map_steps) = counted?;
        present.extend(ids);
        ignored += ignored_pixels;
        steps.merge(map_steps);
    }
    if present.is_empty() && !dir.is_empty() {
        bail!(
            "the label maps of {} hold no class: every pixel is the ignore value ({}); pass \
             --ignore-id with a value the maps do not use, or check the folder",
            dir.dir().display(),
            dir.format().describe_ignore()
        );
    }
    let compact = CompactClasses::from_ids(present)?;
    let table = compact.table(given.unwrap_or(&ClassTable::default()));
    let of = format!("the label maps of {}", dir.dir().display());
    Ok(ClassesFound {
        compact,
        table,
        ignored,
        interpolated: steps.warning(&of),
    })
}

/// What [`classes_in_labels`] found in a label folder.
pub struct ClassesFound {
    pub compact: CompactClasses,
    /// The classes present, named from the table given.
    pub table: ClassTable,
    /// Unlabeled pixels, over every map.
    pub ignored: u64,
    /// A warning where some ids look made by interpolation ([`StepTally`]).
    pub interpolated: Option<String>,
}
