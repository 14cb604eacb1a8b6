//! Inputs the way other tools write them: NumPy arrays in Fortran order, pycolmap's
//! images.txt variants, INRIA run folders, nerfstudio transforms.json, .splat / .spz /
//! SuperSplat compressed PLY, class ids written unsigned. Every file here is built byte by
//! byte (or by a small generator following the other tool's writer), no network.

mod common;

use common::cli::{fails, ok};

use std::io::{Read, Write};
use std::path::Path;

use glam::{DMat3, DVec3};
use semsplat::fuse::ClassScores;
use semsplat::scene::cameras::load_cameras;
use semsplat::scene::cameras_json::write_inria_cameras;
use semsplat::scene::classes::ClassTable;
use semsplat::scene::colmap::read_images_txt_from;
use semsplat::scene::gaussians::sh_coeffs_for_degree;
use semsplat::scene::ply::{read_ply, read_ply_from, write_ply, write_ply_to};
use semsplat::scene::scene_file::{
    cameras_for_scene, read_scene, read_scene_or_point_cloud, resolve_scene_path,
};
use semsplat::scene::{Camera, Gaussians, SemanticLogits, Split};
use semsplat::util::npy::parse_npy_f64;
use semsplat::util::Rng;

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
    let dict = format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {shape_text}, }}");
    common::npy::npy_v1(&dict, raw)
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

/// Contributions that are finite one by one but whose sum for a Gaussian is not (its
/// confidence would divide by infinity) are refused, naming the Gaussian; NaN too.
#[test]
fn evidence_past_float64s_range_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("A.npy");
    let cases: [(&[f64], &str); 2] = [
        (&[1., 1e308, 3., 4., 1e308, 6.], "Gaussian 1 sum past"),
        (&[1., f64::NAN, 3., 4., 5., 6.], "finite and >= 0"),
    ];
    for (values, needle) in cases {
        std::fs::write(&path, npy_bytes("<f8", false, &[2, 3], &f64_bytes(values))).unwrap();
        let err = format!("{:#}", ClassScores::load_npy(&path).unwrap_err());
        assert!(err.contains(needle), "{err}");
    }
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

// ---------------------------------------------------------------------------------------
// Splat files written the way other tools write them, compared with the standard PLY reading
// of the same Gaussians within each format's quantization.

const SH_C0: f64 = 0.282_094_791_773_878_14;

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// Gaussians inside every format's range: |DC| < 1.7 (.splat clips colour to [0, 1]), SH
/// rest in [-0.9, 0.9] (spz's [-1, 1]), log-scales in [-6, 0], w the largest quaternion
/// component of moderate size (so spz version 2's derived w stays accurate).
fn format_gaussians(n: usize, sh_degree: u32, seed: u64) -> Gaussians {
    let mut rng = Rng::new(seed);
    let mut u = |a: f64, b: f64| rng.range_f64(a, b) as f32;
    let k = sh_coeffs_for_degree(sh_degree);
    let mut g = Gaussians {
        sh_degree,
        ..Default::default()
    };
    for _ in 0..n {
        g.means.push([u(-3.0, 3.0), u(-3.0, 3.0), u(-3.0, 3.0)]);
        g.log_scales
            .push([u(-6.0, 0.0), u(-6.0, 0.0), u(-6.0, 0.0)]);
        g.quats
            .push([u(1.0, 2.0), u(-0.8, 0.8), u(-0.8, 0.8), u(-0.8, 0.8)]);
        g.opacity_logits.push(u(-3.0, 3.0));
        for c in 0..k * 3 {
            g.sh.push(if c < 3 { u(-1.7, 1.7) } else { u(-0.9, 0.9) });
        }
    }
    g
}

/// The standard PLY reading of `g` (what a user's scene.ply would load as).
fn via_standard_ply(g: &Gaussians) -> Gaussians {
    let mut bytes = Vec::new();
    write_ply_to(&mut bytes, g).unwrap();
    read_ply_from(&bytes[..], Some(bytes.len() as u64)).unwrap()
}

fn unit_quat(q: [f32; 4]) -> [f64; 4] {
    let n = q.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    q.map(|v| v as f64 / n)
}

/// Per-field tolerances of a lossy format.
struct Tol {
    mean: f64,
    log_scale: f64,
    /// On sigmoid(opacity).
    alpha: f64,
    dc: f64,
    rest: f64,
    /// Lower bound of |dot| of the unit quaternions.
    quat_dot: f64,
}

fn assert_close(got: &Gaussians, want: &Gaussians, tol: &Tol, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: count");
    assert_eq!(got.sh_degree, want.sh_degree, "{what}: SH degree");
    got.validate().unwrap();
    let k3 = want.sh_coeffs() * 3;
    for i in 0..want.len() {
        for a in 0..3 {
            let d = (got.means[i][a] - want.means[i][a]).abs() as f64;
            assert!(d <= tol.mean, "{what}: Gaussian {i} mean {a} off by {d}");
            let d = (got.log_scales[i][a] - want.log_scales[i][a]).abs() as f64;
            assert!(
                d <= tol.log_scale,
                "{what}: Gaussian {i} log-scale {a} off by {d}"
            );
        }
        let d =
            (sigmoid(got.opacity_logits[i] as f64) - sigmoid(want.opacity_logits[i] as f64)).abs();
        assert!(d <= tol.alpha, "{what}: Gaussian {i} opacity off by {d}");
        let (qa, qb) = (unit_quat(got.quats[i]), unit_quat(want.quats[i]));
        let dot: f64 = qa.iter().zip(&qb).map(|(a, b)| a * b).sum::<f64>().abs();
        assert!(
            dot >= tol.quat_dot,
            "{what}: Gaussian {i} rotation: |dot| {dot}"
        );
        for c in 0..k3 {
            let d = (got.sh[i * k3 + c] - want.sh[i * k3 + c]).abs() as f64;
            let t = if c < 3 { tol.dc } else { tol.rest };
            assert!(
                d <= t,
                "{what}: Gaussian {i} SH value {c} off by {d} (tolerance {t})"
            );
        }
    }
}

/// A `.splat` as antimatter15's `convert.py` writes it: float32 position and exp(scale),
/// `(0.5 + SH_C0 f_dc, sigmoid(opacity)) * 255` clipped and truncated to u8, and
/// `q / |q| * 128 + 128` clipped and truncated to u8 (w x y z).
fn write_splat_like_convert_py(g: &Gaussians) -> Vec<u8> {
    let to_u8 = |v: f64| v.clamp(0.0, 255.0) as u8;
    let mut out = Vec::new();
    for i in 0..g.len() {
        for v in g.means[i] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in g.log_scales[i] {
            out.extend_from_slice(&v.exp().to_le_bytes());
        }
        for c in 0..3 {
            out.push(to_u8((0.5 + SH_C0 * g.sh[i * 3 + c] as f64) * 255.0));
        }
        out.push(to_u8(sigmoid(g.opacity_logits[i] as f64) * 255.0));
        for v in unit_quat(g.quats[i]) {
            out.push(to_u8(v * 128.0 + 128.0));
        }
    }
    out
}

#[test]
fn splat_file_matches_the_standard_ply_within_its_quantization() {
    let g = format_gaussians(200, 0, 11);
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("scene.splat");
    std::fs::write(&path, write_splat_like_convert_py(&g)).unwrap();
    let tol = Tol {
        mean: 0.0,
        log_scale: 1e-5,
        // Truncation to u8: up to one step, plus the clamp of 0 and 255.
        alpha: 1.0 / 255.0 + 1e-6,
        dc: 1.0 / 255.0 / SH_C0 + 1e-5,
        rest: 0.0,
        quat_dot: 0.999,
    };
    assert_close(
        &read_scene(&path).unwrap(),
        &via_standard_ply(&g),
        &tol,
        ".splat",
    );
    // A cut record is named as such.
    let mut bytes = std::fs::read(&path).unwrap();
    bytes.truncate(bytes.len() - 3);
    std::fs::write(&path, bytes).unwrap();
    let err = format!("{:#}", read_scene(&path).unwrap_err());
    assert!(
        err.contains("scene.splat") && err.contains("multiple of 32"),
        "{err}"
    );
}

/// spz's `flipSh` signs for RDF <-> RUB (x 1, y -1, z -1), per coefficient past DC.
const SPZ_FLIP_SH: [f32; 15] = [
    -1., -1., 1., -1., 1., 1., -1., 1., -1., 1., -1., -1., 1., -1., 1.,
];

/// An .spz as nianticlabs/spz `packGaussians` + `serializePackedGaussians` write it from an
/// RDF (PLY) scene, gzip-compressed: 12 fractional bits, SH quantized with 5 bits (degree 1)
/// and 4 bits (higher), rotations as version 2 (first three) or 3 (smallest three).
fn write_spz_like_niantic(g: &Gaussians, version: u32) -> Vec<u8> {
    let to_u8 = |x: f32| x.round().clamp(0.0, 255.0) as u8;
    let quantize_sh = |x: f32, bucket: i32| {
        let q = (x * 128.0).round() as i32 + 128;
        (((q + bucket / 2) / bucket) * bucket).clamp(0, 255) as u8
    };
    let n = g.len();
    let rest = g.sh_coeffs() - 1;
    let mut raw = Vec::new();
    raw.extend_from_slice(&0x5053_474e_u32.to_le_bytes());
    raw.extend_from_slice(&version.to_le_bytes());
    raw.extend_from_slice(&(n as u32).to_le_bytes());
    raw.extend_from_slice(&[g.sh_degree as u8, 12, 0, 0]);
    let flip_p = [1.0f32, -1.0, -1.0];
    for i in 0..n {
        for (flip, v) in flip_p.iter().zip(g.means[i]) {
            let fixed = (flip * v * 4096.0).round() as i32;
            raw.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
    }
    for i in 0..n {
        raw.push(to_u8(sigmoid(g.opacity_logits[i] as f64) as f32 * 255.0));
    }
    for i in 0..n {
        for c in 0..3 {
            raw.push(to_u8(
                g.sh[i * g.sh_coeffs() * 3 + c] * (0.15 * 255.0) + 0.5 * 255.0,
            ));
        }
    }
    for i in 0..n {
        for a in 0..3 {
            raw.push(to_u8((g.log_scales[i][a] + 10.0) * 16.0));
        }
    }
    for i in 0..n {
        let w = unit_quat(g.quats[i]);
        // xyzw in RUB: x y z times (1, -1, -1).
        let q = [w[1] as f32, -w[2] as f32, -w[3] as f32, w[0] as f32];
        if version >= 3 {
            raw.extend_from_slice(&pack_smallest_three(q));
        } else {
            let s = if q[3] < 0.0 { -127.5 } else { 127.5 };
            for v in &q[..3] {
                raw.push(to_u8(v * s + 127.5));
            }
        }
    }
    for i in 0..n {
        for (k, flip) in SPZ_FLIP_SH.iter().enumerate().take(rest) {
            for c in 0..3 {
                let v = flip * g.sh[i * g.sh_coeffs() * 3 + (1 + k) * 3 + c];
                raw.push(quantize_sh(v, if k < 3 { 8 } else { 16 }));
            }
        }
    }
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&raw).unwrap();
    gz.finish().unwrap()
}

/// spz's `packQuaternionSmallestThree` (xyzw order).
fn pack_smallest_three(q: [f32; 4]) -> [u8; 4] {
    let largest = (0..4)
        .max_by(|&a, &b| q[a].abs().partial_cmp(&q[b].abs()).unwrap())
        .unwrap();
    let negate = q[largest] < 0.0;
    let mut comp = largest as u32;
    for (i, v) in q.iter().enumerate() {
        if i != largest {
            let negbit = ((*v < 0.0) ^ negate) as u32;
            let mag = (511.0 * (v.abs() / std::f32::consts::FRAC_1_SQRT_2) + 0.5) as u32;
            comp = (comp << 10) | (negbit << 9) | mag;
        }
    }
    comp.to_le_bytes()
}

#[test]
fn spz_versions_2_and_3_match_the_standard_ply_within_their_quantization() {
    let g = format_gaussians(150, 3, 12);
    let tmp = tempfile::tempdir().unwrap();
    let tol = |quat_dot| Tol {
        mean: 0.5 / 4096.0 + 1e-5,
        log_scale: 0.5 / 16.0 + 1e-5,
        alpha: 0.5 / 255.0 + 1e-5,
        dc: 0.5 / (0.15 * 255.0) + 1e-5,
        // 4-bit buckets of 16/128 (degree 2 and 3): half a bucket plus the 1/128 rounding.
        rest: 8.0 / 128.0 + 1.0 / 128.0 + 1e-5,
        quat_dot,
    };
    for (version, quat_dot) in [(2, 0.999), (3, 0.99999)] {
        let path = tmp.path().join(format!("v{version}.spz"));
        std::fs::write(&path, write_spz_like_niantic(&g, version)).unwrap();
        let got = read_scene(&path).unwrap();
        assert_close(
            &got,
            &via_standard_ply(&g),
            &tol(quat_dot),
            &format!("spz v{version}"),
        );
    }
    // Degree 1 keeps 5 bits: half of an 8/128 bucket.
    let g1 = format_gaussians(50, 1, 13);
    let path = tmp.path().join("d1.spz");
    std::fs::write(&path, write_spz_like_niantic(&g1, 2)).unwrap();
    let t = Tol {
        rest: 4.0 / 128.0 + 1.0 / 128.0 + 1e-5,
        ..tol(0.999)
    };
    assert_close(
        &read_scene(&path).unwrap(),
        &via_standard_ply(&g1),
        &t,
        "spz degree 1",
    );
    // Not gzip, a version 4 file (its header uncompressed), a cut gzip stream, and a
    // version this build does not read, are named.
    std::fs::write(&path, b"PLY, not gzip").unwrap();
    let err = format!("{:#}", read_scene(&path).unwrap_err());
    assert!(
        err.contains("d1.spz") && err.contains("gzip header"),
        "{err}"
    );
    std::fs::write(&path, b"NGSP\x04\0\0\0 the rest").unwrap();
    let err = format!("{:#}", read_scene(&path).unwrap_err());
    assert!(
        err.contains("version 4") && err.contains("convert it to PLY"),
        "{err}"
    );
    let whole = write_spz_like_niantic(&g1, 2);
    std::fs::write(&path, &whole[..whole.len() / 2]).unwrap();
    let err = format!("{:#}", read_scene(&path).unwrap_err());
    assert!(err.contains("truncated or corrupt"), "{err}");
    let mut v4 = write_spz_like_niantic(&g1, 2);
    let mut raw = Vec::new();
    flate2::read::GzDecoder::new(&v4[..])
        .read_to_end(&mut raw)
        .unwrap();
    raw[4] = 4;
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&raw).unwrap();
    v4 = gz.finish().unwrap();
    std::fs::write(&path, v4).unwrap();
    let err = format!("{:#}", read_scene(&path).unwrap_err());
    assert!(err.contains("version 4"), "{err}");
}

/// Splats per chunk in splat-transform's compressed PLY.
const COMPRESSED_CHUNK: usize = 256;

/// Header of a compressed PLY: `chunks` rows of float min/max, `n` packed vertices, and an
/// `sh` element of `rest` bytes per splat when there is SH beyond DC.
fn compressed_ply_header(n: usize, chunks: usize, rest: usize) -> String {
    let mut header =
        String::from("ply\nformat binary_little_endian 1.0\ncomment Generated by a test\n");
    header += &format!("element chunk {chunks}\n");
    for p in [
        "min_x",
        "min_y",
        "min_z",
        "max_x",
        "max_y",
        "max_z",
        "min_scale_x",
        "min_scale_y",
        "min_scale_z",
        "max_scale_x",
        "max_scale_y",
        "max_scale_z",
        "min_r",
        "min_g",
        "min_b",
        "max_r",
        "max_g",
        "max_b",
    ] {
        header += &format!("property float {p}\n");
    }
    header += &format!("element vertex {n}\n");
    for p in [
        "packed_position",
        "packed_rotation",
        "packed_scale",
        "packed_color",
    ] {
        header += &format!("property uint {p}\n");
    }
    if rest > 0 {
        header += &format!("element sh {n}\n");
        for i in 0..rest {
            header += &format!("property uchar f_rest_{i}\n");
        }
    }
    header += "end_header\n";
    header
}

/// splat-transform's unsigned normalized integer of `bits` bits for `v` in [0, 1].
fn unorm(v: f64, bits: u32) -> u32 {
    let t = ((1u32 << bits) - 1) as f64;
    (v * t + 0.5).floor().clamp(0.0, t) as u32
}

/// `x` as a fraction of the chunk's range [lo, hi] (0 where the range is empty).
fn normalize_in_range(x: f64, lo: f64, hi: f64) -> f64 {
    if x <= lo {
        0.0
    } else if x >= hi {
        1.0
    } else if hi - lo < 1e-5 {
        0.0
    } else {
        (x - lo) / (hi - lo)
    }
}

/// The 9 fields a chunk bounds, for Gaussian `i`: x y z, log-scales, colours 0.5 + SH_C0 f_dc.
fn compressed_field(g: &Gaussians, i: usize, f: usize) -> f64 {
    match f {
        0..=2 => g.means[i][f] as f64,
        3..=5 => g.log_scales[i][f - 3] as f64,
        _ => 0.5 + SH_C0 * g.sh[i * g.sh_coeffs() * 3 + f - 6] as f64,
    }
}

/// 2-10-10-10 rotation: the largest component's index, then the other three of the
/// quaternion signed so that the largest is positive.
fn pack_rotation_2_10_10_10(quat: [f32; 4]) -> u32 {
    let mut q = unit_quat(quat);
    let largest = (0..4)
        .max_by(|&a, &b| q[a].abs().partial_cmp(&q[b].abs()).unwrap())
        .unwrap();
    if q[largest] < 0.0 {
        q = q.map(|v| -v);
    }
    let mut rot = largest as u32;
    for (k, v) in q.iter().enumerate() {
        if k != largest {
            rot = (rot << 10) | unorm(v * std::f64::consts::FRAC_1_SQRT_2 + 0.5, 10);
        }
    }
    rot
}

/// Gaussian `i`'s packed position, rotation, scale and colour words within a chunk whose
/// field bounds are `lo` and `hi`.
fn pack_compressed_vertex(g: &Gaussians, i: usize, lo: &[f64], hi: &[f64]) -> [u32; 4] {
    let t = |f: usize| {
        normalize_in_range(
            compressed_field(g, i, f),
            lo[f] as f32 as f64,
            hi[f] as f32 as f64,
        )
    };
    let p111011 =
        |a: usize| unorm(t(a), 11) << 21 | unorm(t(a + 1), 10) << 11 | unorm(t(a + 2), 11);
    let color = unorm(t(6), 8) << 24
        | unorm(t(7), 8) << 16
        | unorm(t(8), 8) << 8
        | unorm(sigmoid(g.opacity_logits[i] as f64), 8);
    [
        p111011(0),
        pack_rotation_2_10_10_10(g.quats[i]),
        p111011(3),
        color,
    ]
}

/// One chunk of `rows`: its float min/max onto `chunk_data`, its packed vertices onto
/// `vertex_data`.
fn write_compressed_chunk(
    g: &Gaussians,
    rows: &[usize],
    chunk_data: &mut Vec<u8>,
    vertex_data: &mut Vec<u8>,
) {
    let lo: Vec<f64> = (0..9)
        .map(|f| {
            rows.iter()
                .map(|&i| compressed_field(g, i, f))
                .fold(f64::MAX, f64::min)
        })
        .collect();
    let hi: Vec<f64> = (0..9)
        .map(|f| {
            rows.iter()
                .map(|&i| compressed_field(g, i, f))
                .fold(f64::MIN, f64::max)
        })
        .collect();
    for group in [0, 3, 6] {
        for v in lo[group..group + 3].iter().chain(&hi[group..group + 3]) {
            chunk_data.extend_from_slice(&(*v as f32).to_le_bytes());
        }
    }
    for &i in rows {
        for word in pack_compressed_vertex(g, i, &lo, &hi) {
            vertex_data.extend_from_slice(&word.to_le_bytes());
        }
    }
}

/// The `sh` element: `trunc((v / 8 + 0.5) * 256)` bytes, f_rest_j channel-major (channel
/// j / (K-1), coefficient 1 + j % (K-1)).
fn write_compressed_sh(g: &Gaussians, out: &mut Vec<u8>) {
    let rest = (g.sh_coeffs() - 1) * 3;
    let k3 = g.sh_coeffs() * 3;
    let per = g.sh_coeffs() - 1;
    for i in 0..g.len() {
        for j in 0..rest {
            let v = g.sh[i * k3 + (1 + j % per) * 3 + j / per] as f64;
            out.push(((v / 8.0 + 0.5) * 256.0).trunc().clamp(0.0, 255.0) as u8);
        }
    }
}

/// A compressed PLY as PlayCanvas splat-transform's `writeCompressedPly` / `CompressedChunk`
/// write it: chunks of 256 with float min/max of position, log-scale and colour, uint32
/// packed 11-10-11 position and scale, 2-10-10-10 rotation, 8-8-8-8 colour + opacity, and a
/// `sh` element of `trunc((v / 8 + 0.5) * 256)` bytes. (splat-transform also sorts splats in
/// Morton order; order is the writer's choice, so it is kept here.)
fn write_compressed_ply_like_splat_transform(g: &Gaussians) -> Vec<u8> {
    let n = g.len();
    let chunks = n.div_ceil(COMPRESSED_CHUNK);
    let rest = (g.sh_coeffs() - 1) * 3;
    let mut chunk_data = Vec::new();
    let mut vertex_data = Vec::new();
    for c in 0..chunks {
        let rows: Vec<usize> =
            (c * COMPRESSED_CHUNK..((c + 1) * COMPRESSED_CHUNK).min(n)).collect();
        write_compressed_chunk(g, &rows, &mut chunk_data, &mut vertex_data);
    }
    let mut out = compressed_ply_header(n, chunks, rest).into_bytes();
    out.extend_from_slice(&chunk_data);
    out.extend_from_slice(&vertex_data);
    write_compressed_sh(g, &mut out);
    out
}

#[test]
fn supersplat_compressed_ply_matches_the_standard_ply_within_its_quantization() {
    // 300 splats: two chunks, the second partial.
    let g = format_gaussians(300, 2, 14);
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("scene.compressed.ply");
    std::fs::write(&path, write_compressed_ply_like_splat_transform(&g)).unwrap();
    // Steps: position and scale 11/10 bits over the chunk's range (6 units), colour 8 bits
    // over at most [0.02, 0.98], SH 8 bits over [-4, 4].
    let tol = Tol {
        mean: 6.0 / 1023.0 + 1e-4,
        log_scale: 6.0 / 1023.0 + 1e-4,
        alpha: 0.5 / 255.0 + 1e-5,
        dc: 1.0 / 255.0 / SH_C0 + 1e-4,
        rest: 8.0 / 256.0 + 1e-5,
        quat_dot: 0.9999,
    };
    let got = read_scene(&path).unwrap();
    assert_close(&got, &via_standard_ply(&g), &tol, "compressed PLY");
}

// ---------------------------------------------------------------------------------------
// COLMAP images.txt as pycolmap writes it

const CAMERAS_TXT: &str = "# Camera list\n1 PINHOLE 64 48 50 50 32 24\n";

fn images_txt_lines(points_line: Option<&str>) -> String {
    let mut text = String::from("# Image list with two lines of data per image:\n");
    let names = [
        "cam0/0001.jpg",
        "cam1/0002.jpg",
        "cam0/0003.jpg",
        "cam1/0004.jpg",
    ];
    for (i, name) in names.iter().enumerate() {
        text += &format!("{} 1 0 0 0 {} 0 0 1 {name}\n", i + 1, i as f64 * 0.5);
        if let Some(p) = points_line {
            text += p;
            text += "\n";
        }
    }
    text
}

/// The three shapes of images.txt: COLMAP's (a points line per image), an empty second line,
/// and pycolmap's one line per image. All four images (rig names with subfolders) come back.
#[test]
fn colmap_images_txt_with_or_without_points_lines_keeps_every_image() {
    for (what, points) in [
        ("points lines", Some("10.5 20.25 7 11.0 3.5 -1")),
        ("empty second lines", Some("")),
        ("one line per image", None),
    ] {
        let text = images_txt_lines(points);
        let images = read_images_txt_from(&mut text.as_bytes()).unwrap();
        let names: Vec<&str> = images.iter().map(|i| i.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "cam0/0001.jpg",
                "cam1/0002.jpg",
                "cam0/0003.jpg",
                "cam1/0004.jpg"
            ],
            "{what}"
        );
        assert_eq!(images[3].tvec, [1.5, 0.0, 0.0], "{what}");
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("cameras.txt"), CAMERAS_TXT).unwrap();
        std::fs::write(tmp.path().join("images.txt"), &text).unwrap();
        let cams = load_cameras(tmp.path()).unwrap();
        assert_eq!(cams.len(), 4, "{what}");
    }
    // A line that is neither is an error naming its line.
    let bad = "1 1 0 0 0 0 0 0 1 a.jpg\n1 2 3 4\n";
    let err = format!(
        "{:#}",
        read_images_txt_from(&mut bad.as_bytes()).unwrap_err()
    );
    assert!(err.contains("line 2"), "{err}");
}

// ---------------------------------------------------------------------------------------
// INRIA run folders

#[test]
fn inria_run_folder_gives_the_latest_iteration_and_its_cameras() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("output/run");
    // Lexically 7000 > 30000; numerically 30000 is the latest.
    for (iters, n) in [(7000, 2), (30000, 3), (999, 4)] {
        let dir = run.join(format!("point_cloud/iteration_{iters}"));
        std::fs::create_dir_all(&dir).unwrap();
        write_ply(&dir.join("point_cloud.ply"), &line_of_gaussians(n)).unwrap();
    }
    for p in [run.clone(), run.join("point_cloud")] {
        assert_eq!(
            resolve_scene_path(&p).unwrap(),
            run.join("point_cloud/iteration_30000/point_cloud.ply")
        );
        assert_eq!(read_scene(&p).unwrap().len(), 3);
    }
    let cams = vec![Camera {
        name: "frame_1".into(),
        width: 64,
        height: 48,
        fx: 50.0,
        fy: 50.0,
        cx: 32.0,
        cy: 24.0,
        rotation: DMat3::IDENTITY,
        translation: DVec3::new(0.0, 0.0, 1.0),
        split: Split::Train,
    }];
    write_inria_cameras(&run.join("cameras.json"), &cams).unwrap();
    assert_eq!(load_cameras(&run).unwrap()[0].name, "frame_1");
    // An empty folder says what it expected.
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let err = format!("{:#}", read_scene(&empty).unwrap_err());
    assert!(
        err.contains("iteration_<N>") && err.contains("scene.ply"),
        "{err}"
    );
    // Left out, the cameras are the run's cameras.json, from the run or a scene inside it;
    // given, the ones given.
    let iteration = run.join("point_cloud/iteration_7000");
    for scene in [
        run.clone(),
        run.join("point_cloud"),
        iteration.clone(),
        iteration.join("point_cloud.ply"),
    ] {
        assert_eq!(
            cameras_for_scene(None, &scene).unwrap(),
            run.join("cameras.json"),
            "{}",
            scene.display()
        );
    }
    // Also named from inside the run (a relative scene, `.`).
    for (inside, scene) in [
        (&iteration, "point_cloud.ply"),
        (&iteration, "."),
        (&iteration, ".."),
        (&run, "point_cloud"),
    ] {
        let views = tmp.path().join("views");
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_semsplat"))
            .args(["render", "--scene", scene, "--out", views.to_str().unwrap()])
            .current_dir(inside)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "{scene} in {}: {stderr}",
            inside.display()
        );
    }
    let given = tmp.path().join("sparse/0");
    assert_eq!(cameras_for_scene(Some(&given), &run).unwrap(), given);
    // Without one in the scene's folder, the error asks for --cameras and names the folder.
    let err = format!("{:#}", cameras_for_scene(None, &empty).unwrap_err());
    assert!(err.contains("--cameras") && err.contains("empty"), "{err}");
}

/// A scene folder as `synth` writes it (scene.ply, cameras.json) names its scene file, and
/// its cameras whether the folder or the file is given.
#[test]
fn scene_folder_gives_its_scene_ply_and_cameras() {
    let tmp = tempfile::tempdir().unwrap();
    let room = tmp.path().join("room");
    std::fs::create_dir_all(&room).unwrap();
    write_ply(&room.join("scene.ply"), &line_of_gaussians(5)).unwrap();
    std::fs::write(room.join("cameras.json"), "[]").unwrap();
    assert_eq!(resolve_scene_path(&room).unwrap(), room.join("scene.ply"));
    assert_eq!(read_scene(&room).unwrap().len(), 5);
    for scene in [room.clone(), room.join("scene.ply")] {
        assert_eq!(
            cameras_for_scene(None, &scene).unwrap(),
            room.join("cameras.json")
        );
    }
}

/// An SfM point cloud (INRIA's input.ply: x y z, normals, uchar colours) and a 2DGS scene
/// are named as what they are.
#[test]
fn point_cloud_and_2dgs_plys_are_named() {
    let tmp = tempfile::tempdir().unwrap();
    let pc = tmp.path().join("input.ply");
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n".to_vec();
    bytes.extend_from_slice(&[0u8; 24]);
    bytes.extend_from_slice(&[10, 20, 30]);
    std::fs::write(&pc, bytes).unwrap();
    let err = format!("{:#}", read_scene(&pc).unwrap_err());
    assert!(
        err.contains("point cloud") && err.contains("input.ply"),
        "{err}"
    );

    let mut header = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
    for p in [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "rot_0",
        "rot_1", "rot_2", "rot_3",
    ] {
        header += &format!("property float {p}\n");
    }
    header += "end_header\n0 0 0 0 0 0 0 -3 -3 1 0 0 0\n";
    let surfels = tmp.path().join("2dgs.ply");
    std::fs::write(&surfels, header).unwrap();
    let err = format!("{:#}", read_scene(&surfels).unwrap_err());
    assert!(err.contains("2DGS scenes are not supported"), "{err}");
}

// ---------------------------------------------------------------------------------------
// nerfstudio transforms.json

/// A camera at (1, 2, 3) whose OpenGL camera-to-world rotation is a 90 degree turn about the
/// world y axis: its -z (viewing) axis becomes world -x... worked by hand below.
#[test]
fn nerfstudio_transforms_convert_the_opengl_pose() {
    // c2w (OpenGL) columns: camera x -> world (0, 0, -1), camera y -> world (0, 1, 0),
    // camera z -> world (1, 0, 0); so the camera looks along world -x.
    let json = r#"{
        "camera_model": "OPENCV", "fl_x": 100, "fl_y": 110, "cx": 31.5, "cy": 24.5,
        "w": 64, "h": 48, "k1": 0, "k2": 0, "p1": 0, "p2": 0,
        "frames": [
            {"file_path": "images/frame_00001.png",
             "transform_matrix": [[0, 0, 1, 1], [0, 1, 0, 2], [-1, 0, 0, 3], [0, 0, 0, 1]]},
            {"file_path": "images/frame_00002.png", "fl_x": 90, "w": 64, "h": 48,
             "transform_matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]]}
        ]}"#;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("transforms.json");
    std::fs::write(&path, json).unwrap();
    let cams = load_cameras(&path).unwrap();
    assert_eq!(cams.len(), 2);
    let c = &cams[0];
    assert_eq!(c.name, "frame_00001");
    assert!((c.center() - DVec3::new(1.0, 2.0, 3.0)).length() < 1e-12);
    // By hand: a point 2 m in front (world (-1, 2, 3)) projects to the principal point; a
    // point 1 m above it in world y (up) lands above it in the image (v smaller by fy / 2);
    // world -z is the camera's right (OpenCV x): u larger by fx / 2.
    let project = |p: DVec3| c.project_camera_point(c.world_to_camera(p));
    let (u, v) = project(DVec3::new(-1.0, 2.0, 3.0));
    assert!(
        (u - 31.5).abs() < 1e-9 && (v - 24.5).abs() < 1e-9,
        "{u} {v}"
    );
    let (u, v) = project(DVec3::new(-1.0, 3.0, 3.0));
    assert!(
        (u - 31.5).abs() < 1e-9 && (v - (24.5 - 55.0)).abs() < 1e-9,
        "{u} {v}"
    );
    let (u, v) = project(DVec3::new(-1.0, 2.0, 2.0));
    assert!(
        (u - (31.5 + 50.0)).abs() < 1e-9 && (v - 24.5).abs() < 1e-9,
        "{u} {v}"
    );
    assert!(c.world_to_camera(DVec3::new(-1.0, 2.0, 3.0)).z > 0.0);
    // The second frame's own fl_x wins; fl_y falls back to the top level.
    assert_eq!((cams[1].fx, cams[1].fy), (90.0, 110.0));
    // The folder finds its transforms.json too.
    assert_eq!(load_cameras(tmp.path()).unwrap().len(), 2);

    for (bad, expect) in [
        (json.replace("\"k1\": 0", "\"k1\": 0.01"), "k1"),
        (json.replace("OPENCV", "OPENCV_FISHEYE"), "OPENCV_FISHEYE"),
    ] {
        std::fs::write(&path, bad).unwrap();
        let err = format!("{:#}", load_cameras(&path).unwrap_err());
        assert!(err.contains(expect) && err.contains("undistort"), "{err}");
    }

    // nerfstudio's split lists: a frame test_filenames (or val_filenames) names is held
    // out, written with or without "./" and the extension; a list naming no frame is
    // refused rather than holding nothing out.
    let split = |list: &str| json.replacen("\"frames\"", &format!("{list}, \"frames\""), 1);
    std::fs::write(
        &path,
        split(r#""test_filenames": ["./images/frame_00002"]"#),
    )
    .unwrap();
    let splits: Vec<Split> = (load_cameras(&path).unwrap().iter())
        .map(|c| c.split)
        .collect();
    assert_eq!(splits, [Split::Train, Split::Test]);
    std::fs::write(&path, split(r#""val_filenames": ["frame_00002.png"]"#)).unwrap();
    let err = format!("{:#}", load_cameras(&path).unwrap_err());
    assert!(
        err.contains("'val_filenames' names 1 files, none a frame's"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------------------
// Semantic properties other tools rewrite; class tables; the PLY writer

/// splat-transform rewrites `class` as uint: -1 comes back as 4294967295, which is unseen.
#[test]
fn unsigned_class_4294967295_reads_as_unseen() {
    let mut text = String::from("ply\nformat ascii 1.0\nelement vertex 2\n");
    for p in ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity"] {
        text += &format!("property float {p}\n");
    }
    for p in [
        "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ] {
        text += &format!("property float {p}\n");
    }
    text += "property uint class\nproperty uint instance\nend_header\n";
    text += "0 0 0 0 0 0 0 -3 -3 -3 1 0 0 0 4294967295 4294967295\n";
    text += "1 0 0 0 0 0 0 -3 -3 -3 1 0 0 0 5 2\n";
    let g = read_ply_from(text.as_bytes(), None).unwrap();
    assert_eq!(g.class_ids.unwrap(), vec![-1, 5]);
    assert_eq!(g.instance_ids.unwrap(), vec![-1, 2]);
    // Other values past i32::MAX are still refused.
    let bad = text.replace(" 5 2\n", " 4294967294 2\n");
    assert!(read_ply_from(bad.as_bytes(), None).is_err());
}

#[test]
fn class_table_errors_name_the_entry_and_names_match_any_case() {
    let err = format!(
        "{:#}",
        ClassTable::from_json_str(r#"[{"id": 1, "name": "wall"}, {"id": "two", "name": "floor"}]"#)
            .unwrap_err()
    );
    assert!(
        err.contains("class entry 1") && err.contains("\"two\""),
        "{err}"
    );
    assert!(!err.contains("untagged"), "{err}");
    let t = ClassTable::from_json_str(r#"{"classes": [{"id": 1, "name": "Chair"}, {"id": 4}]}"#)
        .unwrap();
    assert_eq!(t.find("chair").unwrap().id, 1);
    assert_eq!(t.find("CHAIR").unwrap().id, 1);
    assert_eq!(t.find("4").unwrap().id, 4);
    let err = format!("{:#}", t.find("table").unwrap_err());
    assert!(err.contains("Chair"), "{err}");
}

#[test]
fn ply_writer_refuses_non_finite_values_naming_property_and_index() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("nan.ply");
    let mut g = line_of_gaussians(4);
    g.opacity_logits[2] = f32::NAN;
    let err = format!("{:#}", write_ply(&path, &g).unwrap_err());
    assert!(
        err.contains("Gaussian 2") && err.contains("opacity"),
        "{err}"
    );
    assert!(!path.exists());
    let mut g = line_of_gaussians(4);
    g.semantics = Some(SemanticLogits {
        channels: 2,
        logits: vec![0.0, 0.0, 0.0, f32::INFINITY, 0.0, 0.0, 0.0, 0.0],
    });
    let err = format!("{:#}", write_ply(&path, &g).unwrap_err());
    assert!(err.contains("Gaussian 1") && err.contains("sem_1"), "{err}");
    // Results are standard PLYs: a name promising another format is refused.
    let splat = tmp.path().join("fused.splat");
    let err = format!(
        "{:#}",
        write_ply(&splat, &line_of_gaussians(2)).unwrap_err()
    );
    assert!(err.contains("standard 3DGS PLY only"), "{err}");
    assert!(!splat.exists());
}

// ---------------------------------------------------------------------------------------
// Working with a fused scene

fn synth_tiny(dir: &Path) {
    ok(&[
        "synth",
        "--preset",
        "tiny",
        "--out",
        s(dir),
        "--views",
        "3",
        "--test-views",
        "0",
        "--width",
        "48",
        "--height",
        "32",
    ]);
}

/// `fuse` of the synth scene into `fused`, drawing its views into `views`.
fn fuse_with_render_views(d: &Path, fused: &Path, views: &Path) {
    ok(&[
        "fuse",
        "--scene",
        s(&d.join("scene.ply")),
        "--cameras",
        s(&d.join("cameras.json")),
        "--labels",
        s(&d.join("labels")),
        "--out",
        s(fused),
        "--render-views",
        s(views),
    ]);
}

/// `render --semantics` of the fused scene into `rendered` writes exactly the files `fuse
/// --render-views` wrote into `views`.
fn check_render_semantics_matches_fuse_views(d: &Path, fused: &Path, views: &Path) {
    let rendered = d.join("rendered");
    ok(&[
        "render",
        "--scene",
        s(fused),
        "--cameras",
        s(&d.join("cameras.json")),
        "--semantics",
        "--out",
        s(&rendered),
    ]);
    let mut compared = 0;
    for entry in std::fs::read_dir(views).unwrap() {
        let name = entry.unwrap().file_name();
        // Both folders are marked as a render's (they may be rendered into again).
        if name == ".semsplat-render" {
            assert!(rendered.join(&name).is_file());
            continue;
        }
        let want = std::fs::read(views.join(&name)).unwrap();
        let got = std::fs::read(rendered.join(&name)).unwrap();
        assert!(
            want == got,
            "{name:?} differs between fuse --render-views and render"
        );
        compared += 1;
    }
    assert_eq!(compared, 6, "3 views x (labels, palette)");
}

/// `fuse --extract WALL` and `--remove Wall` on the fused scene (class ids `ids`) keep
/// exactly the walls and exactly the rest.
fn check_extract_and_remove_select_by_class_name(d: &Path, fused: &Path, ids: &[i32]) {
    let wall = 1;
    let walls = ids.iter().filter(|&&c| c == wall).count();
    assert!(walls > 0 && walls < ids.len());
    let (only, without) = (d.join("wall.ply"), d.join("no_wall.ply"));
    ok(&[
        "fuse",
        "--scene",
        s(fused),
        "--extract",
        "WALL",
        "--out",
        s(&only),
    ]);
    ok(&[
        "fuse",
        "--scene",
        s(fused),
        "--remove",
        "Wall",
        "--out",
        s(&without),
    ]);
    let only = read_ply(&only).unwrap().class_ids.unwrap();
    let without = read_ply(&without).unwrap().class_ids.unwrap();
    assert_eq!(only.len(), walls);
    assert!(only.iter().all(|&c| c == wall));
    assert_eq!(without.len(), ids.len() - walls);
    assert!(without.iter().all(|&c| c != wall));
}

/// A fused PLY (class, no logits): `render --semantics` draws the same labels `fuse
/// --render-views` drew from it, and `fuse --extract/--remove` select by its class without
/// re-fusing, the class named in any case.
#[test]
fn fused_scene_renders_its_classes_and_selects_without_refusing() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    synth_tiny(d);
    let (fused, views) = (d.join("fused.ply"), d.join("views"));
    fuse_with_render_views(d, &fused, &views);
    let g = read_ply(&fused).unwrap();
    assert!(g.semantics.is_none() && g.class_ids.is_some());
    check_render_semantics_matches_fuse_views(d, &fused, &views);

    let ids = g.class_ids.clone().unwrap();
    check_extract_and_remove_select_by_class_name(d, &fused, &ids);
    // Outputs that need the evidence matrix are refused in this mode, not skipped;
    // --render-views without sending the user after --cameras first.
    let (membership, views) = (d.join("m.npy"), d.join("v"));
    for (option, path) in [
        ("--save-membership", &membership),
        ("--render-views", &views),
    ] {
        let err = fails(&[
            "fuse",
            "--scene",
            s(&fused),
            "--extract",
            "wall",
            "--out",
            s(&d.join("x.ply")),
            option,
            s(path),
        ]);
        assert!(
            err.contains("need --labels or --contrib"),
            "{option}: {err}"
        );
    }
}

/// INRIA's input.ply seeds Gaussians as `create_from_pcd` does: scale = sqrt of the mean
/// squared distance to the 3 nearest neighbours (checked against brute force in f64),
/// opacity 0.1, identity rotation, colour as DC.
#[test]
fn point_cloud_seeds_gaussians_like_inria() {
    let mut rng = Rng::new(21);
    let n = 300;
    let points: Vec<[f32; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|_| rng.range_f64(-2.0, 2.0) as f32))
        .collect();
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    .into_bytes();
    for (i, p) in points.iter().enumerate() {
        for v in p.iter().chain(&[0.0; 3]) {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&[(i % 256) as u8, 128, 255]);
    }
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("input.ply");
    std::fs::write(&path, bytes).unwrap();
    let g = read_scene_or_point_cloud(&path).unwrap();
    assert_eq!(g.len(), n);
    for i in 0..n {
        let mut d2: Vec<f64> = (0..n)
            .filter(|&j| j != i)
            .map(|j| {
                (0..3)
                    .map(|a| (points[i][a] as f64 - points[j][a] as f64).powi(2))
                    .sum()
            })
            .collect();
        d2.sort_by(f64::total_cmp);
        let want = (d2[..3].iter().sum::<f64>() / 3.0).sqrt().ln();
        for a in 0..3 {
            assert!((g.log_scales[i][a] as f64 - want).abs() < 1e-5, "point {i}");
        }
        assert_eq!(g.means[i], points[i]);
        assert!((sigmoid(g.opacity_logits[i] as f64) - 0.1).abs() < 1e-6);
        assert_eq!(g.quats[i], [1.0, 0.0, 0.0, 0.0]);
        let rgb = [(i % 256) as f64 / 255.0, 128.0 / 255.0, 1.0];
        for (c, v) in rgb.iter().enumerate() {
            assert!((g.sh[i * 3 + c] as f64 - (v - 0.5) / SH_C0).abs() < 1e-5);
        }
    }
    // Everywhere else a point cloud is refused as such.
    let err = format!("{:#}", read_scene(&path).unwrap_err());
    assert!(
        err.contains("point cloud") && err.contains("--init"),
        "{err}"
    );
}
