//! Scene data: Gaussians, cameras, label maps, class tables, file formats.

pub mod camera;
pub mod cameras;
pub mod cameras_json;
pub mod classes;
pub mod colmap;
pub mod compressed_ply;
pub mod gaussians;
pub mod images;
pub mod labels;
pub mod look_at;
pub mod nerfstudio;
pub mod ply;
pub mod point_cloud;
pub mod random_scene;
pub mod scene_file;
pub mod select;
pub mod splat_formats;

pub use camera::{Camera, Split};
pub use classes::{ClassInfo, ClassTable};
pub use gaussians::{Gaussians, SemanticLogits};
