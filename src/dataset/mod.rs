//! A labeled dataset as the commands read it: cameras, the label maps matched to them by
//! image name, the class table, and the compact class indices the GPU works in.

pub mod classes;

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

pub use classes::{classes_in_labels, user_classes, CompactClasses, NO_LABEL};

use crate::fuse::LabelSource;
use crate::scene::cameras::load_cameras;
use crate::scene::classes::{read_class_table, ClassTable};
use crate::scene::labels::{
    binary_mask_warning, stray_255_warning, LabelDir, LabelFormat, MissingLabels,
};
use crate::scene::{Camera, Split};

/// Where a dataset's parts are.
pub struct DatasetPaths<'a> {
    /// COLMAP model folder, INRIA cameras.json or semsplat cameras.json.
    pub cameras: &'a Path,
    /// Folder of label PNGs named like the cameras.
    pub labels: &'a Path,
    /// Class table; None: [`default_class_table`] of the label folder, if any.
    pub class_table: Option<&'a Path>,
    /// Keep only the cameras marked "train".
    pub train_only: bool,
    /// How the label maps are read (`--ignore-id`).
    pub format: LabelFormat,
}

/// Cameras with their label maps (cameras without one are kept and have no labels) and the
/// classes the maps use.
pub struct Dataset {
    pub cameras: Vec<Camera>,
    pub labels: LabelDir,
    /// The classes present in the label maps.
    pub classes: CompactClasses,
    /// Names and colors of `classes`, in compact order.
    pub table: ClassTable,
    /// Label map entry of each camera.
    entry_of_camera: Vec<Option<usize>>,
    /// What the user should be told once on stderr (scaled intrinsics, binary masks).
    pub warnings: Vec<String>,
}

impl Dataset {
    /// Loads the cameras, matches the label folder to them (checking ids against the class
    /// table when there is one) and reads every map once to find the classes present.
    pub fn open(paths: &DatasetPaths) -> Result<Dataset> {
        let mut cameras = load_cameras(paths.cameras)?;
        // --train-only's test cameras: their maps are held out, not maps of no camera.
        let mut held_out = Vec::new();
        if paths.train_only {
            let test = cameras.iter().filter(|c| c.split != Split::Train);
            held_out = test.map(|c| c.name.clone()).collect();
            keep_train_cameras(&mut cameras, paths.cameras)?;
        }
        let table_path = paths
            .class_table
            .map(Path::to_path_buf)
            .or_else(|| default_class_table(paths.labels));
        let given = table_path.as_deref().map(read_class_table).transpose()?;
        let labels = LabelDir::open_as(
            paths.labels,
            &cameras,
            &held_out,
            given.as_ref(),
            &paths.format,
            MissingLabels::Skip,
        )?;
        labels.fit_cameras(&mut cameras);
        let found = classes_in_labels(&labels, given.as_ref())?;
        let (classes, table) = (found.compact, found.table);
        let mut warnings = labels.notes().to_vec();
        warnings.extend(binary_mask_warning(
            paths.labels,
            classes.user_ids(),
            found.ignored,
            &paths.format,
        ));
        warnings.extend(stray_255_warning(
            paths.labels,
            classes.user_ids(),
            &paths.format,
            given.as_ref(),
        ));
        warnings.extend(found.interpolated);
        let mut entry_of_camera = vec![None; cameras.len()];
        for i in 0..labels.len() {
            if let Some(c) = labels.camera_index(i) {
                entry_of_camera[c] = Some(i);
            }
        }
        Ok(Dataset {
            cameras,
            labels,
            classes,
            table,
            entry_of_camera,
            warnings,
        })
    }

    /// Whether camera `view` has a label map.
    pub fn has_label_map(&self, view: usize) -> bool {
        self.entry_of(view).is_some()
    }

    /// The label map entry of camera `view`, if it has one.
    fn entry_of(&self, view: usize) -> Option<usize> {
        self.entry_of_camera.get(view).copied().flatten()
    }

    /// The label map of camera `view` as compact class indices ([`NO_LABEL`] where there is
    /// none); None when the camera has no label map.
    pub fn compact_labels(&self, view: usize) -> Result<Option<Vec<u32>>> {
        match self.entry_of(view) {
            Some(entry) => Ok(Some(
                self.classes
                    .compact_labels(&self.labels.load(entry)?.labels),
            )),
            None => Ok(None),
        }
    }
}

impl LabelSource for Dataset {
    fn labels(&self, view: usize, _cam: &Camera) -> Result<Option<Vec<u32>>> {
        self.compact_labels(view)
    }
}

/// The cameras of `path`; with `train_only`, those marked "train" (an error if none is).
pub fn load_split_cameras(path: &Path, train_only: bool) -> Result<Vec<Camera>> {
    let mut cameras = load_cameras(path)?;
    if train_only {
        keep_train_cameras(&mut cameras, path)?;
    }
    Ok(cameras)
}

/// Keeps the cameras marked "train" (of the cameras file `path`): an error if none is.
fn keep_train_cameras(cameras: &mut Vec<Camera>, path: &Path) -> Result<()> {
    cameras.retain(|c| c.split == Split::Train);
    if cameras.is_empty() {
        bail!("{} has no train cameras", path.display());
    }
    Ok(())
}

/// Cameras (scaled to their label maps' size when those are resized copies) and the label
/// maps matched to them: for scoring against true maps, whose ids are compared as they are.
/// `table` only decodes colour-coded maps; ids outside it are not refused.
pub fn open_truth_views(
    cameras: &Path,
    labels: &Path,
    table: Option<&ClassTable>,
    format: &LabelFormat,
) -> Result<(Vec<Camera>, LabelDir)> {
    let mut cameras = load_cameras(cameras)?;
    let labels = LabelDir::open_as(labels, &cameras, &[], table, format, MissingLabels::Skip)?
        .without_id_check();
    labels.fit_cameras(&mut cameras);
    Ok((cameras, labels))
}

/// The name of a label folder's class table, inside the folder or beside it.
pub const CLASS_TABLE_FILE: &str = "classes.json";

/// classes.json inside the label folder or beside it, if there is one.
pub fn default_class_table(labels: &Path) -> Option<PathBuf> {
    [
        labels.join(CLASS_TABLE_FILE),
        labels
            .parent()
            .map(|p| p.join(CLASS_TABLE_FILE))
            .unwrap_or_default(),
    ]
    .into_iter()
    .find(|p| p.is_file())
}
