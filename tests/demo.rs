//! `semsplat demo` end to end on the tiny room, and the charts it draws.

use std::process::Command;

#[test]
fn demo_reports_every_method_with_finite_numbers_and_valid_charts() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let run = Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(
            "demo --preset tiny --views 6 --test-views 2 --width 96 --height 72 \
             --semantics-only-iters 25 --joint-iters 25"
                .split_whitespace(),
        )
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let table = String::from_utf8_lossy(&run.stdout);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let methods = report["methods"].as_array().unwrap();
    let names: Vec<&str> = methods
        .iter()
        .map(|m| m["method"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "vote",
            "vote --occlusion",
            "vote --weighted",
            "flashsplat",
            "flashsplat --per-view",
            "segment-consensus",
            "segment-consensus --relabel",
            "joint --semantics-only",
            "joint"
        ]
    );
    for m in methods {
        for key in ["seconds", "miou", "pixel_accuracy", "gaussian_accuracy"] {
            let v = m[key].as_f64().unwrap();
            assert!(v.is_finite() && v >= 0.0, "{}: {key} = {v}", m["method"]);
        }
        assert!(m["miou"].as_f64().unwrap() <= 1.0);
        assert!(m["peak_device_bytes"].as_u64().unwrap() > 0);
        assert!(
            table.contains(m["method"].as_str().unwrap()),
            "table lacks {}",
            m["method"]
        );
    }
    // On true labels every method should label most held-out pixels right.
    assert!(
        methods
            .iter()
            .all(|m| m["pixel_accuracy"].as_f64().unwrap() > 0.7),
        "{report}"
    );
    let chart = image::open(out.join("speed_vs_accuracy.png")).unwrap();
    assert_eq!(
        (chart.width(), chart.height()),
        semsplat::eval::chart::CHART_SIZE
    );
    let strip = image::open(out.join("strip.png")).unwrap();
    assert!(
        strip.width() > 6 * 96 && strip.height() > 72,
        "{}x{}",
        strip.width(),
        strip.height()
    );
}
