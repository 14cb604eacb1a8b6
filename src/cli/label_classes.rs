//! The classes a label folder uses: C = the classes present ("model no more than the
//! scene needs"), named from the user's class table where one is given.

use std::path::{Path, PathBuf};

use anyhow::Result;

use semsplat::scene::classes::{default_color, ClassInfo, ClassTable, CompactClasses};
use semsplat::scene::labels::LabelDir;

/// The compact classes present in `dir`'s label maps and their table (names and colors
/// from `given`, defaults otherwise). Reads every map once.
pub fn classes_in_labels(
    dir: &LabelDir,
    given: Option<&ClassTable>,
) -> Result<(CompactClasses, ClassTable)> {
    let mut present = std::collections::BTreeSet::new();
    for i in 0..dir.len() {
        present.extend(dir.load(i)?.present_ids());
    }
    let compact = CompactClasses::from_ids(present.iter().copied())?;
    let table = ClassTable {
        classes: compact
            .user_ids()
            .iter()
            .map(|&id| match given.and_then(|t| t.get(id)) {
                Some(c) => c.clone(),
                None => ClassInfo {
                    id,
                    name: format!("class_{id}"),
                    color: default_color(id),
                },
            })
            .collect(),
    };
    Ok((compact, table))
}

/// classes.json inside the label folder or beside it, if there is one.
pub fn default_class_table(labels: &Path) -> Option<PathBuf> {
    [
        labels.join("classes.json"),
        labels
            .parent()
            .map(|p| p.join("classes.json"))
            .unwrap_or_default(),
    ]
    .into_iter()
    .find(|p| p.is_file())
}
