//! Class tables: the user's label ids with names and palette colors, and the compact
//! remap to the classes actually present (C = classes present).

use serde::{Deserialize, Serialize};

/// The ignore value of 8-bit label maps (16-bit maps use 65535).
pub const IGNORE_U8: u32 = 255;
pub const IGNORE_U16: u32 = 65535;

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
