//! The training losses and Adam on the GPU against plain f64 CPU implementations written
//! here (direct 11x11 windows, the SSIM gradient through l * cs, scatter instead of the
//! kernels' transposed blur), and the CPU losses against central finite differences.
//!
//! Tolerances come from float32: values are means of f32 terms summed in a tree, good to a
//! few ulps (seen: <= 1.7e-7 relative; allowed 2e-6). Gradients are compared relative to
//! their largest entry, because entries near zero carry the absolute f32 error of the
//! large ones (the SSIM moments cancel: sigma^2 = E[x^2] - E[x]^2 loses bits; seen: <= 3.2e-7
//! of the max for L1 + SSIM, 1.9e-7 for CE, 2.5e-6 for entropy added onto an f32
//! gradient; allowed 2e-5).

mod common;

use common::{check_validation, gpu};
use semsplat::gpu::{Buffer, Gpu, Recorder};
use semsplat::render::SemanticMode;
use semsplat::train::adam::{record_adam, AdamMoments, AdamStep, AdamTensor, ExponentialLr};
use semsplat::train::loss::{entropy_weight, ImageLoss, LossValues, SemanticTerm, IGNORE_LABEL};
use semsplat::util::Rng;

/// Relative error allowed on logged values (means of f32 terms).
const VALUE_TOL: f64 = 2e-6;
/// Error allowed on a gradient entry, relative to the gradient's largest entry.
const GRAD_TOL: f64 = 2e-5;

// ---------------------------------------------------------------------------------------
// CPU references (f64)

/// The 3DGS SSIM window as an 11 x 11 table: outer product of a normalized gaussian.
fn window() -> [[f64; 11]; 11] {
    let g: Vec<f64> = (0..11)
        .map(|k| (-((k as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let s: f64 = g.iter().sum();
    let mut w = [[0.0; 11]; 11];
    for (i, row) in w.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = g[i] * g[j] / (s * s);
        }
    }
    w
}

const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// Local statistics of x and y at every pixel and channel: means, variances, covariance.
struct Stats {
    mx: Vec<f64>,
    my: Vec<f64>,
    vx: Vec<f64>,
    vy: Vec<f64>,
    cxy: Vec<f64>,
}

/// The window's taps around pixel (px, py) of channel c that fall inside the image (zero
/// padding 5): (index into the [H, W, 3] image, weight).
fn window_taps(
    win: &[[f64; 11]; 11],
    px: usize,
    py: usize,
    c: usize,
    w: usize,
    h: usize,
) -> impl Iterator<Item = (usize, f64)> + '_ {
    win.iter().enumerate().flat_map(move |(dy, row)| {
        row.iter().enumerate().filter_map(move |(dx, &wt)| {
            let (qx, qy) = (px as i64 + dx as i64 - 5, py as i64 + dy as i64 - 5);
            (qx >= 0 && qy >= 0 && qx < w as i64 && qy < h as i64)
                .then(|| ((qy as usize * w + qx as usize) * 3 + c, wt))
        })
    })
}

/// conv2d with the window, zero padding 5, per channel (as torch's F.conv2d, groups = 3).
fn stats(x: &[f64], y: &[f64], w: usize, h: usize) -> Stats {
    let win = window();
    let n = w * h * 3;
    let mut s = Stats {
        mx: vec![0.0; n],
        my: vec![0.0; n],
        vx: vec![0.0; n],
        vy: vec![0.0; n],
        cxy: vec![0.0; n],
    };
    for py in 0..h {
        for px in 0..w {
            for c in 0..3 {
                let (mut a, mut b, mut aa, mut bb, mut ab) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for (i, wt) in window_taps(&win, px, py, c, w, h) {
                    a += wt * x[i];
                    b += wt * y[i];
                    aa += wt * x[i] * x[i];
                    bb += wt * y[i] * y[i];
                    ab += wt * x[i] * y[i];
                }
                let o = (py * w + px) * 3 + c;
                s.mx[o] = a;
                s.my[o] = b;
                s.vx[o] = aa - a * a;
                s.vy[o] = bb - b * b;
                s.cxy[o] = ab - a * b;
            }
        }
    }
    s
}

/// (L_rgb, mean |x - y|, mean SSIM, mean (x - y)^2).
fn rgb_loss_cpu(x: &[f64], y: &[f64], w: usize, h: usize) -> (f64, f64, f64, f64) {
    let s = stats(x, y, w, h);
    let n = x.len() as f64;
    let mut ssim = 0.0;
    for o in 0..x.len() {
        let l = (2.0 * s.mx[o] * s.my[o] + C1) / (s.mx[o].powi(2) + s.my[o].powi(2) + C1);
        let cs = (2.0 * s.cxy[o] + C2) / (s.vx[o] + s.vy[o] + C2);
        ssim += l * cs;
    }
    let l1 = x.iter().zip(y).map(|(a, b)| (a - b).abs()).sum::<f64>() / n;
    let mse = x.iter().zip(y).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / n;
    let ssim = ssim / n;
    (0.8 * l1 + 0.2 * (1.0 - ssim), l1, ssim, mse)
}

/// dL_rgb/dx: SSIM = l * cs, each output pixel scatters into the inputs of its window.
fn rgb_grad_cpu(x: &[f64], y: &[f64], w: usize, h: usize) -> Vec<f64> {
    let s = stats(x, y, w, h);
    let win = window();
    let n = x.len() as f64;
    let mut g: Vec<f64> = x
        .iter()
        .zip(y)
        .map(|(a, b)| {
            0.8 / n
                * if a > b {
                    1.0
                } else if a < b {
                    -1.0
                } else {
                    0.0
                }
        })
        .collect();
    for py in 0..h {
        for px in 0..w {
            for c in 0..3 {
                let o = (py * w + px) * 3 + c;
                let (mx, my) = (s.mx[o], s.my[o]);
                let (l_num, l_den) = (2.0 * mx * my + C1, mx * mx + my * my + C1);
                let (cs_num, cs_den) = (2.0 * s.cxy[o] + C2, s.vx[o] + s.vy[o] + C2);
                let (l, cs) = (l_num / l_den, cs_num / cs_den);
                let dl_dmx = (2.0 * my * l_den - l_num * 2.0 * mx) / (l_den * l_den);
                let dcs_dvx = -cs_num / (cs_den * cs_den);
                let dcs_dcxy = 2.0 / cs_den;
                let up = -0.2 / n; // dL/dSSIM(o)
                for (q, wt) in window_taps(&win, px, py, c, w, h) {
                    // d mx/dx_q = wt, d vx/dx_q = 2 wt (x_q - mx), d cxy/dx_q = wt (y_q - my).
                    let dssim = dl_dmx * wt * cs
                        + l * (dcs_dvx * 2.0 * wt * (x[q] - mx) + dcs_dcxy * wt * (y[q] - my));
                    g[q] += up * dssim;
                }
            }
        }
    }
    g
}

/// Mean CE over labeled pixels (labels < c) and its gradient times `lambda`.
fn ce_cpu(
    sem: &[f64],
    labels: &[u32],
    c: usize,
    mode: SemanticMode,
    lambda: f64,
) -> (f64, usize, Vec<f64>) {
    let labeled = labels.iter().filter(|&&l| (l as usize) < c).count();
    let mut loss = 0.0;
    let mut grad = vec![0.0; sem.len()];
    if labeled == 0 {
        return (0.0, 0, grad);
    }
    let scale = lambda / labeled as f64;
    for (p, &label) in labels.iter().enumerate() {
        if label as usize >= c {
            continue;
        }
        let s = &sem[p * c..(p + 1) * c];
        let l = label as usize;
        match mode {
            SemanticMode::RawLogits => {
                let z: f64 = s.iter().map(|v| v.exp()).sum();
                loss += z.ln() - s[l];
                for k in 0..c {
                    grad[p * c + k] = scale * (s[k].exp() / z - if k == l { 1.0 } else { 0.0 });
                }
            }
            SemanticMode::Softmax => {
                loss -= s[l].max(1e-6).ln();
                if s[l] > 1e-6 {
                    grad[p * c + l] = -scale / s[l];
                }
            }
        }
    }
    (loss / labeled as f64, labeled, grad)
}

/// Mean entropy of softmax(logits_i) and its gradient (not yet scaled by lambda).
fn entropy_cpu(logits: &[f64], c: usize) -> (f64, Vec<f64>) {
    let n = logits.len() / c;
    let mut total = 0.0;
    let mut grad = vec![0.0; logits.len()];
    for i in 0..n {
        let s = &logits[i * c..(i + 1) * c];
        let z: f64 = s.iter().map(|v| v.exp()).sum();
        let p: Vec<f64> = s.iter().map(|v| v.exp() / z).collect();
        let h: f64 = -p.iter().map(|q| q * q.ln()).sum::<f64>();
        total += h;
        // dH/ds_k = sum_j dH/dp_j dp_j/ds_k with dH/dp_j = -(ln p_j + 1).
        for k in 0..c {
            grad[i * c + k] = (0..c)
                .map(|j| {
                    let dp = p[j] * (if j == k { 1.0 } else { 0.0 } - p[k]);
                    -(p[j].ln() + 1.0) * dp
                })
                .sum::<f64>()
                / n as f64;
        }
    }
    (total / n as f64, grad)
}

/// Central difference of `f` in coordinate `i` of `x`.
fn central_difference(x: &[f64], i: usize, step: f64, f: impl Fn(&[f64]) -> f64) -> f64 {
    let mut v = x.to_vec();
    v[i] = x[i] + step;
    let plus = f(&v);
    v[i] = x[i] - step;
    let minus = f(&v);
    (plus - minus) / (2.0 * step)
}

// ---------------------------------------------------------------------------------------
// Helpers

fn uniform(rng: &mut Rng, n: usize, lo: f64, hi: f64) -> Vec<f32> {
    (0..n).map(|_| rng.range_f64(lo, hi) as f32).collect()
}

fn widen(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x as f64).collect()
}

fn assert_value(what: &str, got: f32, want: f64) {
    let err = (got as f64 - want).abs();
    assert!(
        err <= VALUE_TOL * want.abs().max(1e-30),
        "{what}: got {got}, want {want} (relative error {:e})",
        err / want.abs()
    );
}

/// Every entry within GRAD_TOL of the largest |want|; returns that largest relative error.
fn assert_grad(what: &str, got: &[f32], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0, "{what}: the reference gradient is zero");
    let (mut worst, mut at) = (0.0, 0);
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        let e = (g as f64 - w).abs() / scale;
        if e > worst {
            (worst, at) = (e, i);
        }
    }
    assert!(
        worst <= GRAD_TOL,
        "{what}: entry {at} is {} but should be {} (error {worst:e} of the max {scale:e})",
        got[at],
        want[at]
    );
    worst
}

fn zeros(gpu: &Gpu, name: &str, floats: usize) -> Buffer {
    gpu.buffer_from(name, &vec![0f32; floats]).unwrap()
}

/// Runs the RGB loss once; returns the values and v_rgb.
fn gpu_rgb_loss(x: &[f32], y: &[f32], w: u32, h: u32) -> (LossValues, Vec<f32>) {
    let gpu = gpu();
    let loss = ImageLoss::new(gpu, w, h, 0).unwrap();
    let rgb = gpu.buffer_from("rgb", x).unwrap();
    let target = gpu.buffer_from("target", y).unwrap();
    // Garbage in v_rgb: it must be overwritten.
    let v_rgb = gpu.buffer_from("v_rgb", &vec![7f32; x.len()]).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    loss.record(&mut rec, &rgb, &target, &v_rgb, None).unwrap();
    rec.submit_and_wait().unwrap();
    (loss.read_values().unwrap(), gpu.read(&v_rgb).unwrap())
}

/// A rendered-looking image and a target that resembles it (SSIM well above 0) with a
/// flat patch (near-zero variance, where the moments cancel most).
fn image_pair(w: usize, h: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Rng::new(seed);
    let mut x = uniform(&mut rng, w * h * 3, 0.0, 1.0);
    for py in 0..h.min(4) {
        for px in 0..w.min(4) {
            for c in 0..3 {
                x[(py * w + px) * 3 + c] = 0.25 + 1e-3 * c as f32;
            }
        }
    }
    let y = x
        .iter()
        .map(|&v| (v + 0.2 * rng.normal() as f32).clamp(0.0, 1.0))
        .collect();
    (x, y)
}

fn check_rgb_loss(w: usize, h: usize, seed: u64) {
    let (x, y) = image_pair(w, h, seed);
    let (got, v_rgb) = gpu_rgb_loss(&x, &y, w as u32, h as u32);
    let (xd, yd) = (widen(&x), widen(&y));
    let (loss, l1, ssim, mse) = rgb_loss_cpu(&xd, &yd, w, h);
    assert_value("l1", got.l1, l1);
    assert_value("ssim", got.ssim, ssim);
    assert_value("mse", got.mse, mse);
    assert_value("rgb loss", got.rgb_loss(), loss);
    assert!(
        ssim > 0.3 && ssim < 0.99,
        "ssim {ssim}: the test needs a middling SSIM"
    );

    let want = rgb_grad_cpu(&xd, &yd, w, h);
    let worst = assert_grad(&format!("v_rgb {w}x{h}"), &v_rgb, &want);
    eprintln!("{w}x{h}: worst v_rgb error {worst:e} of the max");

    // The CPU gradient against finite differences of the CPU loss, and the GPU's too.
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut rng = Rng::new(seed ^ 0xfd);
    let mut checked = 0;
    while checked < 40 {
        let i = rng.below(xd.len() as u64) as usize;
        // |x| is not differentiable at x = y.
        if (xd[i] - yd[i]).abs() < 1e-4 {
            continue;
        }
        let fd = central_difference(&xd, i, 1e-6, |v| rgb_loss_cpu(v, &yd, w, h).0);
        assert!(
            (want[i] - fd).abs() <= 1e-6 * scale,
            "cpu gradient {i}: {} vs finite difference {fd}",
            want[i]
        );
        assert!(
            (v_rgb[i] as f64 - fd).abs() <= GRAD_TOL * scale,
            "gpu gradient {i}: {} vs finite difference {fd}",
            v_rgb[i]
        );
        checked += 1;
    }
}

// ---------------------------------------------------------------------------------------
// Tests

#[test]
fn rgb_loss_and_gradient_match_cpu_on_an_odd_image() {
    check_rgb_loss(37, 23, 1);
    check_validation(gpu());
}

#[test]
fn rgb_loss_and_gradient_match_cpu_on_images_narrower_than_the_window() {
    check_rgb_loss(9, 30, 2);
    check_rgb_loss(40, 6, 3);
    check_rgb_loss(5, 4, 4);
    check_validation(gpu());
}

#[test]
fn identical_images_have_zero_rgb_loss_and_gradient() {
    let (x, _) = image_pair(20, 17, 5);
    let (got, v_rgb) = gpu_rgb_loss(&x, &x, 20, 17);
    assert_eq!(got.l1, 0.0);
    assert_eq!(got.mse, 0.0);
    assert!((got.ssim - 1.0).abs() < 1e-6, "ssim {}", got.ssim);
    let worst = v_rgb.iter().fold(0f32, |m, v| m.max(v.abs())) as f64;
    // At x = y SSIM is at its maximum and sign(0) = 0: the gradient vanishes up to f32
    // rounding; compare with the L1 term's entries on any mismatched pixel.
    let l1_entry = 0.8 / (20.0 * 17.0 * 3.0);
    eprintln!("identical images: largest |v_rgb| {worst:e}");
    assert!(worst < GRAD_TOL * l1_entry, "largest |v_rgb| {worst}");
    check_validation(gpu());
}

/// Semantic maps of `c` channels for `w x h` pixels with ignored and out-of-range labels.
fn semantic_case(
    w: usize,
    h: usize,
    c: usize,
    mode: SemanticMode,
    seed: u64,
) -> (Vec<f32>, Vec<u32>) {
    let mut rng = Rng::new(seed);
    let p = w * h;
    let labels: Vec<u32> = (0..p)
        .map(|i| match i % 17 {
            3 => IGNORE_LABEL,
            11 => c as u32 + 2, // out of range: left out too
            _ if rng.bool(0.1) => IGNORE_LABEL,
            _ => rng.below(c as u64) as u32,
        })
        .collect();
    let sem = match mode {
        SemanticMode::RawLogits => (0..p * c).map(|_| (3.0 * rng.normal()) as f32).collect(),
        SemanticMode::Softmax => {
            let mut s = Vec::with_capacity(p * c);
            for i in 0..p {
                let raw: Vec<f64> = (0..c).map(|_| rng.range_f64(0.01, 1.0)).collect();
                let sum: f64 = raw.iter().sum();
                s.extend(raw.iter().map(|v| (v / sum) as f32));
                // Some labeled classes at or below the 1e-6 floor: clamped, zero gradient.
                let l = labels[i] as usize;
                if l < c && i % 7 == 0 {
                    s[i * c + l] = [0.0, 1e-8, -0.01][i % 3];
                }
            }
            s
        }
    };
    (sem, labels)
}

fn gpu_ce(
    sem: &[f32],
    labels: &[u32],
    w: u32,
    h: u32,
    c: u32,
    mode: SemanticMode,
    lambda: f32,
) -> (LossValues, Vec<f32>) {
    let gpu = gpu();
    let loss = ImageLoss::new(gpu, w, h, c).unwrap();
    let p = (w * h) as usize;
    let rgb = zeros(gpu, "rgb", p * 3);
    let v_rgb = zeros(gpu, "v_rgb", p * 3);
    let sem_norm = gpu.buffer_from("sem_norm", sem).unwrap();
    let labels = gpu.buffer_from("labels", labels).unwrap();
    let v_sem_norm = gpu
        .buffer_from("v_sem_norm", &vec![5f32; sem.len()])
        .unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    let term = SemanticTerm {
        sem_norm: &sem_norm,
        labels: &labels,
        mode,
        lambda,
        v_sem_norm: &v_sem_norm,
    };
    loss.record(&mut rec, &rgb, &rgb, &v_rgb, Some(&term))
        .unwrap();
    rec.submit_and_wait().unwrap();
    (loss.read_values().unwrap(), gpu.read(&v_sem_norm).unwrap())
}

/// [`gpu_ce`] through [`ImageLoss::semantic`]'s `record_semantic`: no target image.
fn gpu_ce_alone(sem: &[f32], labels: &[u32], w: u32, h: u32, c: u32) -> (LossValues, Vec<f32>) {
    let gpu = gpu();
    let loss = ImageLoss::semantic(gpu, w, h, c).unwrap();
    let sem_norm = gpu.buffer_from("sem_norm", sem).unwrap();
    let labels = gpu.buffer_from("labels", labels).unwrap();
    let v_sem_norm = zeros(gpu, "v_sem_norm", sem.len());
    let mut rec = Recorder::new(gpu).unwrap();
    let term = SemanticTerm {
        sem_norm: &sem_norm,
        labels: &labels,
        mode: SemanticMode::RawLogits,
        lambda: 0.7,
        v_sem_norm: &v_sem_norm,
    };
    loss.record_semantic(&mut rec, &term).unwrap();
    rec.submit_and_wait().unwrap();
    (loss.read_values().unwrap(), gpu.read(&v_sem_norm).unwrap())
}

/// The semantic term recorded alone (`train --semantics-only` without images) gives the
/// cross-entropy and its gradient of the full record, bit for bit, and zeros for the
/// photometric values it leaves out; a photometric record on its scratch is refused.
#[test]
fn the_semantic_term_alone_matches_the_full_record() {
    let (w, h, c) = (29u32, 19u32, 5u32);
    let (sem, labels) = semantic_case(
        w as usize,
        h as usize,
        c as usize,
        SemanticMode::RawLogits,
        3,
    );
    let (full, full_grad) = gpu_ce(&sem, &labels, w, h, c, SemanticMode::RawLogits, 0.7);
    let (alone, alone_grad) = gpu_ce_alone(&sem, &labels, w, h, c);
    assert_eq!(alone.ce.to_bits(), full.ce.to_bits());
    assert_eq!(alone.labeled_pixels, full.labeled_pixels);
    assert_eq!(alone_grad, full_grad);
    assert_eq!((alone.l1, alone.ssim, alone.mse), (0.0, 0.0, 0.0));
    // The full record's all-zero render against itself: a perfect SSIM, not the 0 above.
    assert!(full.ssim > 0.99, "{}", full.ssim);

    let gpu = gpu();
    let loss = ImageLoss::semantic(gpu, w, h, c).unwrap();
    let rgb = zeros(gpu, "rgb", (w * h * 3) as usize);
    let mut rec = Recorder::new(gpu).unwrap();
    let err = loss.record(&mut rec, &rgb, &rgb, &rgb, None).unwrap_err();
    assert!(err.to_string().contains("semantic term alone"), "{err}");
    assert!(ImageLoss::semantic(gpu, w, h, 0).is_err());
}

fn check_ce(mode: SemanticMode, seed: u64) {
    let (w, h, c) = (29, 19, 7);
    let (sem, labels) = semantic_case(w, h, c, mode, seed);
    let lambda = 0.7;
    let (got, grad) = gpu_ce(&sem, &labels, w as u32, h as u32, c as u32, mode, lambda);
    let semd = widen(&sem);
    let (ce, labeled, want) = ce_cpu(&semd, &labels, c, mode, lambda as f64);
    assert_eq!(got.labeled_pixels as usize, labeled);
    assert!(labeled > w * h / 2 && labeled < w * h);
    assert_value("ce", got.ce, ce);
    assert_grad("v_sem_norm", &grad, &want);
    // Ignored pixels: exactly zero.
    for (p, &l) in labels.iter().enumerate() {
        if l as usize >= c {
            assert!(
                grad[p * c..(p + 1) * c].iter().all(|&g| g == 0.0),
                "pixel {p}"
            );
        }
    }
    // The CPU gradient against finite differences of the CPU loss.
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut rng = Rng::new(seed);
    for _ in 0..40 {
        let i = rng.below(semd.len() as u64) as usize;
        let p = semd[i];
        // The softmax mode's floor is a kink.
        if mode == SemanticMode::Softmax && (p - 1e-6).abs() < 1e-5 {
            continue;
        }
        let fd = central_difference(&semd, i, 1e-7, |v| {
            lambda as f64 * ce_cpu(v, &labels, c, mode, 1.0).0
        });
        assert!(
            (want[i] - fd).abs() <= 1e-5 * scale,
            "cpu gradient {i}: {} vs finite difference {fd}",
            want[i]
        );
    }
}

#[test]
fn cross_entropy_on_raw_logits_matches_cpu() {
    check_ce(SemanticMode::RawLogits, 10);
    check_validation(gpu());
}

#[test]
fn cross_entropy_on_probabilities_matches_cpu() {
    check_ce(SemanticMode::Softmax, 11);
    check_validation(gpu());
}

#[test]
fn cross_entropy_without_labeled_pixels_is_zero() {
    let (w, h, c) = (13, 11, 4);
    for mode in [SemanticMode::RawLogits, SemanticMode::Softmax] {
        let (sem, _) = semantic_case(w, h, c, mode, 12);
        let labels = vec![IGNORE_LABEL; w * h];
        let (got, grad) = gpu_ce(&sem, &labels, w as u32, h as u32, c as u32, mode, 1.0);
        assert_eq!(got.labeled_pixels, 0);
        assert_eq!(got.ce, 0.0);
        assert!(grad.iter().all(|&g| g == 0.0));
    }
    check_validation(gpu());
}

fn gpu_entropy(logits: &[f32], grad_in: &[f32], c: u32, lambda: f32) -> (LossValues, Vec<f32>) {
    let gpu = gpu();
    let n = (logits.len() / c as usize) as u32;
    let loss = ImageLoss::new(gpu, 4, 4, c).unwrap();
    let logits_buf = gpu.buffer_from("logits", logits).unwrap();
    let grad = gpu.buffer_from("grad_logits", grad_in).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    loss.record_entropy(&mut rec, &logits_buf, n, lambda, &grad)
        .unwrap();
    rec.submit_and_wait().unwrap();
    (loss.read_values().unwrap(), gpu.read(&grad).unwrap())
}

/// Logits from flat to peaked, so entropies span (0, log C].
fn entropy_logits(n: usize, c: usize, seed: u64) -> Vec<f32> {
    let mut rng = Rng::new(seed);
    (0..n)
        .flat_map(|i| {
            let spread = [0.01, 0.5, 2.0, 8.0][i % 4];
            (0..c)
                .map(|_| (spread * rng.normal()) as f32)
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn entropy_value_and_accumulated_gradient_match_cpu() {
    let (n, c) = (1000, 6);
    let logits = entropy_logits(n, c, 20);
    let mut rng = Rng::new(21);
    let grad_in = uniform(&mut rng, n * c, -1e-3, 1e-3);
    let lambda = 0.05;
    let (got, grad) = gpu_entropy(&logits, &grad_in, c as u32, lambda);
    let ld = widen(&logits);
    let (h, dh) = entropy_cpu(&ld, c);
    assert_value("entropy", got.entropy, h);
    assert!(h > 0.0 && h < (c as f64).ln());
    // Compare what was added, so the check is not drowned by grad_in.
    let added: Vec<f32> = grad.iter().zip(&grad_in).map(|(g, g0)| g - g0).collect();
    let want: Vec<f64> = dh.iter().map(|d| lambda as f64 * d).collect();
    // The addition rounds at the ulp of grad_in (1e-3 * 6e-8), 1e-6 of the ~5e-5 entries.
    assert_grad("added grad_logits", &added, &want);
    let mut rng = Rng::new(22);
    for _ in 0..40 {
        let i = rng.below(ld.len() as u64) as usize;
        let fd = central_difference(&ld, i, 1e-6, |v| lambda as f64 * entropy_cpu(v, c).0);
        let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(
            (want[i] - fd).abs() <= 1e-6 * scale,
            "cpu gradient {i}: {} vs finite difference {fd}",
            want[i]
        );
    }
    check_validation(gpu());
}

#[test]
fn entropy_covers_more_gaussians_than_its_workgroups() {
    // Past 4096 workgroups x 256 invocations each invocation takes several Gaussians.
    let (n, c) = (4096 * 256 + 3_001, 3);
    let logits = entropy_logits(n, c, 23);
    let (got, grad) = gpu_entropy(&logits, &vec![0.0; n * c], c as u32, 2.0);
    let (h, dh) = entropy_cpu(&widen(&logits), c);
    assert_value("entropy", got.entropy, h);
    let want: Vec<f64> = dh.iter().map(|d| 2.0 * d).collect();
    assert_grad("grad_logits", &grad, &want);
    check_validation(gpu());
}

/// Equal logits (a uniform start, at 0 or any other value) are the entropy's maximum: its
/// gradient there is exactly 0, not rounding that Adam would scale into full steps.
#[test]
fn entropy_gradient_of_equal_logits_is_exactly_zero() {
    let c = 7;
    let logits: Vec<f32> = [0.0f32, 1.0, -3.7, 123.456]
        .iter()
        .flat_map(|&v| vec![v; c])
        .collect();
    let (got, grad) = gpu_entropy(&logits, &vec![0.0; logits.len()], c as u32, 0.5);
    assert!(grad.iter().all(|&g| g == 0.0), "{grad:?}");
    assert_value("entropy", got.entropy, (c as f64).ln());
    check_validation(gpu());
}

#[test]
fn entropy_weight_warms_up_linearly() {
    assert_eq!(entropy_weight(0.01, 0, 5000), 0.0);
    assert!((entropy_weight(0.01, 2500, 5000) - 0.005).abs() < 1e-9);
    assert_eq!(entropy_weight(0.01, 5000, 5000), 0.01);
    assert_eq!(entropy_weight(0.01, 9000, 5000), 0.01);
    assert_eq!(entropy_weight(0.01, 0, 0), 0.01);
}

/// One iteration's losses in one submission, then one read; twice, bit for bit.
#[test]
fn one_submission_gives_every_value_deterministically() {
    let gpu = gpu();
    let (w, h, c) = (33usize, 21usize, 5usize);
    let (x, y) = image_pair(w, h, 30);
    let (sem, labels) = semantic_case(w, h, c, SemanticMode::RawLogits, 31);
    let n = 700;
    let logits = entropy_logits(n, c, 32);
    let loss = ImageLoss::new(gpu, w as u32, h as u32, c as u32).unwrap();
    let rgb = gpu.buffer_from("rgb", &x).unwrap();
    let target = gpu.buffer_from("target", &y).unwrap();
    let v_rgb = zeros(gpu, "v_rgb", x.len());
    let sem_norm = gpu.buffer_from("sem_norm", &sem).unwrap();
    let labels_buf = gpu.buffer_from("labels", &labels).unwrap();
    let v_sem_norm = zeros(gpu, "v_sem_norm", sem.len());
    let logits_buf = gpu.buffer_from("logits", &logits).unwrap();
    let grad_logits = zeros(gpu, "grad_logits", logits.len());
    let run = || {
        let mut rec = Recorder::new(gpu).unwrap();
        rec.fill(&grad_logits, 0, grad_logits.size(), 0);
        let term = SemanticTerm {
            sem_norm: &sem_norm,
            labels: &labels_buf,
            mode: SemanticMode::RawLogits,
            lambda: 1.0,
            v_sem_norm: &v_sem_norm,
        };
        loss.record(&mut rec, &rgb, &target, &v_rgb, Some(&term))
            .unwrap();
        loss.record_entropy(&mut rec, &logits_buf, n as u32, 0.01, &grad_logits)
            .unwrap();
        rec.submit_and_wait().unwrap();
        let grads: Vec<Vec<f32>> = [&v_rgb, &v_sem_norm, &grad_logits]
            .iter()
            .map(|b| gpu.read(b).unwrap())
            .collect();
        (loss.read_values().unwrap(), grads)
    };
    let (values, grads) = run();
    let (_, l1, ssim, mse) = rgb_loss_cpu(&widen(&x), &widen(&y), w, h);
    let (ce, labeled, _) = ce_cpu(&widen(&sem), &labels, c, SemanticMode::RawLogits, 1.0);
    let (ent, _) = entropy_cpu(&widen(&logits), c);
    assert_value("l1", values.l1, l1);
    assert_value("ssim", values.ssim, ssim);
    assert_value("mse", values.mse, mse);
    assert_value("ce", values.ce, ce);
    assert_eq!(values.labeled_pixels as usize, labeled);
    assert_value("entropy", values.entropy, ent);
    assert!((values.psnr() as f64 - (-10.0 * mse.log10())).abs() < 1e-4);
    let (values2, grads2) = run();
    assert_eq!(values, values2);
    assert_eq!(grads, grads2);
    check_validation(gpu);
}

#[test]
fn loss_rejects_buffers_that_are_too_small() {
    let gpu = gpu();
    let loss = ImageLoss::new(gpu, 10, 10, 3).unwrap();
    let small = zeros(gpu, "small", 299);
    let rgb = zeros(gpu, "rgb", 300);
    let mut rec = Recorder::new(gpu).unwrap();
    assert!(loss.record(&mut rec, &small, &rgb, &rgb, None).is_err());
    let term = SemanticTerm {
        sem_norm: &rgb,
        labels: &small,
        mode: SemanticMode::RawLogits,
        lambda: 1.0,
        v_sem_norm: &small, // one float short of 100 pixels x 3 channels
    };
    assert!(loss
        .record(&mut rec, &rgb, &rgb, &rgb, Some(&term))
        .is_err());
    assert!(ImageLoss::new(gpu, 0, 10, 3).is_err());
    let no_sem = ImageLoss::new(gpu, 10, 10, 0).unwrap();
    assert!(no_sem
        .record_entropy(&mut rec, &rgb, 10, 1.0, &rgb)
        .is_err());
    drop(rec);
    check_validation(gpu);
}

/// torch.optim.Adam's update in f64.
struct CpuAdam {
    m: Vec<f64>,
    v: Vec<f64>,
    /// m over |g|: the size of the terms m sums, which bounds its f32 error.
    m_abs: Vec<f64>,
}

impl CpuAdam {
    fn step(&mut self, p: &mut [f64], g: &[f64], lr: f64, t: i32) {
        let (b1, b2, eps) = (0.9, 0.999, 1e-15);
        for i in 0..p.len() {
            self.m[i] = b1 * self.m[i] + (1.0 - b1) * g[i];
            self.m_abs[i] = b1 * self.m_abs[i] + (1.0 - b1) * g[i].abs();
            self.v[i] = b2 * self.v[i] + (1.0 - b2) * g[i] * g[i];
            let m_hat = self.m[i] / (1.0 - b1.powi(t));
            let v_hat = self.v[i] / (1.0 - b2.powi(t));
            p[i] -= lr * m_hat / (v_hat.sqrt() + eps);
        }
    }
}

#[test]
fn adam_matches_cpu_over_several_steps() {
    let gpu = gpu();
    let count = 1000; // not a multiple of 256
    let extra = 24; // past `count`: must stay untouched
    let mut rng = Rng::new(40);
    let p0 = uniform(&mut rng, count + extra, -2.0, 2.0);
    let param = gpu.buffer_from("param", &p0).unwrap();
    let grad = zeros(gpu, "grad", count + extra);
    let moments = AdamMoments::new(gpu, "param", (count + extra) as u32).unwrap();
    let mut cpu_p = widen(&p0[..count]);
    let mut cpu = CpuAdam {
        m: vec![0.0; count],
        v: vec![0.0; count],
        m_abs: vec![0.0; count],
    };
    let sched = ExponentialLr::positions(5.0, 6);
    for t in 1..=6u32 {
        // Gradients of mixed scale, some exactly zero (then m = v = 0: no step).
        let mut g: Vec<f32> = (0..count + extra)
            .map(|i| {
                let scale = [1e-6, 1e-3, 1.0, 0.0][i % 4];
                (scale * rng.normal()) as f32
            })
            .collect();
        g[count..].fill(1.0);
        gpu.upload(&grad, 0, &g).unwrap();
        let lr = sched.at(t - 1);
        let mut rec = Recorder::new(gpu).unwrap();
        let tensor = AdamTensor {
            param: &param,
            grad: &grad,
            exp_avg: &moments.exp_avg,
            exp_avg_sq: &moments.exp_avg_sq,
            count: count as u32,
        };
        record_adam(&mut rec, &tensor, AdamStep::new(lr, t)).unwrap();
        rec.submit_and_wait().unwrap();
        cpu.step(&mut cpu_p, &widen(&g[..count]), lr, t as i32);
    }
    let got: Vec<f32> = gpu.read(&param).unwrap();
    let m: Vec<f32> = gpu.read(&moments.exp_avg).unwrap();
    let v: Vec<f32> = gpu.read(&moments.exp_avg_sq).unwrap();
    assert_eq!(&got[count..], &p0[count..], "past count");
    assert!(m[count..].iter().chain(&v[count..]).all(|&x| x == 0.0));
    for i in 0..count {
        // Each step moves a parameter by about lr (8e-4 here) with an f32 error of a few
        // ulps of m / sqrt(v) times lr; the parameter itself rounds at 6e-8 of its size per
        // step. m sums terms of both signs: its error scales with the terms, not with m;
        // v sums positive terms.
        let tol = 1e-6 * cpu_p[i].abs().max(1.0);
        assert!(
            (got[i] as f64 - cpu_p[i]).abs() <= tol,
            "param {i}: {} vs {}",
            got[i],
            cpu_p[i]
        );
        assert!(
            (m[i] as f64 - cpu.m[i]).abs() <= 1e-6 * cpu.m_abs[i],
            "m {i}"
        );
        assert!((v[i] as f64 - cpu.v[i]).abs() <= 1e-6 * cpu.v[i], "v {i}");
        if i % 4 == 3 {
            assert_eq!(got[i], p0[i], "zero gradients leave param {i} alone");
        }
    }
    // The parameters did move (by about lr per step).
    let moved = (0..count)
        .filter(|&i| (got[i] - p0[i]).abs() > 1e-4)
        .count();
    assert!(moved > count / 2, "{moved} parameters moved");
    check_validation(gpu);
}

#[test]
fn position_schedule_follows_3dgs() {
    // 3DGS: position_lr_init 1.6e-4, final 1.6e-6, delay mult 0.01, 30k steps, scaled
    // by the scene extent.
    let s = ExponentialLr::positions(3.0, 30_000);
    let want = |step: f64| {
        let t = (step / 30_000.0).min(1.0);
        (4.8e-4f64.ln() * (1.0 - t) + 4.8e-6f64.ln() * t).exp()
    };
    for step in [0u32, 1, 100, 7_000, 15_000, 29_999, 30_000, 50_000] {
        let got = s.at(step);
        assert!(
            (got - want(step as f64)).abs() <= 1e-12 * want(step as f64),
            "step {step}: {got}"
        );
    }
    // Monotone decay.
    assert!((1..30_000).step_by(997).all(|k| s.at(k) < s.at(k - 1)));
    // With a delay: starts at delay_mult * lr_init, reaches the plain curve at delay_steps.
    let d = ExponentialLr {
        delay_steps: 1000,
        ..s
    };
    assert!((d.at(0) - 0.01 * want(0.0)).abs() < 1e-15);
    assert!((d.at(1000) - want(1000.0)).abs() < 1e-15);
    assert!(d.at(500) < want(500.0) && d.at(500) > 0.01 * want(500.0));
}
