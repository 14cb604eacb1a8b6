//! The Ray driver (tools/ray/fuse_sharded.py) on a local Ray cluster: its merged PLY equals
//! a single-machine `fuse` byte for byte; a shard whose task fails once (its CLI exits
//! non-zero, or its worker process dies) is retried; a shard that always fails is named and
//! nothing is merged. Needs `python3 -c 'import ray'` (tools/setup.sh installs it).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const SEMSPLAT: &str = env!("CARGO_BIN_EXE_semsplat");

fn ok(args: &[&str]) {
    let out = Command::new(SEMSPLAT).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A tiny room (7 labeled views at 48x32) and its single-machine fuse (`single.ply`).
fn room_and_single_fuse(d: &Path) {
    let dir = d.to_str().unwrap();
    ok(&[
        "synth",
        "--preset",
        "tiny",
        "--out",
        dir,
        "--views",
        "6",
        "--test-views",
        "1",
        "--width",
        "48",
        "--height",
        "32",
    ]);
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    ok(&[
        "fuse",
        "--scene",
        &p("scene.ply"),
        "--cameras",
        &p("cameras.json"),
        "--labels",
        &p("labels"),
        "--out",
        &p("single.ply"),
    ]);
}

fn driver() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/ray/fuse_sharded.py")
}

/// Runs the driver on 3 shards with 3 local worker CPUs, with the fault-injection `env`.
fn run_driver(d: &Path, out: &str, env: &[(&str, &str)], max_retries: &str) -> Output {
    let probe = Command::new("python3").args(["-c", "import ray"]).output();
    assert!(
        probe.is_ok_and(|o| o.status.success()),
        "python3 cannot import ray: run tools/setup.sh (pip install ray)"
    );
    let p = |f: &str| d.join(f).to_str().unwrap().to_string();
    let mut cmd = Command::new("python3");
    cmd.arg(driver()).args([
        "--shards",
        "3",
        "--num-cpus",
        "3",
        "--max-retries",
        max_retries,
        "--semsplat",
        SEMSPLAT,
        "--scene",
        &p("scene.ply"),
        "--cameras",
        &p("cameras.json"),
        "--labels",
        &p("labels"),
        "--parts",
        &p("parts"),
        "--out",
        &p(out),
    ]);
    // Ray keeps its session files under the temp dir; keep them inside the test's folder.
    cmd.env("RAY_TMPDIR", d.join("ray")).env("TMPDIR", d);
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.output().unwrap()
}

fn attempts_of_shard1(d: &Path) -> usize {
    std::fs::read_dir(d.join("parts"))
        .unwrap()
        .filter(|e| {
            let name = e.as_ref().unwrap().file_name();
            name.to_string_lossy().starts_with(".fault-shard1-attempt")
        })
        .count()
}

fn assert_same_as_single(d: &Path, out: &Output, merged: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "driver failed: {stderr}");
    let (single, merged) = (d.join("single.ply"), d.join(merged));
    assert!(
        std::fs::read(&single).unwrap() == std::fs::read(&merged).unwrap(),
        "{} differs from the single-machine fuse",
        merged.display()
    );
}

#[test]
fn ray_sharded_fuse_equals_one_fuse_and_survives_a_failed_and_a_killed_task() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    room_and_single_fuse(d);

    let out = run_driver(d, "ray.ply", &[], "2");
    assert_same_as_single(d, &out, "ray.ply");

    // The next run replaces the parts an earlier one left, and only them.
    let (stale, other) = (d.join("parts/part9.npy"), d.join("parts/particles.ply"));
    std::fs::write(&stale, b"old").unwrap();
    std::fs::write(&other, b"mine").unwrap();

    // Shard 1's CLI exits non-zero on its first attempt: Ray retries it once.
    let fail_once = [("SEMSPLAT_RAY_FAULT_SHARD", "1")];
    let out = run_driver(d, "retried.ply", &fail_once, "2");
    assert_same_as_single(d, &out, "retried.ply");
    assert!(!stale.exists() && other.exists());
    assert_eq!(attempts_of_shard1(d), 2, "one failed attempt, one retry");

    // Shard 1's worker process dies on its first attempt: Ray retries it on another.
    let kill_once = [
        ("SEMSPLAT_RAY_FAULT_SHARD", "1"),
        ("SEMSPLAT_RAY_FAULT_MODE", "kill"),
    ];
    let out = run_driver(d, "killed.ply", &kill_once, "2");
    assert_same_as_single(d, &out, "killed.ply");
    assert_eq!(attempts_of_shard1(d), 2, "one killed attempt, one retry");
}

#[test]
fn ray_driver_names_a_shard_that_always_fails_and_merges_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    room_and_single_fuse(d);
    let always = [
        ("SEMSPLAT_RAY_FAULT_SHARD", "1"),
        ("SEMSPLAT_RAY_FAULT_TIMES", "always"),
    ];
    let out = run_driver(d, "lost.ply", &always, "1");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("shard 1/3 failed after 1 retries"),
        "{stderr}"
    );
    assert!(stderr.contains("nothing merged"), "{stderr}");
    assert_eq!(attempts_of_shard1(d), 2, "the first attempt and one retry");
    assert!(!d.join("lost.ply").exists());
}

/// Before any shard runs, the driver names a missing input or CLI, and the lack of Ray (here
/// a `ray` module that fails to import shadows the real one), in one line each: no
/// traceback, no part folder made.
#[test]
fn ray_driver_names_missing_inputs_and_a_missing_ray_before_any_shard() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let existing = d.to_str().unwrap();
    let run = |scene: &str, semsplat: &str, env: &[(&str, &str)]| {
        let parts = d.join("parts");
        let mut cmd = Command::new("python3");
        cmd.arg(driver())
            .args(["--shards", "2", "--scene", scene, "--cameras", existing]);
        cmd.args([
            "--labels",
            existing,
            "--out",
            "x.ply",
            "--semsplat",
            semsplat,
        ]);
        cmd.arg("--parts").arg(&parts).envs(env.iter().copied());
        let out = cmd.output().unwrap();
        assert!(!parts.exists(), "a refused run made its part folder");
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(!stderr.contains("Traceback"), "{stderr}");
        stderr
    };
    let missing = d.join("missing.ply");
    let err = run(missing.to_str().unwrap(), SEMSPLAT, &[]);
    assert!(
        err.contains("--scene") && err.contains("does not exist"),
        "{err}"
    );
    let err = run(existing, "no-such-semsplat", &[]);
    assert!(err.contains("--semsplat no-such-semsplat"), "{err}");

    let shadow = d.join("shadow");
    std::fs::create_dir(&shadow).unwrap();
    std::fs::write(shadow.join("ray.py"), "raise ModuleNotFoundError('ray')\n").unwrap();
    let err = run(
        existing,
        SEMSPLAT,
        &[("PYTHONPATH", shadow.to_str().unwrap())],
    );
    assert!(err.contains("needs Ray"), "{err}");
}
