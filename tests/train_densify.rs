//! Densify-and-prune on the GPU against a plain CPU implementation of 3DGS's rules (f64
//! where the rules compare scales and opacities, f32 for the average gradient as the GPU
//! divides it), and the split offsets against their distribution.

mod common;

use common::{check_validation, gpu};
use semsplat::gpu::{Buffer, Gpu, Recorder};
use semsplat::train::densify::{
    reset_opacity, Densifier, DensifyConfig, DensifyInputs, DensifyPlan, Role, OPACITY_RESET,
};
use semsplat::util::Rng;

/// SH coefficients x RGB and semantic channels of the test models.
const SH_WIDTH: usize = 12;
const CHANNELS: usize = 5;

/// A model on the host, structure-of-arrays as the GPU holds it.
#[derive(Clone, Default)]
struct Model {
    n: usize,
    means: Vec<f32>,
    log_scales: Vec<f32>,
    quats: Vec<f32>,
    opacity_logits: Vec<f32>,
    sh: Vec<f32>,
    logits: Vec<f32>,
    /// One Adam moment of SH (width 12) and one of the opacities (width 1).
    sh_m: Vec<f32>,
    opacity_v: Vec<f32>,
    grad_accum: Vec<f32>,
    grad_count: Vec<f32>,
}

/// Which branch a generated Gaussian is meant to take (data sit far from every threshold).
#[derive(Clone, Copy, PartialEq, Debug)]
enum Intent {
    Transparent,
    Large,
    Idle,
    Clone,
    Split,
    Unseen,
}

/// An accumulated gradient and its count for a Gaussian meant to take `intent`: idle ones
/// average below 0.00015, densified ones above 0.00025 (threshold 0.0002); some repeat an
/// earlier pair of `pairs`, for exact ties.
fn random_gradient(rng: &mut Rng, intent: Intent, pairs: &[(f32, f32)]) -> (f32, f32) {
    if intent == Intent::Unseen {
        (0.0, 0.0)
    } else if !pairs.is_empty() && rng.bool(0.1) {
        pairs[rng.below(pairs.len() as u64) as usize]
    } else {
        let count = 1 + rng.below(20) as u32;
        let avg = match intent {
            Intent::Idle => rng.range_f64(0.0, 0.00015),
            _ => rng.range_f64(0.00025, 0.003),
        };
        ((avg * count as f64) as f32, count as f32)
    }
}

fn random_model(n: usize, extent: f32, seed: u64) -> Model {
    let mut rng = Rng::new(seed);
    let mut m = Model {
        n,
        ..Model::default()
    };
    let ext = extent as f64;
    let intents = [
        Intent::Transparent,
        Intent::Large,
        Intent::Idle,
        Intent::Clone,
        Intent::Split,
        Intent::Unseen,
    ];
    let mut pairs: Vec<(f32, f32)> = Vec::new();
    for _ in 0..n {
        let intent = intents[rng.below(intents.len() as u64) as usize];
        for _ in 0..3 {
            m.means.push(rng.range_f64(-2.0, 2.0) as f32);
        }
        // Largest scale: clone <= 0.01 ext < split <= 0.1 ext < large.
        let max_scale = match intent {
            Intent::Clone => rng.range_f64(0.001, 0.008),
            Intent::Large => rng.range_f64(0.15, 0.4),
            _ if rng.bool(0.5) => rng.range_f64(0.012, 0.08),
            _ => rng.range_f64(0.001, 0.008),
        } * ext;
        let axis = rng.below(3);
        for a in 0..3 {
            let s = if a == axis {
                max_scale
            } else {
                max_scale * rng.range_f64(0.1, 0.9)
            };
            m.log_scales.push(s.ln() as f32);
        }
        for _ in 0..4 {
            m.quats.push(rng.range_f64(-1.0, 1.0) as f32);
        }
        // Opacity: 0.005 has logit -5.29.
        m.opacity_logits.push(match intent {
            Intent::Transparent => rng.range_f64(-9.0, -6.0),
            _ => rng.range_f64(-4.0, 4.0),
        } as f32);
        for _ in 0..SH_WIDTH {
            m.sh.push(rng.range_f64(-1.0, 1.0) as f32);
            m.sh_m.push(rng.range_f64(-1.0, 1.0) as f32);
        }
        for _ in 0..CHANNELS {
            m.logits.push(rng.range_f64(-3.0, 3.0) as f32);
        }
        m.opacity_v.push(rng.range_f64(0.0, 1.0) as f32);
        let (accum, count) = random_gradient(&mut rng, intent, &pairs);
        pairs.push((accum, count));
        m.grad_accum.push(accum);
        m.grad_count.push(count);
    }
    m
}

/// What an output slot holds (the same four kinds the GPU lays out).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Keep,
    Clone,
    Split0,
    Split1,
}

struct Expected {
    slots: Vec<(usize, Kind)>,
    pruned: u32,
    cloned: u32,
    split: u32,
    candidates: u32,
}

fn avg_grad(m: &Model, i: usize) -> f32 {
    if m.grad_count[i] > 0.0 {
        m.grad_accum[i] / m.grad_count[i]
    } else {
        0.0
    }
}

fn max_scale(m: &Model, i: usize) -> f64 {
    (0..3)
        .map(|a| (m.log_scales[3 * i + a] as f64).exp())
        .fold(f64::MIN, f64::max)
}

/// 3DGS's densify_and_prune, written plainly: prune the originals, pick candidates, keep
/// the top-k by average gradient (ties by index) under the cap, lay out in input order.
fn reference(m: &Model, c: &DensifyConfig) -> Expected {
    let ext = c.extent as f64;
    let pruned: Vec<bool> = (0..m.n)
        .map(|i| {
            let opacity = 1.0 / (1.0 + (-(m.opacity_logits[i] as f64)).exp());
            opacity < c.min_opacity as f64 || (c.prune_large && max_scale(m, i) > 0.1 * ext)
        })
        .collect();
    let survivors = pruned.iter().filter(|p| !**p).count();
    let mut candidates: Vec<usize> = (0..m.n)
        .filter(|&i| !pruned[i] && avg_grad(m, i) >= c.grad_threshold)
        .collect();
    let budget = (c.max_gaussians as usize).saturating_sub(survivors);
    let n_candidates = candidates.len();
    candidates.sort_by(|&a, &b| avg_grad(m, b).total_cmp(&avg_grad(m, a)).then(a.cmp(&b)));
    candidates.truncate(budget);
    let mut densified = vec![false; m.n];
    for &i in &candidates {
        densified[i] = true;
    }
    let mut e = Expected {
        slots: Vec::new(),
        pruned: (m.n - survivors) as u32,
        cloned: 0,
        split: 0,
        candidates: n_candidates as u32,
    };
    for i in 0..m.n {
        if pruned[i] {
            continue;
        }
        if !densified[i] {
            e.slots.push((i, Kind::Keep));
        } else if max_scale(m, i) <= c.percent_dense as f64 * ext {
            e.cloned += 1;
            e.slots.extend([(i, Kind::Keep), (i, Kind::Clone)]);
        } else {
            e.split += 1;
            e.slots.extend([(i, Kind::Split0), (i, Kind::Split1)]);
        }
    }
    e
}

/// pcg4d as documented in src/train/densify.rs (Jarzynski and Olano 2020).
fn pcg4d(mut v: [u32; 4]) -> [u32; 4] {
    for x in &mut v {
        *x = x.wrapping_mul(1664525).wrapping_add(1013904223);
    }
    let mix = |v: &mut [u32; 4]| {
        v[0] = v[0].wrapping_add(v[1].wrapping_mul(v[3]));
        v[1] = v[1].wrapping_add(v[2].wrapping_mul(v[0]));
        v[2] = v[2].wrapping_add(v[0].wrapping_mul(v[1]));
        v[3] = v[3].wrapping_add(v[1].wrapping_mul(v[2]));
    };
    mix(&mut v);
    for x in &mut v {
        *x ^= *x >> 16;
    }
    mix(&mut v);
    v
}

/// The documented split draw z of child `child` of Gaussian `index`, in f64.
fn split_normal(index: usize, child: u32, seed: u64) -> [f64; 3] {
    let h = pcg4d([index as u32, child, seed as u32, (seed >> 32) as u32]);
    let u = |w: u32| ((w >> 8) as f64 + 0.5) / 16_777_216.0;
    let pi = std::f64::consts::PI;
    let (r0, a0) = ((-2.0 * u(h[0]).ln()).sqrt(), pi * (2.0 * u(h[1]) - 1.0));
    let (r1, a1) = ((-2.0 * u(h[2]).ln()).sqrt(), pi * (2.0 * u(h[3]) - 1.0));
    [r0 * a0.cos(), r0 * a0.sin(), r1 * a1.cos()]
}

/// Rotation of the normalized quaternion (w, x, y z), row-major.
fn rotation(q: &[f32]) -> [[f64; 3]; 3] {
    let len = q.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
    let [w, x, y, z] = [0, 1, 2, 3].map(|k| q[k] as f64 / len);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The offset R(q) * (exp(log_scales) * z) of a split child, in f64.
fn split_offset(m: &Model, i: usize, child: u32, seed: u64) -> [f64; 3] {
    let r = rotation(&m.quats[4 * i..4 * i + 4]);
    let z = split_normal(i, child, seed);
    let s: Vec<f64> = (0..3)
        .map(|a| (m.log_scales[3 * i + a] as f64).exp() * z[a])
        .collect();
    [0, 1, 2].map(|row| (0..3).map(|col| r[row][col] * s[col]).sum())
}

/// The model on the GPU.
struct GpuModel {
    means: Buffer,
    log_scales: Buffer,
    quats: Buffer,
    opacity_logits: Buffer,
    sh: Buffer,
    logits: Buffer,
    sh_m: Buffer,
    opacity_v: Buffer,
    grad_accum: Buffer,
    grad_count: Buffer,
}

impl GpuModel {
    fn upload(gpu: &Gpu, m: &Model) -> GpuModel {
        let b = |name: &str, v: &[f32]| gpu.buffer_from(name, v).unwrap();
        GpuModel {
            means: b("means", &m.means),
            log_scales: b("log_scales", &m.log_scales),
            quats: b("quats", &m.quats),
            opacity_logits: b("opacity_logits", &m.opacity_logits),
            sh: b("sh", &m.sh),
            logits: b("logits", &m.logits),
            sh_m: b("sh_m", &m.sh_m),
            opacity_v: b("opacity_v", &m.opacity_v),
            grad_accum: b("grad_accum", &m.grad_accum),
            grad_count: b("grad_count", &m.grad_count),
        }
    }

    fn inputs(&self, n: usize) -> DensifyInputs<'_> {
        DensifyInputs {
            n: n as u32,
            log_scales: &self.log_scales,
            quats: &self.quats,
            opacity_logits: &self.opacity_logits,
            grad_accum: &self.grad_accum,
            grad_count: &self.grad_count,
        }
    }
}

/// Plans and applies a step to every tensor of the model; returns the plan and new model.
fn densify_on_gpu(
    gpu: &Gpu,
    densifier: &mut Densifier,
    m: &Model,
    c: &DensifyConfig,
) -> (DensifyPlan, Model) {
    let g = GpuModel::upload(gpu, m);
    let plan = densifier.plan(&g.inputs(m.n), c).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    let mut apply = |t: &Buffer, width: u32, role: Role| {
        densifier.apply(&mut rec, &plan, t, width, role).unwrap()
    };
    let outs = [
        apply(&g.means, 3, Role::Means),
        apply(&g.log_scales, 3, Role::LogScales),
        apply(&g.quats, 4, Role::Copy),
        apply(&g.opacity_logits, 1, Role::Copy),
        apply(&g.sh, SH_WIDTH as u32, Role::Copy),
        apply(&g.logits, CHANNELS as u32, Role::Copy),
        apply(&g.sh_m, SH_WIDTH as u32, Role::AdamMoment),
        apply(&g.opacity_v, 1, Role::AdamMoment),
        apply(&g.grad_accum, 1, Role::Zeroed),
        apply(&g.grad_count, 1, Role::Zeroed),
    ];
    rec.submit_and_wait().unwrap();
    let k = plan.new_n as usize;
    let read = |b: &Buffer, width: usize| -> Vec<f32> { gpu.download(b, 0, k * width).unwrap() };
    let out = Model {
        n: k,
        means: read(&outs[0], 3),
        log_scales: read(&outs[1], 3),
        quats: read(&outs[2], 4),
        opacity_logits: read(&outs[3], 1),
        sh: read(&outs[4], SH_WIDTH),
        logits: read(&outs[5], CHANNELS),
        sh_m: read(&outs[6], SH_WIDTH),
        opacity_v: read(&outs[7], 1),
        grad_accum: read(&outs[8], 1),
        grad_count: read(&outs[9], 1),
    };
    (plan, out)
}

fn row(v: &[f32], width: usize, i: usize) -> &[f32] {
    &v[i * width..(i + 1) * width]
}

/// The bit patterns of `v`, so that equality is bitwise (-0.0 must stay -0.0).
fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Checks every tensor of the GPU's new model against the reference layout.
fn check_against_reference(m: &Model, c: &DensifyConfig, plan: &DensifyPlan, out: &Model) {
    let e = reference(m, c);
    let ctx = format!("n = {}, config {c:?}", m.n);
    check_plan_counts(m, c, plan, &e, &ctx);
    for (j, &(i, kind)) in e.slots.iter().enumerate() {
        let at = format!("slot {j} (source {i}, {kind:?}), {ctx}");
        check_copied_and_scaled_rows(m, out, (j, i, kind), &at);
        check_mean_row(m, c, out, (j, i, kind), &at);
        check_moment_rows(m, out, (j, i, kind), &at);
    }
    assert!(out
        .grad_accum
        .iter()
        .chain(&out.grad_count)
        .all(|&x| x.to_bits() == 0));
}

/// The plan's counts and size are the reference's, within the cap.
fn check_plan_counts(m: &Model, c: &DensifyConfig, plan: &DensifyPlan, e: &Expected, ctx: &str) {
    assert_eq!(
        (
            plan.n,
            plan.pruned,
            plan.cloned,
            plan.split,
            plan.candidates
        ),
        (m.n as u32, e.pruned, e.cloned, e.split, e.candidates),
        "counts (n, pruned, cloned, split, candidates), {ctx}"
    );
    assert_eq!(plan.new_n as usize, e.slots.len(), "new n, {ctx}");
    assert!(plan.new_n <= c.max_gaussians, "over the cap, {ctx}");
}

/// Output slot `j` holds source `i` as `kind`: the copied tensors identify the source
/// exactly, and the log-scales are the source's, shrunk by ln 1.6 in split children.
fn check_copied_and_scaled_rows(
    m: &Model,
    out: &Model,
    (j, i, kind): (usize, usize, Kind),
    at: &str,
) {
    for (name, width, new, old) in [
        ("quats", 4, &out.quats, &m.quats),
        ("opacity", 1, &out.opacity_logits, &m.opacity_logits),
        ("sh", SH_WIDTH, &out.sh, &m.sh),
        ("logits", CHANNELS, &out.logits, &m.logits),
    ] {
        assert_eq!(
            bits(row(new, width, j)),
            bits(row(old, width, i)),
            "{name} at {at}"
        );
    }
    let shrink = 1.6f64.ln() as f32;
    let child = matches!(kind, Kind::Split0 | Kind::Split1);
    let want_ls: Vec<f32> = row(&m.log_scales, 3, i)
        .iter()
        .map(|&x| if child { x - shrink } else { x })
        .collect();
    assert_eq!(
        bits(row(&out.log_scales, 3, j)),
        bits(&want_ls),
        "log_scales at {at}"
    );
}

/// A split child's mean is the source's moved by its f64 split offset; any other slot's
/// is the source's, bitwise.
fn check_mean_row(
    m: &Model,
    c: &DensifyConfig,
    out: &Model,
    (j, i, kind): (usize, usize, Kind),
    at: &str,
) {
    if matches!(kind, Kind::Split0 | Kind::Split1) {
        let offset = split_offset(m, i, u32::from(kind == Kind::Split1), c.seed);
        for (a, d) in offset.iter().enumerate() {
            let want = m.means[3 * i + a] as f64 + d;
            let got = out.means[3 * j + a] as f64;
            assert!(
                (got - want).abs() <= 1e-5,
                "mean[{a}] {got} vs {want} at {at}"
            );
        }
    } else {
        assert_eq!(
            bits(row(&out.means, 3, j)),
            bits(row(&m.means, 3, i)),
            "mean at {at}"
        );
    }
}

/// Adam moments start at zero in new Gaussians (clones and split children) and are kept
/// in the rest.
fn check_moment_rows(m: &Model, out: &Model, (j, i, kind): (usize, usize, Kind), at: &str) {
    let fresh = kind != Kind::Keep;
    let moment = |new: &[f32], old: &[f32], width: usize| {
        if fresh {
            assert!(
                row(new, width, j).iter().all(|&x| x.to_bits() == 0),
                "moment at {at}"
            );
        } else {
            assert_eq!(
                bits(row(new, width, j)),
                bits(row(old, width, i)),
                "moment at {at}"
            );
        }
    };
    moment(&out.sh_m, &m.sh_m, SH_WIDTH);
    moment(&out.opacity_v, &m.opacity_v, 1);
}

#[test]
fn densify_matches_cpu_reference() {
    let gpu = gpu();
    let mut densifier = Densifier::new(gpu);
    let mut hit = [0u32; 3];
    for (k, &n) in [0usize, 1, 2, 3, 17, 256, 257, 1000, 5000]
        .iter()
        .enumerate()
    {
        for prune_large in [false, true] {
            let extent = [1.0, 2.5, 0.3][k % 3];
            let m = random_model(n, extent, 100 + k as u64);
            let c = DensifyConfig {
                extent,
                prune_large,
                seed: 0x1234_5678_9ABC_DEF0 ^ (k as u64 * 977),
                ..DensifyConfig::default()
            };
            let (plan, out) = densify_on_gpu(gpu, &mut densifier, &m, &c);
            check_against_reference(&m, &c, &plan, &out);
            hit[0] += plan.pruned;
            hit[1] += plan.cloned;
            hit[2] += plan.split;
        }
    }
    assert!(hit.iter().all(|&h| h > 100), "branches hit: {hit:?}");
    check_validation(gpu);
}

#[test]
fn one_gaussian_each_branch() {
    let gpu = gpu();
    let mut densifier = Densifier::new(gpu);
    // (opacity logit, log-scale, accum, count) -> (new n, pruned, cloned, split)
    let cases = [
        ((0.0, -6.0, 0.001, 1.0), (2, 0, 1, 0)),  // clone
        ((0.0, -3.0, 0.001, 1.0), (2, 0, 0, 1)),  // split
        ((0.0, -3.0, 0.0001, 1.0), (1, 0, 0, 0)), // kept
        ((0.0, -3.0, 0.001, 0.0), (1, 0, 0, 0)),  // unseen: avg 0
        ((-8.0, -2.0, 0.001, 1.0), (0, 1, 0, 0)), // pruned beats densified
        ((0.0, 0.0, 0.001, 1.0), (0, 1, 0, 0)),   // too large (prune_large)
    ];
    for ((logit, ls, accum, count), want) in cases {
        let m = Model {
            n: 1,
            means: vec![0.5, -0.25, -0.0],
            log_scales: vec![ls, ls - 0.5, ls - 1.0],
            quats: vec![0.9, 0.1, -0.3, 0.2],
            opacity_logits: vec![logit],
            sh: vec![0.5; SH_WIDTH],
            logits: vec![1.0; CHANNELS],
            sh_m: vec![0.25; SH_WIDTH],
            opacity_v: vec![0.125],
            grad_accum: vec![accum],
            grad_count: vec![count],
        };
        let c = DensifyConfig {
            prune_large: true,
            ..DensifyConfig::default()
        };
        let (plan, out) = densify_on_gpu(gpu, &mut densifier, &m, &c);
        assert_eq!((plan.new_n, plan.pruned, plan.cloned, plan.split), want);
        check_against_reference(&m, &c, &plan, &out);
    }
    check_validation(gpu);
}

/// Densifies random models of 1 to 3000 Gaussians under caps from the input size to 2n - 1
/// (bound or not), checking each against the reference and that the cap cuts the
/// densified count exactly; returns how many caps left some candidates out.
fn check_caps_on_random_models(gpu: &Gpu, densifier: &mut Densifier) -> usize {
    let mut partial = 0;
    for (k, &n) in [1usize, 2, 7, 50, 3000].iter().enumerate() {
        // About a sixth is pruned and half are candidates, so caps from n up bind.
        let m = random_model(n, 1.0, 700 + k as u64);
        let c = DensifyConfig {
            seed: 99,
            ..DensifyConfig::default()
        };
        let open = reference(&m, &c);
        let survivors = n as u32 - open.pruned;
        let densified = open.cloned + open.split;
        let all = survivors + densified;
        // The input size (room for the pruned only), one more, halfway, all but one,
        // exactly all, and a cap that sorts (2n above it) without binding.
        let budgets = [
            n as u32,
            n as u32 + 1,
            (n as u32 + all) / 2,
            all.saturating_sub(1),
            all,
            2 * n as u32 - 1,
        ];
        for max_gaussians in budgets {
            if max_gaussians < n as u32 {
                continue;
            }
            let c = DensifyConfig { max_gaussians, ..c };
            let (plan, out) = densify_on_gpu(gpu, densifier, &m, &c);
            check_against_reference(&m, &c, &plan, &out);
            let want = densified.min(max_gaussians - survivors);
            assert_eq!(
                plan.cloned + plan.split,
                want,
                "densified under cap {max_gaussians}"
            );
            assert_eq!(plan.capped(), densified - want);
            if want > 0 && want < densified {
                partial += 1;
            }
        }
    }
    partial
}

/// Exact ties in the gradient at the cap: the lower indices win (and the tied top
/// gradients beat the distinct lower ones).
fn check_ties_at_the_cap(gpu: &Gpu, densifier: &mut Densifier) {
    let mut m = random_model(400, 1.0, 31);
    for i in 0..m.n {
        m.opacity_logits[i] = 1.0;
        m.grad_accum[i] = match i % 3 {
            0 => 0.003,
            1 => 0.001 * (1.0 + i as f32 / 400.0),
            _ => 0.0001,
        };
        m.grad_count[i] = 1.0;
    }
    let ties = m.n.div_ceil(3) as u32;
    let c = DensifyConfig {
        max_gaussians: m.n as u32 + ties / 2,
        ..DensifyConfig::default()
    };
    let (plan, out) = densify_on_gpu(gpu, densifier, &m, &c);
    check_against_reference(&m, &c, &plan, &out);
    assert_eq!(
        (plan.cloned + plan.split, plan.capped()),
        (ties / 2, 2 * ties - 1 - ties / 2)
    );
}

#[test]
fn cap_keeps_the_largest_gradients() {
    let gpu = gpu();
    let mut densifier = Densifier::new(gpu);
    let partial = check_caps_on_random_models(gpu, &mut densifier);
    assert!(
        partial >= 6,
        "caps that left some candidates out: {partial}"
    );
    check_ties_at_the_cap(gpu, &mut densifier);
    check_validation(gpu);
}

/// Means, covariance and kurtosis of the whitened split offsets S^-1 R^T d: with z ~ N(0, I)
/// they are 0, I and 3; child 0 and child 1 are uncorrelated.
#[test]
fn split_offsets_are_gaussian_with_the_parents_covariance() {
    let gpu = gpu();
    let mut densifier = Densifier::new(gpu);
    let n = 20_000;
    let scales = [0.3f64, 0.1, 0.05];
    let q = [0.8f32, -0.2, 0.5, 0.3];
    let m = Model {
        n,
        means: (0..3 * n).map(|k| (k % 7) as f32 * 0.25).collect(),
        log_scales: (0..3 * n).map(|k| scales[k % 3].ln() as f32).collect(),
        quats: (0..4 * n).map(|k| q[k % 4]).collect(),
        opacity_logits: vec![2.0; n],
        sh: vec![0.0; n * SH_WIDTH],
        logits: vec![0.0; n * CHANNELS],
        sh_m: vec![0.0; n * SH_WIDTH],
        opacity_v: vec![0.0; n],
        grad_accum: vec![0.01; n],
        grad_count: vec![1.0; n],
    };
    let c = DensifyConfig {
        seed: 2024,
        ..DensifyConfig::default()
    };
    let (plan, out) = densify_on_gpu(gpu, &mut densifier, &m, &c);
    assert_eq!((plan.split, plan.new_n as usize), (n as u32, 2 * n));
    let r = rotation(&q);
    // z = S^-1 R^T (new mean - mean), per child.
    let whiten = |j: usize, i: usize| -> [f64; 3] {
        let d: Vec<f64> = (0..3)
            .map(|a| out.means[3 * j + a] as f64 - m.means[3 * i + a] as f64)
            .collect();
        [0, 1, 2].map(|a| (0..3).map(|b| r[b][a] * d[b]).sum::<f64>() / scales[a])
    };
    let z: Vec<[[f64; 3]; 2]> = (0..n)
        .map(|i| [whiten(2 * i, i), whiten(2 * i + 1, i)])
        .collect();
    let samples: Vec<[f64; 3]> = z.iter().flatten().copied().collect();
    let count = samples.len() as f64;
    // Standard errors for N(0, 1) samples: mean 1/sqrt(N), covariance sqrt(2/N) on the
    // diagonal and sqrt(1/N) off it, kurtosis sqrt(24/N); bounds at 5 sigma.
    for a in 0..3 {
        let mean = samples.iter().map(|s| s[a]).sum::<f64>() / count;
        assert!(mean.abs() < 5.0 / count.sqrt(), "mean[{a}] = {mean}");
        for b in 0..3 {
            let cov = samples.iter().map(|s| s[a] * s[b]).sum::<f64>() / count;
            let (want, se) = if a == b {
                (1.0, (2.0 / count).sqrt())
            } else {
                (0.0, (1.0 / count).sqrt())
            };
            assert!((cov - want).abs() < 5.0 * se, "cov[{a}][{b}] = {cov}");
        }
        let kurt = samples.iter().map(|s| s[a].powi(4)).sum::<f64>() / count;
        assert!(
            (kurt - 3.0).abs() < 5.0 * (24.0 / count).sqrt(),
            "kurtosis[{a}] = {kurt}"
        );
        for b in 0..3 {
            let cross = z.iter().map(|p| p[0][a] * p[1][b]).sum::<f64>() / n as f64;
            assert!(
                cross.abs() < 5.0 / (n as f64).sqrt(),
                "children cov[{a}][{b}] = {cross}"
            );
        }
    }
    check_validation(gpu);
}

#[test]
fn opacity_reset_caps_opacity_and_zeroes_its_moments() {
    let gpu = gpu();
    for n in [1usize, 1000] {
        // From 8 down (n = 1: a single opaque one), across the cap at -4.6.
        let logits: Vec<f32> = (0..n).map(|i| 8.0 - 16.0 * i as f32 / n as f32).collect();
        let buf = gpu.buffer_from("opacity_logits", &logits).unwrap();
        let m = gpu.buffer_from("m", &vec![0.5f32; n]).unwrap();
        let v = gpu.buffer_from("v", &vec![0.25f32; n]).unwrap();
        let mut rec = Recorder::new(gpu).unwrap();
        reset_opacity(&mut rec, n as u32, &buf, &[&m, &v], OPACITY_RESET).unwrap();
        rec.submit_and_wait().unwrap();
        let cap = (0.01f64 / 0.99).ln() as f32;
        let got: Vec<f32> = gpu.read(&buf).unwrap();
        for (i, (&g, &x)) in got.iter().zip(&logits).enumerate() {
            assert_eq!(g.to_bits(), x.min(cap).to_bits(), "logit {i}");
        }
        assert!(
            got[0] == cap && (n == 1 || got[n - 1] < cap),
            "both sides of the cap"
        );
        for b in [&m, &v] {
            assert!(gpu
                .read::<f32>(b)
                .unwrap()
                .iter()
                .all(|&x| x.to_bits() == 0));
        }
    }
    check_validation(gpu);
}

#[test]
fn refuses_bad_input_and_stale_plans() {
    let gpu = gpu();
    let mut densifier = Densifier::new(gpu);
    let m = random_model(10, 1.0, 5);
    let g = GpuModel::upload(gpu, &m);
    let c = DensifyConfig::default();
    // More Gaussians than the cap, and tensors shorter than n.
    let over = DensifyConfig {
        max_gaussians: 9,
        ..c
    };
    assert!(densifier.plan(&g.inputs(10), &over).is_err());
    assert!(densifier.plan(&g.inputs(11), &c).is_err());
    let bad = DensifyConfig {
        min_opacity: 1.5,
        ..c
    };
    assert!(densifier.plan(&g.inputs(10), &bad).is_err());
    let first = densifier.plan(&g.inputs(10), &c).unwrap();
    let second = densifier.plan(&g.inputs(10), &c).unwrap();
    assert_eq!(first.new_n, second.new_n, "the same input plans the same");
    let mut rec = Recorder::new(gpu).unwrap();
    assert!(densifier
        .apply(&mut rec, &first, &g.means, 3, Role::Means)
        .is_err());
    assert!(densifier
        .apply(&mut rec, &second, &g.sh, SH_WIDTH as u32, Role::Means)
        .is_err());
    assert!(densifier
        .apply(&mut rec, &second, &g.quats, 5, Role::Copy)
        .is_err());
    rec.submit_and_wait().unwrap();
    check_validation(gpu);
}

/// A tensor whose new set has more elements than 65,535 workgroups cover in one
/// dimension: the gather runs on a 2D grid and must still place every element.
#[test]
fn wide_tensor_gathers_past_one_grid_dimension() {
    let gpu = gpu();
    let mut densifier = Densifier::new(gpu);
    let (n, width) = (60_000usize, 200usize);
    let b = |name: &str, v: Vec<f32>| gpu.buffer_from(name, &v).unwrap();
    // Every even Gaussian is cloned; the tensor holds each element's own index.
    let log_scales = b("log_scales", vec![-6.0; 3 * n]);
    let quats = b("quats", vec![1.0; 4 * n]);
    let opacity_logits = b("opacity_logits", vec![1.0; n]);
    let grad_accum = b("grad_accum", (0..n).map(|i| ((i + 1) % 2) as f32).collect());
    let grad_count = b("grad_count", vec![1.0; n]);
    let data: Vec<f32> = (0..n * width).map(|k| k as f32).collect();
    let wide = gpu.buffer_from("wide", &data).unwrap();
    let inputs = DensifyInputs {
        n: n as u32,
        log_scales: &log_scales,
        quats: &quats,
        opacity_logits: &opacity_logits,
        grad_accum: &grad_accum,
        grad_count: &grad_count,
    };
    let plan = densifier.plan(&inputs, &DensifyConfig::default()).unwrap();
    assert_eq!(
        (plan.cloned, plan.new_n as usize),
        (n as u32 / 2, n + n / 2)
    );
    assert!(plan.new_n as usize * width > 65_535 * 256);
    let mut rec = Recorder::new(gpu).unwrap();
    let out = densifier
        .apply(&mut rec, &plan, &wide, width as u32, Role::Copy)
        .unwrap();
    rec.submit_and_wait().unwrap();
    let got: Vec<f32> = gpu.download(&out, 0, plan.new_n as usize * width).unwrap();
    let sources = (0..n).flat_map(|i| std::iter::repeat_n(i, 2 - i % 2));
    for (j, i) in sources.enumerate() {
        assert_eq!(row(&got, width, j), row(&data, width, i), "slot {j}");
    }
    check_validation(gpu);
}
