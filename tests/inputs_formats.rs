//! Inputs the way other tools write them: NumPy arrays in Fortran order, pycolmap's
//! images.txt variants, INRIA run folders, nerfstudio transforms.json, .splat / .spz /
//! SuperSplat compressed PLY, class ids written unsigned. Every file here is built byte by
//! byte (or by a small generator following the other tool's writer), no network.

use std::path::Path;
use std::process::Command;

use semsplat::fuse::ClassScores;
use semsplat::scene::ply::{read_ply, write_ply};
use semsplat::scene::Gaussians;
use semsplat::util::npy::parse_npy_f64;

fn semsplat(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_semsplat"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = semsplat(args);
    assert!(
        out.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn fails(args: &[&str]) -> String {
    let out = semsplat(args);
    assert!(!out.status.success(), "{args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

// ---------------------------------------------------------------------------------------
// .npy

/// A version 1.0 .npy file as numpy writes it: magic, header dict padded with spaces to a
/// multiple of 64 bytes and ended by '\n', then the raw little-endian values.
fn npy_bytes(descr: &str, fortran: bool, shape: &[usize], raw: &[u8]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let order = if fortran { "True" } else { "False" };
    let mut dict =
        format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape_text}, }}");
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.extend_from_slice(raw);
    out
}

fn f64_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// B = [[1, 2, 3], [4, 5, 6]] saved as `np.save(p, B)` and as `np.save(p, B.T.T)` in
/// Fortran order (numpy writes the column-major bytes 1 4 2 5 3 6 with fortran_order True):
/// both read as the same row-major matrix.
#[test]
fn fortran_order_npy_is_transposed_on_read() {
    let c = npy_bytes("<f8", false, &[2, 3], &f64_bytes(&[1., 2., 3., 4., 5., 6.]));
    let f = npy_bytes("<f8", true, &[2, 3], &f64_bytes(&[1., 4., 2., 5., 3., 6.]));
    let from_c = parse_npy_f64(&c).unwrap();
    let from_f = parse_npy_f64(&f).unwrap();
    assert_eq!(from_c.shape, vec![2, 3]);
    assert_eq!(from_c.data, vec![1., 2., 3., 4., 5., 6.]);
    assert_eq!(from_f, from_c);
    // 3-D, float32: element [i][j][k] = 100 i + 10 j + k, stored with i fastest.
    let (a, b, cc) = (2, 3, 4);
    let mut col_major = Vec::new();
    for k in 0..cc {
        for j in 0..b {
            for i in 0..a {
                col_major.extend_from_slice(&((100 * i + 10 * j + k) as f32).to_le_bytes());
            }
        }
    }
    let arr = parse_npy_f64(&npy_bytes("<f4", true, &[a, b, cc], &col_major)).unwrap();
    let want: Vec<f64> = (0..a)
        .flat_map(|i| (0..b).flat_map(move |j| (0..cc).map(move |k| (100 * i + 10 * j + k) as f64)))
        .collect();
    assert_eq!(arr.data, want);
}

#[test]
fn truncated_npy_names_the_file_and_byte_counts() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("A.npy");
    let mut bytes = npy_bytes("<f8", false, &[2, 3], &f64_bytes(&[1., 2., 3., 4., 5., 6.]));
    bytes.truncate(bytes.len() - 5);
    std::fs::write(&path, &bytes).unwrap();
    let err = format!("{:#}", ClassScores::load_npy(&path).unwrap_err());
    assert!(err.contains("A.npy"), "{err}");
    assert!(
        err.contains("48 bytes") && err.contains("43 bytes"),
        "{err}"
    );
}

/// `n` plain Gaussians along x (degree 0), enough for file-format tests.
fn line_of_gaussians(n: usize) -> Gaussians {
    Gaussians {
        means: (0..n).map(|i| [i as f32, 0.5, 2.0]).collect(),
        log_scales: vec![[-2.0, -2.5, -3.0]; n],
        quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
        opacity_logits: vec![1.0; n],
        sh_degree: 0,
        sh: (0..n * 3).map(|i| (i % 7) as f32 * 0.1).collect(),
        ..Default::default()
    }
}

/// `fuse --contrib` on an evidence matrix saved in Fortran order assigns the classes of the
/// matrix it holds (read as C order it would give [1, 1, 1]).
#[test]
fn fuse_contrib_reads_fortran_order_evidence() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_ply(&d.join("scene.ply"), &line_of_gaussians(3)).unwrap();
    // A = [[5, 0, 2], [1, 6, 3]] stored column-major.
    let a = npy_bytes("<f8", true, &[2, 3], &f64_bytes(&[5., 1., 0., 6., 2., 3.]));
    std::fs::write(d.join("A.npy"), a).unwrap();
    std::fs::write(
        d.join("A.classes.json"),
        r#"[{"id": 3, "name": "chair"}, {"id": 7, "name": "table"}]"#,
    )
    .unwrap();
    ok(&[
        "fuse",
        "--scene",
        s(&d.join("scene.ply")),
        "--contrib",
        s(&d.join("A.npy")),
        "--out",
        s(&d.join("out.ply")),
    ]);
    let fused = read_ply(&d.join("out.ply")).unwrap();
    assert_eq!(fused.class_ids.unwrap(), vec![3, 7, 7]);
}
