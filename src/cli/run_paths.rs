//! What a run reads and writes, checked against each other before any work. Each output
//! must be writable ([`check_output_file`]), and must not be one of the run's inputs (or an
//! input scene's class table or cameras), be an image inside a folder the run reads with its
//! subfolders (label maps, images) or a folder there, or be another of its outputs: the run itself would destroy or mix up
//! what it reads, or one output would replace another, and the run would still say it
//! succeeded.

use std::fs;
use std::path::{Component, Path, PathBuf};

use anyhow::{bail, Result};
use semsplat::dataset::CLASS_TABLE_FILE;
use semsplat::scene::cameras::camera_files;
use semsplat::scene::images::is_view_image;
use semsplat::scene::ply::classes_sidecar_path;
use semsplat::scene::scene_file::{resolve_scene_path, scene_cameras_file};
use semsplat::util::{check_output_file, check_output_folder, resolve_output_file};

/// One input of a run, named by its option.
#[derive(Clone, Copy)]
pub enum Input<'a> {
    /// A file read as a whole (a camera file, a class table, an evidence matrix).
    File(&'a str, Option<&'a Path>),
    /// A scene, given as a file or a folder: the file it resolves to, and its class table.
    Scene(&'a str, Option<&'a Path>),
    /// Cameras, given as a file or a model folder: the files their reader reads.
    Cameras(&'a str, Option<&'a Path>),
    /// A folder read with its subfolders (images).
    Tree(&'a str, Option<&'a Path>),
    /// A label folder: read with its subfolders, and its class table `classes.json` inside
    /// or beside it (where it exists or will: a file written there is the next run's table).
    Labels(&'a str, Option<&'a Path>),
}

/// A path read, as its [`identity`], beside the option (or part of one) naming it.
type Named = (String, PathBuf);

/// Checks, before any long work, every output file and folder (each paired with its
/// option's name; `None` where the option was not given) against the run's inputs and
/// each other (see the module's description).
pub fn check_outputs(
    files: &[(&str, Option<&Path>)],
    folders: &[(&str, Option<&Path>)],
    inputs: &[Input],
) -> Result<()> {
    let files: Vec<(&str, &Path)> = given(files);
    let folders: Vec<(&str, &Path)> = given(folders);
    for &(option, path) in &files {
        check_output_file(option, path)?;
    }
    for &(option, path) in &folders {
        check_output_folder(option, path)?;
    }
    let (read_files, read_trees) = read_paths(inputs);
    let mut written: Vec<(&str, PathBuf)> = Vec::new();
    for &(option, path) in &files {
        // Where the write lands: a link (dangling too) is written through to its target.
        let id = identity(&resolve_output_file(path)?);
        if let Some((other, _)) = written.iter().find(|(_, w)| *w == id) {
            bail!(
                "{option} {} is also {other}: one would replace the other; give each its own file",
                path.display()
            );
        }
        if let Some((input, _)) = read_files.iter().find(|(_, r)| same_file(r, &id)) {
            bail!("{option} {} is the run's {input}: writing it would replace that input; write elsewhere", path.display());
        }
        // Only images are read back from the label and image folders.
        if is_view_image(path) || is_view_image(&id) {
            refuse_inside_trees(option, path, &id, &read_trees)?;
        }
        written.push((option, id));
    }
    for &(option, path) in &folders {
        let id = identity(path);
        if let Some((file, _)) = written.iter().find(|(_, w)| *w == id) {
            bail!(
                "{option} {} is also {file}: a folder and a file cannot share a path",
                path.display()
            );
        }
        refuse_inside_trees(option, path, &id, &read_trees)?;
    }
    Ok(())
}

/// The (device, inode) of an existing file or folder: one file under two mount points (a
/// bind mount, a container's volume mounted twice) has two paths, which no resolving of
/// links makes one, and one of these.
fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// Whether two identities name one file: by path, or as the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    a == b || file_id(a).is_some_and(|f| file_id(b) == Some(f))
}

/// Whether `id` is `tree` or lies under it: by path, or through a folder above it that is
/// `tree` under another mount point.
fn is_within(id: &Path, tree: &Path) -> bool {
    id.starts_with(tree)
        || file_id(tree).is_some_and(|t| id.ancestors().any(|a| file_id(a) == Some(t)))
}

fn given<'a>(paths: &[(&'a str, Option<&'a Path>)]) -> Vec<(&'a str, &'a Path)> {
    (paths.iter())
        .filter_map(|&(option, path)| Some((option, path?)))
        .collect()
}

/// An output at or under a folder the run reads with its subfolders would be read back
/// as an input by this run or the next (a label map replaced, a rendered view taken for one).
fn refuse_inside_trees(option: &str, path: &Path, id: &Path, trees: &[Named]) -> Result<()> {
    if let Some((input, tree)) = trees.iter().find(|(_, t)| is_within(id, t)) {
        bail!(
            "{option} {} is inside the {input} folder {}, which the run reads with its \
             subfolders: write it outside that folder",
            path.display(),
            tree.display()
        );
    }
    Ok(())
}

/// The files the inputs read, and the folders they read with their subfolders, each as
/// its [`identity`] beside the option naming it.
fn read_paths(inputs: &[Input]) -> (Vec<Named>, Vec<Named>) {
    let (mut files, mut trees) = (Vec::new(), Vec::new());
    for input in inputs {
        match *input {
            Input::File(option, Some(path)) => files.push((option.into(), identity(path))),
            Input::Scene(option, Some(path)) => {
                // A scene that does not resolve is reported by its reader, after these checks.
                if let Ok(file) = resolve_scene_path(path) {
                    let table = classes_sidecar_path(&file);
                    files.push((format!("{option}'s class table"), identity(&table)));
                    files.push((option.into(), identity(&file)));
                }
                // The cameras a scene's folder (or INRIA run) holds are its default cameras.
                if let Some(cameras) = scene_cameras_file(path) {
                    files.push((format!("{option}'s cameras"), identity(&cameras)));
                }
            }
            Input::Cameras(option, Some(path)) => {
                let read = camera_files(path).into_iter().chain([path.to_path_buf()]);
                files.extend(read.map(|f| (option.into(), identity(&f))));
            }
            Input::Tree(option, Some(path)) => trees.push((option.into(), identity(path))),
            Input::Labels(option, Some(path)) => {
                trees.push((option.into(), identity(path)));
                let beside = path.parent().map(|p| p.join(CLASS_TABLE_FILE));
                for table in [Some(path.join(CLASS_TABLE_FILE)), beside]
                    .into_iter()
                    .flatten()
                {
                    files.push((format!("{option} folder's class table"), identity(&table)));
                }
            }
            _ => {}
        }
    }
    (files, trees)
}

/// One spelling per file: absolute, with the links and `..` of its existing part resolved
/// (a write goes through links to their target) and the rest appended as given.
pub(super) fn identity(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let parts: Vec<Component> = absolute.components().collect();
    for existing in (1..=parts.len()).rev() {
        let head: PathBuf = parts[..existing].iter().collect();
        let Ok(mut resolved) = fs::canonicalize(&head) else {
            continue;
        };
        // The rest does not exist yet, so holds no link: its `..` is the folder above.
        for part in &parts[existing..] {
            match part {
                Component::ParentDir => {
                    resolved.pop();
                }
                Component::CurDir => {}
                other => resolved.push(other),
            }
        }
        return resolved;
    }
    absolute
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_resolves_links_and_dots_of_the_existing_part() {
        let dir = std::env::temp_dir().join(format!("semsplat-identity-{}", std::process::id()));
        fs::create_dir_all(dir.join("real")).unwrap();
        let link = dir.join("link");
        let _ = fs::remove_file(&link);
        std::os::unix::fs::symlink(dir.join("real"), &link).unwrap();
        let by_link = identity(&link.join("new.ply"));
        let by_dots = identity(&dir.join("real").join("..").join("real").join("new.ply"));
        assert_eq!(by_link, by_dots);
        // `..` past a folder that does not exist yet.
        let by_new = identity(&dir.join("new").join("..").join("real").join("new.ply"));
        assert_eq!(by_link, by_new);
        assert_eq!(
            by_link,
            fs::canonicalize(dir.join("real")).unwrap().join("new.ply")
        );
        fs::remove_dir_all(&dir).unwrap();
    }
}
