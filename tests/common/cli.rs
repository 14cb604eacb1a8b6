//! Running the `semsplat` binary from the integration tests.

use std::path::Path;
use std::process::{Command, Output};

/// `file` in `dir`, as a command-line argument.
pub fn arg_in(dir: &Path, file: &str) -> String {
    dir.join(file).to_str().unwrap().to_string()
}

/// `args` as owned strings, for argument lists that mix literals and paths.
pub fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|s| s.to_string()).collect()
}

/// The JSON file at `path` (a report, a manifest), parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap()
}

/// Runs `semsplat args...` and returns what it did.
pub fn semsplat(args: &[&str]) -> Output {
    semsplat_with_env(args, &[])
}

/// [`semsplat`] with environment variables set (e.g. `SEMSPLAT_MAX_BINDING`).
pub fn semsplat_with_env(args: &[&str], env: &[(&str, String)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(args)
        .envs(env.iter().map(|(k, v)| (k, v)))
        .output()
        .unwrap()
}

/// Runs a command that must succeed; returns its stderr (progress and summary lines).
pub fn ok(args: &[&str]) -> String {
    let out = semsplat(args);
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Runs a command that must fail; returns its error message.
pub fn fails(args: &[&str]) -> String {
    let out = semsplat(args);
    assert!(!out.status.success(), "{args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// [`ok`] for arguments built as owned strings.
pub fn ok_owned(args: &[String]) -> String {
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

/// [`fails`] for arguments built as owned strings.
pub fn fails_owned(args: &[String]) -> String {
    fails(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

/// The PNG label maps of a room `dir`'s `labels` folder, in name order.
pub fn label_pngs(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut maps: Vec<_> = std::fs::read_dir(dir.join("labels"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    maps.sort();
    maps
}

/// Writes the tiny synthetic room into `dir`: `views` train views and one held-out view at
/// `width` x `height`, without preview images.
pub fn synth_tiny(dir: &Path, views: u32, (width, height): (u32, u32)) {
    let (views, width, height) = (views.to_string(), width.to_string(), height.to_string());
    ok(&[
        "synth",
        "--preset",
        "tiny",
        "--views",
        &views,
        "--test-views",
        "1",
        "--width",
        &width,
        "--height",
        &height,
        "--no-previews",
        "--out",
        dir.to_str().unwrap(),
    ]);
}

/// `train` on a `synth` folder `d`'s train views, from the scene `init`, into `out` (the
/// images path is element 2, for tests that replace it).
pub fn train_args(d: &str, init: &str, out: &str) -> Vec<String> {
    [
        "train",
        "--images",
        &format!("{d}/images"),
        "--labels",
        &format!("{d}/labels"),
        "--cameras",
        &format!("{d}/cameras.json"),
        "--init",
        init,
        "--out",
        out,
        "--train-only",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

/// `fuse` on a `synth` folder's scene, cameras and labels, plus `extra`.
pub fn fuse_synth_args(dir: &Path, extra: &[&str]) -> Vec<String> {
    let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let mut args: Vec<String> = vec!["fuse".into(), "--scene".into(), p("scene.ply")];
    args.extend([
        "--cameras".into(),
        p("cameras.json"),
        "--labels".into(),
        p("labels"),
    ]);
    args.extend(extra.iter().map(|s| s.to_string()));
    args
}

/// Runs `fuse` on a `synth` folder's scene, cameras and labels, plus `extra` (at least
/// `--out`), and returns its stderr.
pub fn fuse_synth(dir: &Path, extra: &[&str]) -> String {
    let args = fuse_synth_args(dir, extra);
    ok_owned(&args)
}

/// Like [`fuse_synth`] for a command that must fail; returns its error message.
pub fn fuse_synth_fails(dir: &Path, extra: &[&str]) -> String {
    let args = fuse_synth_args(dir, extra);
    fails_owned(&args)
}
