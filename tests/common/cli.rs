//! Running the `semsplat` binary from the integration tests.

use std::path::Path;
use std::process::{Command, Output};

/// Runs `semsplat args...` and returns what it did.
pub fn semsplat(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(args)
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

/// Runs `fuse` on a `synth` folder's scene, cameras and labels, plus `extra` (at least
/// `--out`), and returns its stderr.
pub fn fuse_synth(dir: &Path, extra: &[&str]) -> String {
    let p = |f: &str| dir.join(f).to_str().unwrap().to_string();
    let (scene, cameras, labels) = (p("scene.ply"), p("cameras.json"), p("labels"));
    let mut args = vec![
        "fuse",
        "--scene",
        &scene,
        "--cameras",
        &cameras,
        "--labels",
        &labels,
    ];
    args.extend_from_slice(extra);
    ok(&args)
}
