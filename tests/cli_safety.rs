//! The CLI's safety rails: numeric options are validated, camera names cannot steer files
//! outside the output folder, outputs are never special files and are checked writable
//! before any work, Ctrl-C/SIGTERM leave no partial output or temp file, and a buffer the
//! device cannot hold is named in the error.
// Symbolic links, FIFOs and signals as Unix has them.
#![cfg(unix)]

mod common;

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use common::cli::strings;
use semsplat::util::{check_output_file, stage_atomic, write_atomic, write_bytes_atomic};

fn semsplat<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(args)
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `synth` of the tiny room into `out`: `views` train and `test` held-out views of
/// `width` x `height`, without previews.
fn tiny_synth_args(views: u32, test: u32, (width, height): (u32, u32), out: &Path) -> Vec<String> {
    let counts = [views, test, width, height].map(|n| n.to_string());
    let [views, test, width, height] = counts.each_ref().map(String::as_str);
    [
        "synth",
        "--preset",
        "tiny",
        "--views",
        views,
        "--test-views",
        test,
    ]
    .into_iter()
    .chain([
        "--width",
        width,
        "--height",
        height,
        "--no-previews",
        "--out",
    ])
    .map(String::from)
    .chain([out.to_str().unwrap().to_string()])
    .collect()
}

/// A tiny synth room (4 views of 32x24) in `dir`.
fn synth(dir: &Path) {
    let o = semsplat(tiny_synth_args(3, 1, (32, 24), dir));
    assert!(o.status.success(), "{}", stderr(&o));
}

/// Files in `dir` whose names say they are temp files of ours.
fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("semsplat-tmp") || n.contains(".tmp"))
        .collect()
}

// ---------------------------------------------------------------------------------------
// A closed standard output

/// `semsplat eval ... | head` with the reader gone before the first line: the process ends
/// as a shell tool does (SIGPIPE), without a panic and its backtrace on stderr.
#[test]
fn a_closed_stdout_ends_the_process_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path();
    synth(room);
    let path = |name: &str| room.join(name).to_str().unwrap().to_owned();
    let mut child = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(["eval", "--scene", &path("scene.ply"), "--cameras"])
        .args([&path("cameras.json"), "--labels", &path("labels")])
        .args(["--truth", &path("scene.ply")])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take()); // the reader closes before eval prints anything
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGPIPE),
        "{:?}: {err}",
        out.status
    );
}

/// A standard output that cannot be written (a full disk): a command whose output is its
/// result fails with a plain error, no panic; `sweep`, whose results are its files, says
/// so and writes them, as it does when `| head` closes its pipe.
#[test]
fn a_full_stdout_is_an_error_and_sweeps_still_write_their_files() {
    let full = || std::fs::File::create("/dev/full").unwrap();
    let info = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(["info", "--json"])
        .stdout(full())
        .output()
        .unwrap();
    let err = stderr(&info);
    assert_eq!(info.status.code(), Some(1), "{err}");
    assert!(
        err.contains("error: writing standard output") && !err.contains("panicked"),
        "{err}"
    );
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("sweep");
    for stdout in ["full", "closed"] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_semsplat"))
            .args([
                "sweep", "--noise", "salt", "--levels", "0,0.1", "--preset", "tiny",
            ])
            .args([
                "--views",
                "2",
                "--test-views",
                "1",
                "--width",
                "32",
                "--height",
                "24",
            ])
            .args(["--methods", "vote", "--out", out.to_str().unwrap()])
            .stdout(match stdout {
                "full" => Stdio::from(full()),
                _ => Stdio::piped(),
            })
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let run = child.wait_with_output().unwrap();
        let err = stderr(&run);
        assert!(run.status.success(), "{stdout}: {err}");
        assert!(
            err.contains("note: writing standard output"),
            "{stdout}: {err}"
        );
        assert!(
            out.join("robustness_salt.json").is_file(),
            "{stdout}: {err}"
        );
        std::fs::remove_dir_all(&out).unwrap();
    }
}

// ---------------------------------------------------------------------------------------
// Numeric options

/// `line`'s words followed by `out`: a command line that ends with its output path.
fn with_out<'a>(line: &'a str, out: &'a str) -> Vec<&'a str> {
    line.split_whitespace().chain([out]).collect()
}

#[test]
fn bad_numeric_options_are_refused_naming_option_value_and_range() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out.ply");
    let o = out.to_str().unwrap();
    let train = with_out(
        "train --images i --labels l --cameras c.json --init x.ply --out",
        o,
    );
    let fuse = with_out("fuse --scene s.ply --cameras c.json --labels l --out", o);
    let render = with_out("render --scene s.ply --cameras c.json --out", o);
    let sweep = with_out("sweep --noise salt --out", o);
    let demo = with_out("demo --out", o);
    let synth = with_out("synth --out", o);
    // (command, option, bad value, words of the allowed range in the error)
    let cases: &[(&[&str], &str, &str, &str)] = &[
        (&train, "--lr-logits", "nan", "> 0"),
        (&train, "--lr-logits", "inf", "> 0"),
        (&train, "--lr-logits", "-0.1", "> 0"),
        (&train, "--lr-logits", "0", "> 0"),
        (&train, "--lambda-sem", "inf", ">= 0"),
        (&train, "--lambda-sem", "-1", ">= 0"),
        (&train, "--lambda-entropy", "NaN", ">= 0"),
        (&train, "--iters", "0", ">= 1"),
        (&train, "--max-gaussians", "0", ">= 1"),
        (&train, "--checkpoint-every", "0", ">= 1"),
        (&fuse, "--depth-tol", "nan", "> 0"),
        (&fuse, "--depth-tol", "-0.05", "> 0"),
        (&fuse, "--depth-tol", "0", "> 0"),
        (&fuse, "--gamma", "nan", "[-1, 1]"),
        (&fuse, "--gamma", "1.5", "[-1, 1]"),
        (&fuse, "--mem-budget", "0", "1 byte"),
        (&fuse, "--mem-budget", "inf", "1 byte"),
        (&render, "--background", "0,nan,0", "[0, 1]"),
        (&render, "--background", "0,2,0", "[0, 1]"),
        (&sweep, "--levels", "0,nan", ">= 0"),
        (&sweep, "--levels", "-1", ">= 0"),
        (&sweep, "--levels", "0,1.5", "[0, 1]"),
        (&sweep, "--views", "0", ">= 1"),
        (&demo, "--test-views", "0", ">= 1"),
        (&demo, "--width", "0", ">= 1"),
        (&demo, "--joint-iters", "0", ">= 1"),
        (&["bench", "render"], "--n", "0", ">= 1"),
        (&["bench", "render"], "--iters", "0", ">= 1"),
        (&["bench", "sort"], "--n", "0", ">= 1"),
        (&synth, "--fov", "nan", "20.0..=120.0 degrees"),
        (&synth, "--spacing", "0", "0.002..=1.0 m"),
        (&synth, "--init-spacing", "9", "0.01..=5.0 m"),
        (&synth, "--width", "9000", "1..=8192 pixels"),
    ];
    for (command, option, value, range) in cases {
        assert_refused_naming_option_value_and_range(command, option, value, range, &out);
    }
}

/// `command` with `option=value` fails before writing `out`, with an error that names the
/// option, quotes the value and states the allowed `range`.
fn assert_refused_naming_option_value_and_range(
    command: &[&str],
    option: &str,
    value: &str,
    range: &str,
    out: &Path,
) {
    // `--opt=value`; fuse, train and render also take `--opt -1` as a value, not a flag.
    let apart = ["fuse", "train", "render"].contains(&command[0]);
    let forms = [
        vec![format!("{option}={value}")],
        vec![option.to_string(), value.to_string()],
    ];
    for form in &forms[..1 + usize::from(apart)] {
        let mut args = strings(command);
        args.extend(form.iter().cloned());
        assert_refused_as(&args, option, value, range, out);
    }
}

fn assert_refused_as(args: &[String], option: &str, value: &str, range: &str, out: &Path) {
    let run = semsplat(args);
    let err = stderr(&run);
    assert!(!run.status.success(), "{args:?} succeeded");
    for needle in [option, range] {
        assert!(
            err.contains(needle),
            "{args:?}: error lacks '{needle}': {err}"
        );
    }
    // The bad value itself, quoted (of a list, the element that is bad).
    let quoted = value.split(',').any(|v| err.contains(&format!("'{v}'")));
    assert!(quoted, "{args:?}: error does not quote the value: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert!(!out.exists(), "{args:?} wrote {}", out.display());
}

// ---------------------------------------------------------------------------------------
// Camera names

#[test]
fn camera_names_that_are_paths_are_refused_by_every_command() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth(&room);
    let cameras: serde_json::Value =
        serde_json::from_slice(&std::fs::read(room.join("cameras.json")).unwrap()).unwrap();
    let escape = tmp.path().join("escaped");
    let bad_names = [
        "../../escaped".to_string(),
        escape.to_str().unwrap().to_string(),
        "..".to_string(),
        "a\0b".to_string(),
        String::new(),
    ];
    let out = tmp.path().join("out");
    for (i, name) in bad_names.iter().enumerate() {
        let mut cams = cameras.clone();
        cams["cameras"][0]["name"] = name.clone().into();
        let file = tmp.path().join(format!("bad{i}.json"));
        std::fs::write(&file, serde_json::to_vec(&cams).unwrap()).unwrap();
        for args in commands_naming_files_by_camera(&room, &file, &out) {
            assert_refused_as_camera_name(name, &args);
        }
    }
    assert!(!out.exists(), "a refused run wrote into --out");
    let leaked: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("escaped"))
        .collect();
    assert!(leaked.is_empty(), "wrote outside --out: {leaked:?}");

    // A camera named after another's label map would write its image over it.
    let mut cams = cameras.clone();
    let other = cams["cameras"][1]["name"].as_str().unwrap().to_owned();
    cams["cameras"][0]["name"] = format!("{other}.labels").into();
    let file = tmp.path().join("clash.json");
    std::fs::write(&file, serde_json::to_vec(&cams).unwrap()).unwrap();
    let render = &commands_naming_files_by_camera(&room, &file, &out)[0];
    let o = semsplat(render);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("would both write"), "{e}");
    assert!(!out.exists(), "a refused render wrote into --out");
}

/// Every command that names files after cameras: on the synth `room`, with the camera file
/// `cameras`, writing into `out`.
fn commands_naming_files_by_camera(room: &Path, cameras: &Path, out: &Path) -> Vec<Vec<String>> {
    let p = |f: &Path| f.to_str().unwrap().to_string();
    let r = |f: &str| p(&room.join(f));
    let (cameras, out_s) = (p(cameras), p(out));
    let render = |raw: &[&str]| {
        let scene = r("scene.ply");
        let mut args = strings(&["render", "--scene", &scene, "--cameras", &cameras]);
        args.extend(strings(raw));
        args.extend(strings(&["--out", &out_s]));
        args
    };
    vec![
        render(&[]),
        render(&["--raw"]),
        strings(&[
            "fuse",
            "--scene",
            &r("scene.ply"),
            "--cameras",
            &cameras,
            "--labels",
            &r("labels"),
            "--render-views",
            &out_s,
            "--out",
            &p(&out.join("f.ply")),
        ]),
        train_on(room, &cameras, "2", &p(&out.join("t.ply"))),
    ]
}

/// `args`, run with a camera called `name`, fails saying the camera name is no file name.
fn assert_refused_as_camera_name(name: &str, args: &[String]) {
    let run = semsplat(args);
    let err = stderr(&run);
    assert!(!run.status.success(), "{name:?}: {args:?} succeeded");
    assert!(
        err.contains("camera name") && err.contains("file name"),
        "{name:?}: {args:?}: {err}"
    );
}

// ---------------------------------------------------------------------------------------
// Output paths

#[test]
fn writes_go_through_symlinks_and_never_replace_special_files() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    // A link to an existing file, and a dangling one: both written through, links kept.
    std::fs::create_dir(d.join("real")).unwrap();
    std::fs::write(d.join("real/old.txt"), "old").unwrap();
    std::os::unix::fs::symlink("real/old.txt", d.join("link.txt")).unwrap();
    std::os::unix::fs::symlink("real/new.txt", d.join("dangling.txt")).unwrap();
    for link in ["link.txt", "dangling.txt"] {
        write_bytes_atomic(&d.join(link), b"new").unwrap();
        assert!(
            d.join(link).symlink_metadata().unwrap().is_symlink(),
            "{link}"
        );
        assert_eq!(std::fs::read(d.join(link)).unwrap(), b"new", "{link}");
    }
    assert_eq!(std::fs::read(d.join("real/new.txt")).unwrap(), b"new");
    assert!(temp_files(d).is_empty() && temp_files(&d.join("real")).is_empty());
    // ...but an output check does not create folders where a dangling link points.
    let into_nothing = d.join("gone/sub/x.ply");
    std::os::unix::fs::symlink(&into_nothing, d.join("far.ply")).unwrap();
    let err = format!(
        "{:#}",
        check_output_file("--out", &d.join("far.ply")).unwrap_err()
    );
    assert!(
        err.contains("whose folder") && err.contains("does not exist"),
        "{err}"
    );
    assert!(!d.join("gone").exists());
    check_output_file("--out", &d.join("dangling.txt")).unwrap();

    // A FIFO, a device, a folder and a link to a folder are refused, and stay what they were.
    let fifo = d.join("fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    std::os::unix::fs::symlink("real", d.join("dirlink")).unwrap();
    for (target, needle) in [
        (fifo.clone(), "not a regular file"),
        ("/dev/null".into(), "not a regular file"),
        (d.join("real"), "is a folder"),
        (d.join("dirlink"), "is a folder"),
    ] {
        let err = format!("{:#}", write_atomic(&target, |_| Ok(())).unwrap_err());
        assert!(err.contains(needle), "{}: {err}", target.display());
    }
    use std::os::unix::fs::FileTypeExt;
    assert!(fifo.symlink_metadata().unwrap().file_type().is_fifo());
    assert!(Path::new("/dev/null")
        .metadata()
        .unwrap()
        .file_type()
        .is_char_device());
}

/// A PID that names no running process (a child's, waited for).
fn dead_pid() -> u32 {
    let mut child = Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    dead
}

/// Writes `path` as last modified two minutes ago (a temp file as old as a killed run's).
fn write_aged(path: &Path) -> std::fs::File {
    std::fs::write(path, "x").unwrap();
    let file = std::fs::File::options().write(true).open(path).unwrap();
    let two_minutes_ago = std::time::SystemTime::now() - Duration::from_secs(120);
    file.set_modified(two_minutes_ago).unwrap();
    file
}

#[test]
fn stale_temp_files_of_dead_runs_are_removed_and_live_ones_kept() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let dead = dead_pid();
    let stale = d.join(format!(".out.ply.semsplat-tmp{dead}-0a1b2c3d"));
    let stale_old_name = d.join(format!(".old.ply.semsplat-tmp{dead}"));
    // PID 1 is always alive: its temp file may be in use.
    let live = d.join(".other.ply.semsplat-tmp1-0a1b2c3d");
    let unrelated = d.join(".notes.tmp123");
    for f in [&stale, &stale_old_name, &live, &unrelated] {
        write_aged(f);
    }
    write_bytes_atomic(&d.join("out.ply"), b"new").unwrap();
    assert!(
        !stale.exists() && !stale_old_name.exists(),
        "stale temp file left"
    );
    assert!(
        live.exists() && unrelated.exists(),
        "removed a file that is not stale"
    );
}

/// A run in another PID namespace (a container sharing the folder) has a PID that names no
/// process here: its temp file is kept while its writer holds the file's lock, or while it
/// is younger than a minute (its writer may not have locked it yet), and removed once
/// neither holds. A write here takes a temp name no file has, whatever its PID.
#[test]
fn temp_files_of_runs_in_other_namespaces_are_kept_while_in_use() {
    let tmp = tempfile::tempdir().unwrap();
    let dead = dead_pid();
    let folder = |name: &str| {
        let d = tmp.path().join(name);
        std::fs::create_dir(&d).unwrap();
        d
    };
    let (locked_dir, young_dir, idle_dir) = (folder("locked"), folder("young"), folder("idle"));
    let temp_in = |d: &Path| d.join(format!(".out.ply.semsplat-tmp{dead}-0a1b2c3d"));
    let writer = write_aged(&temp_in(&locked_dir));
    writer.lock().unwrap();
    std::fs::write(temp_in(&young_dir), "x").unwrap();
    write_aged(&temp_in(&idle_dir));
    for d in [&locked_dir, &young_dir, &idle_dir] {
        write_bytes_atomic(&d.join("out.ply"), b"new").unwrap();
        assert_eq!(std::fs::read(d.join("out.ply")).unwrap(), b"new");
    }
    assert!(temp_in(&locked_dir).exists(), "a locked temp file removed");
    assert!(
        temp_in(&young_dir).exists(),
        "a temp file younger than a minute removed"
    );
    assert!(
        !temp_in(&idle_dir).exists(),
        "an unlocked old temp file left"
    );
    assert_eq!(
        std::fs::read(temp_in(&locked_dir)).unwrap(),
        b"x",
        "the other run's temp file written over"
    );
    // Two writes of one file at once (as two runs with one PID would): two temp files, each
    // renamed with its own bytes.
    let target = idle_dir.join("twice.ply");
    let first = stage_atomic(&target, |w| Ok(w.write_all(b"first")?)).unwrap();
    let second = stage_atomic(&target, |w| Ok(w.write_all(b"second")?)).unwrap();
    first.commit().unwrap();
    assert_eq!(std::fs::read(&target).unwrap(), b"first");
    second.commit().unwrap();
    assert_eq!(std::fs::read(&target).unwrap(), b"second");
}

#[test]
fn outputs_are_checked_writable_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth(&room);
    let blocker = tmp.path().join("a_file");
    std::fs::write(&blocker, "x").unwrap();
    let under_file = blocker.join("x.ply").to_str().unwrap().to_string();
    let good = tmp.path().join("good.ply");
    let good_s = good.to_str().unwrap().to_string();
    let contrib = tmp.path().join("contrib.npy");
    let contrib_s = contrib.to_str().unwrap().to_string();
    let blocker_s = blocker.to_str().unwrap().to_string();
    let fuse = |extra: &[&str]| fuse_on(&room, extra);
    let at = |name: &str| tmp.path().join(name).to_str().unwrap().to_string();
    std::fs::create_dir(tmp.path().join("a_file_out.iter50000.ply")).unwrap();
    std::fs::create_dir(tmp.path().join("a_file_part.manifest.json")).unwrap();
    std::fs::create_dir_all(tmp.path().join("a_file_sweep/robustness_flicker.json")).unwrap();
    std::fs::create_dir_all(tmp.path().join("a_file_demo/strip.png")).unwrap();
    std::os::unix::fs::symlink(tmp.path().join("nowhere/x"), tmp.path().join("a_file_link"))
        .unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        // Would train 100000 iterations and then fail on --out without the check.
        (train_100000_iters(&room, &under_file), "--out"),
        // Side outputs would be written before --out fails.
        (
            fuse(&["--save-contrib", &contrib_s, "--out", &under_file]),
            "--out",
        ),
        (
            fuse(&["--out", &good_s, "--report", &under_file]),
            "--report",
        ),
        (
            fuse(&["--out", &good_s, "--render-views", &blocker_s]),
            "--render-views",
        ),
        (
            fuse(&["--out", &good_s, "--palette-ply", &under_file]),
            "--palette-ply",
        ),
        // Derived outputs, and a dangling link as a folder: found before the work too.
        (
            {
                let mut a = train_100000_iters(&room, &at("a_file_out.ply"));
                a.extend(strings(&["--checkpoint-every", "50000"]));
                a
            },
            "--checkpoint-every",
        ),
        (
            fuse(&["--shard", "0/2", "--out", &at("a_file_part.npy")]),
            "--out's manifest",
        ),
        (
            fuse(&["--out", &good_s, "--render-views", &at("a_file_link")]),
            "--render-views",
        ),
        (
            strings(&["sweep", "--noise", "flicker", "--out", &at("a_file_sweep")]),
            "--out's report",
        ),
        (
            strings(&["demo", "--out", &at("a_file_demo")]),
            "--out's strip",
        ),
    ];
    for (args, option) in cases {
        assert_refused_before_work(&args, option, &good, &contrib);
    }
}

/// `fuse` on the synth `room`'s scene, cameras and labels, plus `extra`.
fn fuse_on(room: &Path, extra: &[&str]) -> Vec<String> {
    let r = |f: &str| room.join(f).to_str().unwrap().to_string();
    let mut a = strings(&[
        "fuse",
        "--scene",
        &r("scene.ply"),
        "--cameras",
        &r("cameras.json"),
        "--labels",
        &r("labels"),
    ]);
    a.extend(strings(extra));
    a
}

/// `train` on the synth `room` for 100000 iterations, into `out`.
fn train_100000_iters(room: &Path, out: &str) -> Vec<String> {
    let cameras = room.join("cameras.json");
    train_on(room, cameras.to_str().unwrap(), "100000", out)
}

/// `train` on the synth `room`'s images, labels and init cloud, with the camera file
/// `cameras`, for `iters` iterations, into `out`.
fn train_on(room: &Path, cameras: &str, iters: &str, out: &str) -> Vec<String> {
    let r = |f: &str| room.join(f).to_str().unwrap().to_string();
    let (images, labels, init) = (r("images"), r("labels"), r("init.ply"));
    strings(&[
        "train",
        "--images",
        &images,
        "--labels",
        &labels,
        "--cameras",
        cameras,
        "--init",
        &init,
        "--iters",
        iters,
        "--out",
        out,
    ])
}

/// `args` fails on the output `option` (under the file a_file) before any training, and
/// writes neither `good` nor `contrib`.
fn assert_refused_before_work(args: &[String], option: &str, good: &Path, contrib: &Path) {
    let run = semsplat(args);
    let err = stderr(&run);
    assert!(!run.status.success(), "{args:?} succeeded");
    assert!(
        err.contains(option) && err.contains("a_file"),
        "{args:?}: {err}"
    );
    assert!(!err.contains("training"), "{args:?} started work: {err}");
    assert!(
        !good.exists() && !contrib.exists(),
        "{args:?} wrote an output"
    );
}

// ---------------------------------------------------------------------------------------
// Interruption

/// Starts `train` on `room` for very many iterations, waits until it reports that training
/// started, sends `signal`, and returns its exit code and stderr.
fn interrupt_training(room: &Path, out: &Path, signal: &str) -> (Option<i32>, String) {
    let r = |f: &str| room.join(f);
    let mut child = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .arg("train")
        .args(["--images".as_ref(), r("images").as_os_str()])
        .args(["--labels".as_ref(), r("labels").as_os_str()])
        .args(["--cameras".as_ref(), r("cameras.json").as_os_str()])
        .args(["--init".as_ref(), r("init.ply").as_os_str()])
        .args(["--iters", "10000000"])
        .args(["--out".as_ref(), out.as_os_str()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (tx, rx) = mpsc::channel();
    let reader = BufReader::new(child.stderr.take().unwrap());
    let lines = std::thread::spawn(move || {
        let mut all = String::new();
        for line in reader.lines().map_while(Result::ok) {
            if line.starts_with("training ") {
                let _ = tx.send(());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    // Generous: the device and the scene upload come first (lavapipe, 2 busy cores).
    let started = rx.recv_timeout(Duration::from_secs(300));
    let sent = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = child.wait().unwrap();
    let err = lines.join().unwrap();
    assert!(started.is_ok(), "training never started: {err}");
    (status.code(), err)
}

#[test]
fn ctrl_c_and_sigterm_stop_training_with_no_output_and_no_temp_files() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth(&room);
    let out_dir = tmp.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let out = out_dir.join("trained.ply");
    // The exit status is 128 plus the signal's number, as a shell reports a process the
    // signal killed.
    for (signal, status) in [("-INT", 130), ("-TERM", 143)] {
        let (code, err) = interrupt_training(&room, &out, signal);
        assert_eq!(code, Some(status), "{signal}: {err}");
        assert!(err.contains("interrupted"), "{signal}: {err}");
        assert!(!err.contains("panicked"), "{signal}: {err}");
        let left: Vec<_> = std::fs::read_dir(&out_dir).unwrap().collect();
        assert!(left.is_empty(), "{signal}: left {left:?}");
    }
}

// ---------------------------------------------------------------------------------------
// Device memory

#[test]
fn a_buffer_too_large_for_the_device_is_named_with_its_size_and_a_remedy() {
    let gpu = common::gpu();
    // Twice all the memory the device reports (its heaps), so it cannot fit anywhere; no
    // fixed size, which might exceed a device's maxBufferSize and upset the validation layer.
    let all_memory: u64 = gpu.caps().heaps.iter().map(|h| h.size_bytes).sum();
    let size = 2 * all_memory.max(1 << 30);
    let err = gpu
        .buffer("too-large-for-any-device", size)
        .err()
        .expect("a buffer of twice the device's memory was created");
    let msg = err.to_string();
    let human = semsplat::gpu::error::human_bytes(&size);
    for needle in [
        "too-large-for-any-device",
        &human,
        "smaller images",
        "--mem-budget",
    ] {
        assert!(msg.contains(needle), "error lacks '{needle}': {msg}");
    }
    common::check_validation(gpu);
}

/// Every file name under `dir`, recursively.
fn all_files(dir: &Path) -> Vec<String> {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_dir() {
            names.extend(all_files(&entry.path()));
        } else {
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
    }
    names
}

/// Sends Ctrl-C (SIGINT) to `child` and checks that it stopped as interrupted (exit 130);
/// returns its stderr.
fn interrupt(child: Child) -> String {
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let run = child.wait_with_output().unwrap();
    let err = stderr(&run);
    assert_eq!(run.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    err
}

/// A command that does not poll (synth) exits at the first Ctrl-C, mid-write, and still
/// leaves no temp file: the handler removes the ones in flight.
#[test]
fn ctrl_c_during_synth_writing_exits_at_once_without_temp_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("room");
    let mut child = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(tiny_synth_args(400, 1, (64, 48), &out))
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The view images are written last (400 views, about 3 s on 2 cores): wait for the
    // first one's folder, polling.
    let images = out.join("images");
    for _ in 0..120_000 {
        if images.exists() || child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    interrupt(child);
    let files = all_files(&out);
    let temps: Vec<&String> = files
        .iter()
        .filter(|n| n.contains("semsplat-tmp"))
        .collect();
    assert!(temps.is_empty(), "temp files left: {temps:?}");
    let written = all_files(&images).len();
    assert!(
        written < 401,
        "synth finished before the signal ({written} images)"
    );
}

/// A render stopped part-way says how many of its views it wrote and which, and the files
/// there are those views' (whole, no temp file).
#[test]
fn ctrl_c_during_render_names_the_views_written() {
    let tmp = tempfile::tempdir().unwrap();
    let (room, out) = (tmp.path().join("room"), tmp.path().join("render"));
    let synth = semsplat(tiny_synth_args(400, 0, (32, 24), &room));
    assert!(synth.status.success(), "{}", stderr(&synth));
    let child = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .arg("render")
        .args(["--scene".as_ref(), room.join("scene.ply").as_os_str()])
        .args(["--cameras".as_ref(), room.join("cameras.json").as_os_str()])
        .args(["--out".as_ref(), out.as_os_str()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let first = out.join("train_0000.png");
    for _ in 0..300_000 {
        if first.exists() {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let err = interrupt(child);
    let done: usize = (err.split("stopped after ").nth(1))
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count of views written: {err}"));
    assert!((1..400).contains(&done), "{err}");
    assert!(err.contains(&format!("{done} of 400 views")), "{err}");
    let last = format!("train_{:04}", done - 1);
    assert!(
        err.contains(&format!("train_0000 to {last}")) || done == 1,
        "{err}"
    );
    // Each written view's files, and perhaps some of the next one's (stopped mid-view).
    let mut views: Vec<String> = (all_files(&out).iter())
        .filter(|n| n.ends_with(".png"))
        .map(|n| n.split('.').next().unwrap().to_string())
        .collect();
    views.sort();
    views.dedup();
    let view = |i: usize| format!("train_{i:04}");
    let whole: Vec<String> = (0..done).map(view).collect();
    assert!(
        views == whole || views == (0..=done).map(view).collect::<Vec<_>>(),
        "{views:?}: {err}"
    );
    for v in &whole {
        assert!(out.join(format!("{v}.png")).exists(), "{v}.png");
    }
}

/// A render that fails part-way (here a folder where its third view's image goes, as a full
/// disk would fail it) names the views it wrote whole, as an interrupted one does.
#[test]
fn a_render_failing_part_way_names_the_views_written() {
    let tmp = tempfile::tempdir().unwrap();
    let (room, out) = (tmp.path().join("room"), tmp.path().join("render"));
    synth(&room);
    std::fs::create_dir_all(out.join("train_0002.png")).unwrap();
    let r = semsplat(
        [
            "render",
            "--scene",
            room.join("scene.ply").to_str().unwrap(),
        ]
        .into_iter()
        .chain(["--cameras", room.join("cameras.json").to_str().unwrap()])
        .chain(["--out", out.to_str().unwrap(), "--force"]),
    );
    let err = stderr(&r);
    assert!(!r.status.success(), "{err}");
    assert!(
        err.contains("stopped after 2 of 4 views")
            && err.contains("train_0000 to train_0001")
            && err.contains("train_0002.png"),
        "{err}"
    );
    assert!(out.join("train_0001.png").is_file());
    assert!(!out.join("test_0000.png").exists());
    assert_eq!(temp_files(&out), Vec::<String>::new());
}

/// A synth stopped part-way over an earlier one leaves no room to read: the earlier run's
/// views are removed before any is written, and the cameras and summary come last (a
/// stopped rerun left the new scene beside the old run's label maps, and fuse read them,
/// mIoU 0.20 where the room gives 0.94). Its rerun needs no --force.
#[test]
fn a_synth_stopped_part_way_leaves_no_mixed_room() {
    let tmp = tempfile::tempdir().unwrap();
    let synth_seed = |out: &Path, seed: &str| {
        let args = tiny_synth_args(6, 1, (64, 48), out);
        semsplat(args.into_iter().chain(["--seed".into(), seed.into()]))
    };
    let (room, reference) = (tmp.path().join("room"), tmp.path().join("reference"));
    assert!(synth_seed(&room, "0").status.success());
    assert!(synth_seed(&reference, "7").status.success());
    // A view's image that cannot be replaced (a folder in its place) stops the rerun.
    let blocker = room.join("images/train_0003.png");
    std::fs::remove_file(&blocker).unwrap();
    std::fs::create_dir(&blocker).unwrap();
    let stopped = synth_seed(&room, "7");
    assert!(!stopped.status.success());
    assert!(!room.join("cameras.json").exists() && !room.join("synth.json").exists());
    for name in all_files(&room.join("labels")) {
        let left = std::fs::read(room.join("labels").join(&name)).unwrap();
        let new = std::fs::read(reference.join("labels").join(&name)).unwrap();
        assert!(left == new, "labels/{name} is the earlier run's");
    }
    let (labels, fused) = (room.join("labels"), tmp.path().join("f.ply"));
    let fuse = semsplat([
        "fuse",
        "--scene",
        room.to_str().unwrap(),
        "--labels",
        labels.to_str().unwrap(),
        "--out",
        fused.to_str().unwrap(),
    ]);
    assert!(
        !fuse.status.success() && stderr(&fuse).contains("cameras"),
        "{}",
        stderr(&fuse)
    );
    std::fs::remove_dir(&blocker).unwrap();
    assert!(
        synth_seed(&room, "7").status.success(),
        "the rerun needs --force"
    );
    assert!(room.join("cameras.json").is_file() && room.join("synth.json").is_file());
}

/// A finite but absurd learning rate makes the logits overflow: training stops with the
/// iteration, and writes nothing (it used to write a NaN model with exit 0).
#[test]
fn diverged_training_stops_with_a_clear_error_and_no_output() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    synth(&room);
    let out = tmp.path().join("diverged.ply");
    let r = |f: &str| room.join(f);
    let run = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .arg("train")
        .args(["--images".as_ref(), r("images").as_os_str()])
        .args(["--labels".as_ref(), r("labels").as_os_str()])
        .args(["--cameras".as_ref(), r("cameras.json").as_os_str()])
        .args(["--init".as_ref(), r("init.ply").as_os_str()])
        .args(["--semantics-only", "--iters", "20", "--lr-logits", "1e38"])
        .args(["--out".as_ref(), out.as_os_str()])
        .output()
        .unwrap();
    let err = stderr(&run);
    assert!(!run.status.success(), "a diverged run succeeded: {err}");
    assert!(
        err.contains("training diverged") && err.contains("not finite at iteration"),
        "{err}"
    );
    assert!(!out.exists(), "a diverged model was written");
}

/// Ctrl-C while `fuse` streams its evidence rows to the scratch file beside --out (as
/// --save-contrib asks): exit 130, and neither an output nor the scratch file is left.
#[test]
fn ctrl_c_during_fuse_leaves_neither_output_nor_scratch_file() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    common::cli::synth_tiny(&room, 200, (96, 72));
    let out_dir = tmp.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let r = |f: &str| room.join(f);
    let mut child = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .arg("fuse")
        .arg("--scene")
        .arg(r("scene.ply"))
        .arg("--cameras")
        .arg(r("cameras.json"))
        .arg("--labels")
        .arg(r("labels"))
        .arg("--out")
        .arg(out_dir.join("fused.ply"))
        .arg("--save-contrib")
        .arg(out_dir.join("contrib.npy"))
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The scratch file appears before the first view is fused: signal once it is there.
    let mut scratch_seen = false;
    for _ in 0..120_000 {
        scratch_seen = all_files(&out_dir)
            .iter()
            .any(|n| n.contains("semsplat-tmp"));
        if scratch_seen || child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(scratch_seen, "fuse ended before its scratch file was seen");
    interrupt(child);
    let left = all_files(&out_dir);
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// A rerun of synth that fails part-way (a folder where a view's file goes) says that the
/// folder no longer holds the earlier room, rather than leaving the user to find out.
#[test]
fn a_synth_rerun_that_fails_says_the_earlier_room_is_gone() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("room");
    synth(&out);
    let view = out.join("images").join("train_0001.png");
    std::fs::remove_file(&view).unwrap();
    std::fs::create_dir(&view).unwrap();
    let o = semsplat(tiny_synth_args(3, 1, (32, 24), &out));
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("no longer holds the earlier run's room") && err.contains("is a folder"),
        "{err}"
    );
    assert!(
        !out.join("cameras.json").exists(),
        "no room is readable there"
    );
}
