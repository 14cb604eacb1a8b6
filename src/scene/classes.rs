//! Class tables: the user's label ids with names and palette colors. The compact remap to
//! the classes actually present lives with the dataset (`crate::dataset::CompactClasses`).

use std::collections::{BTreeSet, HashSet};
use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::util::write_atomic;

/// The ignore value of 8-bit label map files. It loads as [`LabelMap::IGNORE`], so only the
/// PNG reader and writer see it.
///
/// [`LabelMap::IGNORE`]: super::labels::LabelMap::IGNORE
pub const IGNORE_U8: u32 = 255;
/// The ignore value of 16-bit label map files and of label maps in memory
/// ([`LabelMap::IGNORE`](super::labels::LabelMap::IGNORE)), widened for id arithmetic.
pub const IGNORE_U16: u32 = super::labels::LabelMap::IGNORE as u32;

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClassInfo {
    /// The id as it appears in label maps.
    pub id: u32,
    pub name: String,
    pub color: [u8; 3],
}

#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClassTable {
    pub classes: Vec<ClassInfo>,
}

/// A deterministic, well-spread color for a class id without one (golden-ratio hue steps at
/// fixed saturation/value), so the same id gets the same color in every image we write.
pub fn default_color(id: u32) -> [u8; 3] {
    let hue = (id as f64 * 0.618_033_988_749_895).fract();
    // Alternate two value levels so neighbouring ids also differ in brightness.
    let (s, v) = if id.is_multiple_of(2) {
        (0.75, 0.95)
    } else {
        (0.85, 0.70)
    };
    hsv_to_rgb(hue, s, v)
}

fn hsv_to_rgb(h: f64, s: f64, v: f64) -> [u8; 3] {
    let i = (h * 6.0).floor();
    let f = h * 6.0 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - f * s), v * (1.0 - (1.0 - f) * s));
    let (r, g, b) = match i as i32 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    let to_u8 = |x: f64| (x * 255.0).round().clamp(0.0, 255.0) as u8;
    [to_u8(r), to_u8(g), to_u8(b)]
}

/// One class entry as written by users: color and name may be left out.
#[derive(Deserialize)]
struct ClassEntryJson {
    id: u32,
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    color: Option<[u8; 3]>,
}

impl ClassTable {
    /// Builds a table for ids without names or colors ("class_<id>", default palette).
    pub fn from_ids(ids: impl IntoIterator<Item = u32>) -> ClassTable {
        let ids: BTreeSet<u32> = ids.into_iter().collect();
        let classes = ids
            .into_iter()
            .map(|id| ClassInfo {
                id,
                name: format!("class_{id}"),
                color: default_color(id),
            })
            .collect();
        ClassTable { classes }
    }

    /// Whether parsed JSON has a class table's shape: a list of objects with an `id`, or an
    /// object whose `classes` is one (perhaps empty: a table that lists no class, which
    /// the reader refuses as such); synth's `room.json` lists classes by name alone, a
    /// report counts them: neither is a table.
    pub fn json_has_shape(value: &serde_json::Value) -> bool {
        let with_ids =
            |entries: &[serde_json::Value]| entries.iter().all(|e| e.get("id").is_some());
        match value {
            serde_json::Value::Array(v) => !v.is_empty() && with_ids(v),
            serde_json::Value::Object(o) => match o.get("classes") {
                Some(serde_json::Value::Array(v)) => with_ids(v),
                _ => false,
            },
            _ => false,
        }
    }

    /// Parses a class table from JSON: a list of `{id, name, color}` or `{"classes": [...]}`.
    /// Missing names become `class_<id>`, missing colors come from [`default_color`]. An
    /// entry that does not parse is named in the error by its index and text.
    pub fn from_json_str(text: &str) -> Result<ClassTable> {
        const SHAPE: &str = "expected a JSON list of {\"id\", \"name\", \"color\": [r, g, b]} \
                             or {\"classes\": [...]}";
        let value: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| anyhow::anyhow!("not a class table ({e}); {SHAPE}"))?;
        let entries = match &value {
            serde_json::Value::Array(v) => v,
            serde_json::Value::Object(o) => match o.get("classes") {
                Some(serde_json::Value::Array(v)) => v,
                _ => bail!("not a class table (an object without a \"classes\" list); {SHAPE}"),
            },
            _ => bail!("not a class table; {SHAPE}"),
        };
        let classes = entries
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let e = ClassEntryJson::deserialize(v).map_err(|err| {
                    let shown: String = v.to_string().chars().take(120).collect();
                    anyhow::anyhow!(
                        "not a class table: class entry {i} ({shown}) is not {{\"id\": non-negative integer, \
                         \"name\": text, \"color\": [r, g, b] in 0..=255}}: {err}"
                    )
                })?;
                Ok(ClassInfo {
                    id: e.id,
                    name: e.name.unwrap_or_else(|| format!("class_{}", e.id)),
                    color: e.color.unwrap_or_else(|| default_color(e.id)),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let table = ClassTable { classes };
        table.validate()?;
        Ok(table)
    }

    /// The class a user names on the command line: an exact name, else a name matched
    /// case-insensitively (when only one matches), else an id. A key that is one class's
    /// name and another's id is an error naming both. The error lists the names.
    pub fn find(&self, key: &str) -> Result<&ClassInfo> {
        let by_id = key.trim().parse::<u32>().ok().and_then(|id| self.get(id));
        if let Some(c) = self.by_name(key) {
            if let Some(other) = by_id.filter(|o| o.id != c.id) {
                // Its name picks the other class, unless that name is a number too.
                let remedy = match other.name.trim().parse::<u32>() {
                    Err(_) => format!("give '{}' for class {}, or rename", other.name, other.id),
                    Ok(_) => "rename".to_owned(),
                };
                bail!(
                    "class '{key}' is the name of class {} and the id of class '{}': {remedy} \
                     class {} (the class table's names that are numbers shadow ids)",
                    c.id,
                    other.name,
                    c.id
                );
            }
            return Ok(c);
        }
        let folded: Vec<&ClassInfo> = self
            .classes
            .iter()
            .filter(|c| c.name.to_lowercase() == key.to_lowercase())
            .collect();
        match folded.as_slice() {
            [one] => return Ok(one),
            [] => {}
            several => {
                let names: Vec<&str> = several.iter().map(|c| c.name.as_str()).collect();
                bail!("class '{key}' matches several names when case is ignored: {names:?}; give the exact name or the id")
            }
        }
        if let Some(c) = by_id {
            return Ok(c);
        }
        let names: Vec<&str> = self.classes.iter().map(|c| c.name.as_str()).collect();
        bail!("no class '{key}' among {names:?}")
    }

    /// The first two classes (in table order) whose names differ only in case: a name given
    /// in a third case matches both, and [`ClassTable::find`] refuses it.
    pub fn names_alike_but_case(&self) -> Option<(&ClassInfo, &ClassInfo)> {
        let mut by_folded = std::collections::HashMap::with_capacity(self.len());
        (self.classes.iter()).find_map(|c| {
            let other = by_folded.insert(c.name.to_lowercase(), c)?;
            Some((other, c))
        })
    }

    /// The first two classes (ids, in table order) that share a colour, and the colour: a
    /// colour-coded map cannot be read through such a table.
    pub fn shared_colour(&self) -> Option<(u32, u32, [u8; 3])> {
        let mut by_color = std::collections::HashMap::with_capacity(self.len());
        (self.classes.iter()).find_map(|c| {
            let other = by_color.insert(c.color, c.id)?;
            Some((other, c.id, c.color))
        })
    }

    /// Checks for duplicate ids or names, empty names, and ids that collide with the
    /// 16-bit ignore value.
    pub fn validate(&self) -> Result<()> {
        let mut ids = HashSet::new();
        let mut names = HashSet::new();
        for c in &self.classes {
            if c.id >= IGNORE_U16 {
                bail!(
                    "class '{}' has id {}: ids must be below {IGNORE_U16} (the ignore value of 16-bit label maps)",
                    c.name,
                    c.id
                );
            }
            if c.name.trim().is_empty() {
                bail!("class id {} has an empty name", c.id);
            }
            if !ids.insert(c.id) {
                bail!("duplicate class id {}", c.id);
            }
            if !names.insert(c.name.as_str()) {
                bail!("duplicate class name '{}'", c.name);
            }
        }
        Ok(())
    }

    pub fn is_empty(&self) -> bool {
        self.classes.is_empty()
    }

    pub fn len(&self) -> usize {
        self.classes.len()
    }

    pub fn get(&self, id: u32) -> Option<&ClassInfo> {
        self.classes.iter().find(|c| c.id == id)
    }

    pub fn by_name(&self, name: &str) -> Option<&ClassInfo> {
        self.classes.iter().find(|c| c.name == name)
    }

    pub fn contains(&self, id: u32) -> bool {
        self.get(id).is_some()
    }

    /// The table's color for `id`, or the default palette color if the id is not listed.
    pub fn color_of(&self, id: u32) -> [u8; 3] {
        self.get(id)
            .map(|c| c.color)
            .unwrap_or_else(|| default_color(id))
    }

    /// The class name for `id`, or `class_<id>` if the id is not listed.
    pub fn name_of(&self, id: u32) -> String {
        self.get(id)
            .map(|c| c.name.clone())
            .unwrap_or_else(|| format!("class_{id}"))
    }

    /// Dense id -> color lookup for all 16-bit ids (painting images pixel by pixel).
    pub fn color_lut(&self) -> Vec<[u8; 3]> {
        let mut lut: Vec<[u8; 3]> = (0..=IGNORE_U16).map(default_color).collect();
        for c in &self.classes {
            lut[c.id as usize] = c.color;
        }
        lut[IGNORE_U16 as usize] = [0, 0, 0];
        lut
    }
}

/// Reads a class table JSON file (see [`ClassTable::from_json_str`]).
pub fn read_class_table(path: &Path) -> Result<ClassTable> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading class table {}", path.display()))?;
    ClassTable::from_json_str(&text).with_context(|| format!("class table {}", path.display()))
}

/// Writes `{"classes": [{id, name, color}, ...]}` atomically, sorted by id.
pub fn write_class_table(path: &Path, table: &ClassTable) -> Result<()> {
    table
        .validate()
        .with_context(|| format!("refusing to write class table {}", path.display()))?;
    let mut sorted = table.clone();
    sorted.classes.sort_by_key(|c| c.id);
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, &sorted)?;
        w.write_all(b"\n")?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(classes: &[(u32, &str)]) -> ClassTable {
        ClassTable {
            classes: (classes.iter())
                .map(|&(id, name)| ClassInfo {
                    id,
                    name: name.into(),
                    color: [0; 3],
                })
                .collect(),
        }
    }

    #[test]
    fn find_takes_names_then_ids_and_refuses_a_key_that_is_both() {
        let t = table(&[(0, "floor"), (7, "Wall"), (1000, "vase"), (3, "1000")]);
        assert_eq!(t.find("floor").unwrap().id, 0);
        assert_eq!(t.find("wall").unwrap().id, 7); // case ignored
        assert_eq!(t.find("7").unwrap().id, 7); // an id
        let err = t.find("1000").unwrap_err().to_string();
        assert!(
            err.contains("name of class 3") && err.contains("id of class 'vase'"),
            "{err}"
        );
        assert!(err.contains("give 'vase' for class 1000"), "{err}");
        assert_eq!(t.find("vase").unwrap().id, 1000);
        // Names that are ids both ways: renaming is the way out, not the other number.
        let t = table(&[(1, "4"), (4, "1")]);
        let err = t.find("4").unwrap_err().to_string();
        assert!(
            err.contains(": rename class 1") && !err.contains("give"),
            "{err}"
        );
        assert!(t.find("vase").is_err());
        assert!(t.find("sofa").is_err());
    }
}
