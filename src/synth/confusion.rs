//! Which wrong class a 2D segmenter plausibly predicts for a class: a fixed table of look-alikes
//! (chair <-> armchair, table <-> desk, tv <-> monitor, ...), restricted to the classes a room
//! actually has. Rooms may override entries (`confusions` in the room JSON).

use std::collections::BTreeMap;

use anyhow::{bail, Result};

use crate::scene::ClassTable;

const LOOK_ALIKES: &[(&str, &[&str])] = &[
    ("floor", &["rug", "wall"]),
    ("wall", &["ceiling", "door", "window"]),
    ("ceiling", &["wall"]),
    ("door", &["wall", "cabinet"]),
    ("window", &["curtain", "picture", "wall"]),
    ("curtain", &["window", "wall"]),
    ("rug", &["floor"]),
    (
        "desk",
        &["table", "dining_table", "coffee_table", "cabinet"],
    ),
    ("table", &["desk", "coffee_table", "dining_table"]),
    ("dining_table", &["desk", "coffee_table", "table"]),
    ("coffee_table", &["side_table", "dining_table", "table"]),
    ("side_table", &["coffee_table", "cabinet", "table"]),
    ("chair", &["armchair", "sofa"]),
    ("armchair", &["chair", "sofa"]),
    ("sofa", &["armchair", "chair"]),
    ("cushion", &["sofa", "armchair"]),
    ("monitor", &["tv"]),
    ("tv", &["monitor", "picture"]),
    ("tv_stand", &["cabinet", "side_table", "shelf"]),
    ("speaker", &["box", "cabinet"]),
    ("cabinet", &["shelf", "bookshelf", "desk"]),
    ("shelf", &["bookshelf", "cabinet"]),
    ("bookshelf", &["shelf", "cabinet"]),
    ("book", &["box"]),
    ("lamp", &["vase", "plant"]),
    ("plant", &["vase"]),
    ("vase", &["cup", "plant", "lamp"]),
    ("cup", &["vase", "bowl"]),
    ("bowl", &["cup", "vase"]),
    ("picture", &["window", "tv"]),
    ("clock", &["picture"]),
    ("ball", &["bowl", "box"]),
    ("box", &["book", "cabinet"]),
    ("pillar", &["wall"]),
];

/// Per class id (index into the class table), the wrong class ids it is confused with; never
/// empty when the table has at least two classes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfusionTable {
    pub options: Vec<Vec<u32>>,
}

impl ConfusionTable {
    /// Builds the table for `classes`; `overrides` maps a class name to look-alike names.
    pub fn new(classes: &ClassTable, overrides: &BTreeMap<String, Vec<String>>) -> Result<Self> {
        let id_of = |name: &str| {
            classes
                .classes
                .iter()
                .find(|c| c.name == name)
                .map(|c| c.id)
        };
        for (name, list) in overrides {
            for other in std::iter::once(name).chain(list) {
                if id_of(other).is_none() {
                    bail!(
                        "confusions: unknown class '{other}' (classes: {})",
                        class_names(classes)
                    );
                }
            }
        }
        let mut options = Vec::with_capacity(classes.classes.len());
        for (index, class) in classes.classes.iter().enumerate() {
            let listed: Vec<&str> = match overrides.get(&class.name) {
                Some(list) => list.iter().map(String::as_str).collect(),
                None => LOOK_ALIKES
                    .iter()
                    .find(|(n, _)| *n == class.name)
                    .map(|(_, l)| l.to_vec())
                    .unwrap_or_default(),
            };
            let mut ids: Vec<u32> = listed
                .iter()
                .filter_map(|n| id_of(n))
                .filter(|&id| id != class.id)
                .collect();
            ids.dedup();
            if ids.is_empty() && classes.classes.len() > 1 {
                // No listed look-alike in this room: the neighbouring class keeps it deterministic.
                ids.push(classes.classes[(index + 1) % classes.classes.len()].id);
            }
            options.push(ids);
        }
        Ok(ConfusionTable { options })
    }

    pub fn for_class(&self, class_index: usize) -> &[u32] {
        self.options
            .get(class_index)
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }
}

fn class_names(classes: &ClassTable) -> String {
    classes
        .classes
        .iter()
        .map(|c| c.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::ClassInfo;

    fn table(names: &[&str]) -> ClassTable {
        ClassTable {
            classes: names
                .iter()
                .enumerate()
                .map(|(i, n)| ClassInfo {
                    id: i as u32,
                    name: n.to_string(),
                    color: [0, 0, 0],
                })
                .collect(),
        }
    }

    #[test]
    fn look_alikes_restricted_to_present_classes_with_fallback() {
        let t = table(&["floor", "wall", "chair", "sofa", "ball"]);
        let c = ConfusionTable::new(&t, &BTreeMap::new()).unwrap();
        assert_eq!(c.for_class(2), &[3]); // chair -> sofa (no armchair here)
        assert_eq!(c.for_class(0), &[1]); // floor -> wall (no rug)
        assert_eq!(c.for_class(4), &[0]); // ball: no look-alike present -> next class, wrapping
    }

    #[test]
    fn overrides_replace_entries_and_unknown_names_fail() {
        let t = table(&["floor", "wall", "chair"]);
        let mut o = BTreeMap::new();
        o.insert("chair".to_string(), vec!["floor".to_string()]);
        assert_eq!(ConfusionTable::new(&t, &o).unwrap().for_class(2), &[0]);
        o.insert("chair".to_string(), vec!["spaceship".to_string()]);
        assert!(ConfusionTable::new(&t, &o).is_err());
    }
}
