//! Finite-difference tests of the CPU reference backward pass
//! (`semsplat::render::reference::backward`).
//!
//! The objective is `L = sum_p v_rgb . rgb + v_alpha alpha + v_sem . sem_norm` with random
//! upstream gradients `v`. Finite differences (FD) run entirely in f64: the scene's float32
//! parameters are copied exactly into `GaussianParams`, perturbed there and rendered by the
//! f64 twin of the forward (`render_params`). Every case first asserts that this twin is
//! bitwise the reference forward (`render`) on the unperturbed scene, so the FD
//! differentiate the real forward, with steps far below float32 resolution. Screen-space
//! gradients (mean2d, conic, opacity, color) are checked the same way by perturbing the
//! projected Gaussians and compositing them again (`render_screen`).
//!
//! Each value gets central differences at steps h and h/2, D(h) and D(h/2), and is
//! compared against their Richardson extrapolation `R = D(h/2) + (D(h/2) - D(h)) / 3`
//! (truncation O(h^4)). The forward is only piecewise smooth: a Gaussian's alpha crossing
//! 1/255, a pixel's T stop, a depth-order swap, the 0.999 alpha clamp, the Jacobian and
//! color clamps make L jump or kink, and FD across such a point measure the jump, not the
//! derivative. There D(h) and D(h/2) disagree (a jump J gives J/2h vs J/h; a slope change
//! at offset d within the step gives a difference proportional to d/h), so a value whose
//! |D(h) - D(h/2)| exceeds the comparison tolerance is excluded as "FD not trustworthy
//! here", printed, counted, and the excluded fraction is asserted small. Small steps keep
//! it small: the chance that some pixel sits within the step of a threshold is about the
//! length of the Gaussian's 1/255 contour times the step (in px). Everything else must
//! match to
//!   |analytic - R| <= RTOL * max(|analytic|, |R|) + atol,
//! RTOL = 1e-6: the f64 analytic gradient is accurate to ~1e-12 and R's truncation error at
//! our steps is far below 1e-6 relative, while any real bug is O(1) wrong (the worst
//! |error| / tolerance seen is a few percent). atol is the FD's rounding floor,
//! `ATOL_ROUNDING * eps * touched / h`, with `touched` the summed magnitude of the objective
//! terms of the pixels the perturbation changes (differencing pixel by pixel, pixels it
//! does not reach contribute exactly 0).

// Parameter loops index several parallel arrays at once, like the formulas they check.
#![allow(clippy::needless_range_loop)]

mod common;

use common::spec_scene::{scene, Spec};

use std::time::Instant;

use glam::{DMat3, DQuat, DVec3};
use semsplat::render::reference::backward::{
    backward, backward_params, objective, render_params, render_screen, sh_basis_grad,
    GaussianParams, ParamGrads, PixelGrads, ScreenSpace,
};
use semsplat::render::reference::{
    eval_alpha, project, render, sh_basis, ReferenceImage, RenderSettings, SemanticMode,
    FRUSTUM_MARGIN, MAX_ALPHA, T_STOP,
};
use semsplat::scene::random_scene::{random_scene, RandomSceneSpec};
use semsplat::scene::{Camera, Gaussians, Split};
use semsplat::util::Rng;

/// Relative tolerance of the FD comparison (see the module docs).
const RTOL: f64 = 1e-6;
/// The absolute floor, in units of `eps * touched / h`. A pixel's term is a sum of many
/// rounded products (every blended Gaussian, the background, the division by 1 - T), so
/// its rounding noise reaches ~100 eps |term| (measured on faint Gaussians, whose FD are
/// all noise); Richardson's (4 D(h/2) - D(h)) / 3 amplifies noise by ~3; ~3x margin.
const ATOL_ROUNDING: f64 = 1000.0;
/// Largest fraction of a case's values that may be excluded as kinks (seen: at most ~1%,
/// on random scenes whose Gaussians have long 1/255 contours).
const MAX_KINK_FRACTION: f64 = 0.02;

// ---------------------------------------------------------------- scenes

fn axis_camera(width: u32, height: u32, f: f64) -> Camera {
    Camera {
        name: "axis".into(),
        width,
        height,
        fx: f,
        fy: f,
        cx: 0.5 * f64::from(width),
        cy: 0.5 * f64::from(height),
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        split: Split::Train,
    }
}

/// A rotated, translated camera with fx != fy and an off-center principal point, so every
/// camera term of the chain rule is exercised.
fn posed_camera(width: u32, height: u32) -> Camera {
    let (w, h) = (f64::from(width), f64::from(height));
    Camera {
        name: "posed".into(),
        width,
        height,
        fx: 0.9 * w,
        fy: 0.85 * w,
        cx: 0.45 * w,
        cy: 0.55 * h,
        rotation: DMat3::from_quat(DQuat::from_euler(glam::EulerRot::YXZ, 0.4, -0.3, 0.2)),
        translation: DVec3::new(0.3, -0.2, 0.5),
        split: Split::Train,
    }
}

/// A Gaussian at pixel `(u, v)` and depth `z` of `cam`, with random rotation, SH and
/// logits for the given degree and channel count.
fn spec_at(
    rng: &mut Rng,
    cam: &Camera,
    (u, v, z): (f64, f64, f64),
    log_scale: [f32; 3],
    logit: f32,
    degree: u32,
    channels: usize,
) -> Spec {
    let pc = DVec3::new((u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z);
    let pw = cam.rotation.transpose() * (pc - cam.translation);
    let coeffs = ((degree + 1) * (degree + 1)) as usize;
    Spec {
        mean: pw.as_vec3().to_array(),
        log_scale,
        quat: [(); 4].map(|_| rng.normal() as f32),
        logit,
        sh: (0..coeffs)
            .map(|k| {
                let spread = if k == 0 { 1.0 } else { 0.4 };
                [(); 3].map(|_| (spread * rng.normal()) as f32)
            })
            .collect(),
        logits: (0..channels).map(|_| (2.0 * rng.normal()) as f32).collect(),
    }
}

/// Random Gaussians around and beyond the image of `cam` (a quarter of the image outside
/// on each side, so some are partly outside the frustum), depths 0.5..5, anisotropic
/// scales, opacities from faint to opaque.
fn posed_random_scene(
    seed: u64,
    n: usize,
    cam: &Camera,
    degree: u32,
    channels: usize,
) -> Gaussians {
    let mut rng = Rng::new(seed);
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let specs: Vec<Spec> = (0..n)
        .map(|_| {
            let at = (
                rng.range_f64(-0.25 * w, 1.25 * w),
                rng.range_f64(-0.25 * h, 1.25 * h),
                rng.range_f64(0.5, 5.0),
            );
            let ls = [(); 3].map(|_| rng.range_f64(-4.5, -1.0) as f32);
            let logit = rng.range_f64(-4.0, 7.0) as f32;
            spec_at(&mut rng, cam, at, ls, logit, degree, channels)
        })
        .collect();
    scene(&specs)
}

fn settings(background: [f64; 3], mode: SemanticMode) -> RenderSettings {
    RenderSettings {
        background,
        semantic_mode: mode,
        ..Default::default()
    }
}

fn view_channels(g: &Gaussians, settings: &RenderSettings) -> usize {
    match &g.semantics {
        Some(s) if settings.semantics => s.channels,
        _ => 0,
    }
}

/// Upstream gradients uniform in [-1, 1].
fn random_upstream(cam: &Camera, channels: usize, seed: u64) -> PixelGrads {
    let mut rng = Rng::new(seed);
    let pixels = (cam.width * cam.height) as usize;
    let mut u = || rng.range_f64(-1.0, 1.0);
    PixelGrads {
        rgb: (0..pixels).map(|_| [u(), u(), u()]).collect(),
        alpha: (0..pixels).map(|_| u()).collect(),
        sem_norm: (0..pixels * channels).map(|_| u()).collect(),
    }
}

// ---------------------------------------------------------------- what a scene exercises

/// Which non-smooth pieces of the forward a view actually reaches.
#[derive(Debug, Default)]
struct Coverage {
    /// Visible Gaussians whose x/z or y/z the Jacobian clamps.
    jacobian_clamped: Vec<u32>,
    /// Blended (pixel, Gaussian) pairs whose alpha sits at the 0.999 clamp.
    alpha_clamped_pairs: usize,
    /// Pixels that stopped at T <= 1e-4 (a Gaussian with visible alpha not blended).
    t_stopped_pixels: usize,
    /// Visible Gaussians with a color channel clamped at 0.
    color_clamped: usize,
    visible: usize,
}

/// Written out from the conventions (not the crate's helpers): the Jacobian clamps x/z to
/// `[-(cx/fx + m tan), (w - cx)/fx + m tan]` with `tan = w / (2 fx)`, y alike.
fn coverage(g: &Gaussians, cam: &Camera, settings: &RenderSettings) -> Coverage {
    let projected = project(g, cam, settings);
    let mut cov = Coverage {
        visible: projected.len(),
        ..Default::default()
    };
    let (w, h) = (f64::from(cam.width), f64::from(cam.height));
    let tx = 0.5 * w / cam.fx;
    let ty = 0.5 * h / cam.fy;
    for p in &projected {
        let (rx, ry) = (p.mean_cam.x / p.mean_cam.z, p.mean_cam.y / p.mean_cam.z);
        let out_x = rx > (w - cam.cx) / cam.fx + FRUSTUM_MARGIN * tx
            || rx < -(cam.cx / cam.fx + FRUSTUM_MARGIN * tx);
        let out_y = ry > (h - cam.cy) / cam.fy + FRUSTUM_MARGIN * ty
            || ry < -(cam.cy / cam.fy + FRUSTUM_MARGIN * ty);
        if out_x || out_y {
            cov.jacobian_clamped.push(p.id);
        }
        if p.color.contains(&0.0) {
            cov.color_clamped += 1;
        }
    }
    // Brute force per pixel over all visible Gaussians by depth (outside its tiles a
    // Gaussian's alpha is below 1/255 anyway).
    let mut order: Vec<_> = projected.iter().collect();
    order.sort_by(|a, b| a.depth.total_cmp(&b.depth).then(a.id.cmp(&b.id)));
    for py in 0..cam.height {
        for px in 0..cam.width {
            let mut t = 1.0;
            for p in &order {
                let Some(alpha) = eval_alpha(p, px, py) else {
                    continue;
                };
                if t * (1.0 - alpha) <= T_STOP {
                    cov.t_stopped_pixels += 1;
                    break;
                }
                if alpha == MAX_ALPHA {
                    cov.alpha_clamped_pairs += 1;
                }
                t *= 1.0 - alpha;
            }
        }
    }
    cov
}

// ---------------------------------------------------------------- finite differences

/// Counts over one view's FD checks.
#[derive(Debug, Default)]
struct FdStats {
    checked: usize,
    /// Excluded: D(h) and D(h/2) disagree (a kink or jump within the step).
    kinks: usize,
    /// Of the checked ones, how many had a gradient above the absolute floor.
    nonzero: usize,
    /// Largest |analytic - R| / (RTOL * scale + atol) seen (<= 1 passes).
    worst_ratio: f64,
    failures: Vec<String>,
}

impl FdStats {
    fn kink_fraction(&self) -> f64 {
        self.kinks as f64 / (self.checked + self.kinks).max(1) as f64
    }

    fn add(&mut self, other: FdStats) {
        self.checked += other.checked;
        self.kinks += other.kinks;
        self.nonzero += other.nonzero;
        self.worst_ratio = self.worst_ratio.max(other.worst_ratio);
        self.failures.extend(other.failures);
    }

    /// Compares `analytic` with FD of the objective defined by `upstream` on
    /// `render(offset)`, the image with the parameter moved by `offset`.
    fn judge(
        &mut self,
        label: impl FnOnce() -> String,
        analytic: f64,
        h: f64,
        upstream: &PixelGrads,
        mut render: impl FnMut(f64) -> ReferenceImage,
    ) {
        // Differencing pixel by pixel leaves untouched pixels exactly 0, so the rounding
        // noise comes only from the pixels the parameter reaches: `touched` sums their
        // terms' magnitudes.
        let mut central = |step: f64| {
            let (plus, minus) = (render(step), render(-step));
            let (terms_plus, terms_minus) =
                (pixel_terms(upstream, &plus), pixel_terms(upstream, &minus));
            let (abs_plus, abs_minus) = (
                pixel_abs_terms(upstream, &plus),
                pixel_abs_terms(upstream, &minus),
            );
            let mut diff = 0.0;
            let mut scale = 0.0;
            for p in 0..terms_plus.len() {
                if terms_plus[p] != terms_minus[p] {
                    diff += terms_plus[p] - terms_minus[p];
                    scale += abs_plus[p].max(abs_minus[p]);
                }
            }
            (diff / (2.0 * step), scale)
        };
        let (d_h, touched_h) = central(h);
        let (d_half, touched_half) = central(0.5 * h);
        let touched = touched_h.max(touched_half);
        let richardson = d_half + (d_half - d_h) / 3.0;
        let atol = ATOL_ROUNDING * f64::EPSILON * touched / h;
        let tol = RTOL * analytic.abs().max(richardson.abs()) + atol;
        if (d_h - d_half).abs() > tol {
            // Shown with --nocapture, so every exclusion can be inspected.
            println!(
                "  excluded {}: analytic {analytic:.6e}, D(h) {d_h:.6e}, D(h/2) {d_half:.6e}",
                label()
            );
            self.kinks += 1;
            return;
        }
        self.checked += 1;
        if analytic.abs() > atol {
            self.nonzero += 1;
        }
        let err = (analytic - richardson).abs();
        if tol > 0.0 {
            self.worst_ratio = self.worst_ratio.max(err / tol);
        }
        if err > tol || !analytic.is_finite() {
            self.failures.push(format!(
                "{}: analytic {analytic:.12e}, FD {richardson:.12e} (D(h) {d_h:.12e}, \
                 D(h/2) {d_half:.12e}, h {h:e}, tol {tol:.3e})",
                label()
            ));
        }
    }
}

/// Per pixel, `|v_rgb| . |rgb| + |v_alpha alpha| + |v_sem| . |sem_norm|`: the scale of the
/// rounding noise of its objective term, whatever cancels inside it.
fn pixel_abs_terms(up: &PixelGrads, img: &ReferenceImage) -> Vec<f64> {
    let channels = img.channels;
    (0..img.rgb.len())
        .map(|p| {
            let rgb: f64 = (0..3)
                .map(|ch| (up.rgb[p][ch] * img.rgb[p][ch]).abs())
                .sum();
            let sem: f64 = (p * channels..(p + 1) * channels)
                .map(|k| (up.sem_norm[k] * img.sem_norm[k]).abs())
                .sum();
            rgb + (up.alpha[p] * img.alpha[p]).abs() + sem
        })
        .collect()
}

/// Per pixel, `v_rgb . rgb + v_alpha alpha + v_sem . sem_norm` with the same operations
/// as `PixelGrads::objective` (whose in-order sum is bitwise their sum).
fn pixel_terms(up: &PixelGrads, img: &ReferenceImage) -> Vec<f64> {
    let channels = img.channels;
    (0..img.rgb.len())
        .map(|p| {
            let rgb: f64 = (0..3).map(|ch| up.rgb[p][ch] * img.rgb[p][ch]).sum();
            let sem: f64 = (p * channels..(p + 1) * channels)
                .map(|k| up.sem_norm[k] * img.sem_norm[k])
                .sum();
            rgb + up.alpha[p] * img.alpha[p] + sem
        })
        .collect()
}

/// The stored parameters, by kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Param {
    Mean,
    LogScale,
    Quat,
    OpacityLogit,
    Sh,
    Logit,
}

const PARAMS: [Param; 6] = [
    Param::Mean,
    Param::LogScale,
    Param::Quat,
    Param::OpacityLogit,
    Param::Sh,
    Param::Logit,
];

/// Components of kind `which` per Gaussian.
fn components(params: &GaussianParams, which: Param) -> usize {
    match which {
        Param::Mean | Param::LogScale => 3,
        Param::Quat => 4,
        Param::OpacityLogit => 1,
        Param::Sh => params.sh_coeffs() * 3,
        Param::Logit => params.channels,
    }
}

fn entry(params: &mut GaussianParams, which: Param, i: usize, j: usize) -> &mut f64 {
    match which {
        Param::Mean => &mut params.means[i][j],
        Param::LogScale => &mut params.log_scales[i][j],
        Param::Quat => &mut params.quats[i][j],
        Param::OpacityLogit => &mut params.opacity_logits[i],
        Param::Sh => {
            let row = params.sh_coeffs() * 3;
            &mut params.sh[i * row + j]
        }
        Param::Logit => &mut params.logits[i * params.channels + j],
    }
}

fn analytic(grads: &ParamGrads, params: &GaussianParams, which: Param, i: usize, j: usize) -> f64 {
    match which {
        Param::Mean => grads.means[i][j],
        Param::LogScale => grads.log_scales[i][j],
        Param::Quat => grads.quats[i][j],
        Param::OpacityLogit => grads.opacity_logits[i],
        Param::Sh => grads.sh[i * params.sh_coeffs() * 3 + j],
        Param::Logit => grads.logits[i * params.channels + j],
    }
}

/// FD step of the dimensionless nonlinear values (log-scales, opacity logits and
/// opacities; relative for quaternions and conics). Small, so that few (pixel, Gaussian)
/// pairs cross the 1/255 alpha threshold or the T stop within the step (those are the
/// kinks), yet large against the rounding noise (see `ATOL_ROUNDING`).
const STEP: f64 = 1e-5;
/// FD step of screen motion, in pixels, for means and mean2d: a Gaussian's alpha varies on
/// the scale of its 2D standard deviation, at least sqrt(0.3) px.
const STEP_PX: f64 = 1e-4;
/// FD step of the values L depends on (piecewise) linearly or gently: SH coefficients,
/// colors and semantic logits.
const STEP_LINEAR: f64 = 1e-4;

fn fd_step(params: &GaussianParams, cam: &Camera, which: Param, i: usize) -> f64 {
    match which {
        Param::Mean => {
            // dx_px = f dx / z.
            let z = cam.world_to_camera(DVec3::from(params.means[i])).z.abs();
            STEP_PX * z.max(0.1) / cam.fx.max(cam.fy)
        }
        Param::LogScale | Param::OpacityLogit => STEP,
        Param::Quat => STEP * params.quats[i].iter().map(|v| v * v).sum::<f64>().sqrt(),
        Param::Sh | Param::Logit => STEP_LINEAR,
    }
}

/// Screen-space values, by kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Screen {
    Mean2d,
    Conic,
    Opacity,
    Color,
}

/// One view to check: scene, camera, settings and the upstream seed.
struct Case {
    name: String,
    g: Gaussians,
    cam: Camera,
    settings: RenderSettings,
    seed: u64,
}

/// FD-checks every stored parameter and every visible Gaussian's screen-space values of
/// one view; asserts the f64 twin equals the forward and the gradients are finite.
fn check_case(case: &Case) -> FdStats {
    let start = Instant::now();
    let (params, upstream, grads) = checked_forward_and_backward(case);
    let mut stats = FdStats::default();
    fd_check_stored_params(&mut stats, case, &params, &grads, &upstream);
    let screen = ScreenSpace::new(&params, &case.cam, &case.settings);
    fd_check_screen_space(&mut stats, case, &screen, &grads, &upstream);
    print_case_summary(case, screen.projected.len(), &stats, start);
    stats
}

/// The case's parameters in f64, its upstream gradients and its analytic gradients, after
/// asserting that the f64 twin is bitwise the reference forward (so the FD differentiate
/// the real forward), that both backward entry points agree, that the gradients are finite
/// and that the objective is the in-order sum of the per-pixel terms the FD take apart.
fn checked_forward_and_backward(case: &Case) -> (GaussianParams, PixelGrads, ParamGrads) {
    let Case {
        g, cam, settings, ..
    } = case;
    let params = GaussianParams::from_gaussians(g);
    let img = render(g, cam, settings);
    assert_eq!(
        render_params(&params, cam, settings),
        img,
        "{}: the f64 twin must be bitwise the reference forward",
        case.name
    );
    let channels = view_channels(g, settings);
    let upstream = random_upstream(cam, channels, case.seed);
    let grads = backward(g, cam, settings, &upstream);
    assert_eq!(grads, backward_params(&params, cam, settings, &upstream));
    assert_finite(&grads, &case.name);
    let l0 = objective(&params, cam, settings, &upstream);
    assert_eq!(l0, upstream.objective(&img));
    let terms = pixel_terms(&upstream, &img);
    assert_eq!(l0, terms.iter().fold(0.0, |acc, t| acc + t));
    (params, upstream, grads)
}

/// FD-checks every component of every stored parameter of every Gaussian, rendering the
/// moved parameters with the f64 twin.
fn fd_check_stored_params(
    stats: &mut FdStats,
    case: &Case,
    params: &GaussianParams,
    grads: &ParamGrads,
    upstream: &PixelGrads,
) {
    let Case { cam, settings, .. } = case;
    for which in PARAMS {
        for i in 0..params.len() {
            for j in 0..components(params, which) {
                let h = fd_step(params, cam, which, i);
                let mut moved = params.clone();
                let x0 = *entry(&mut moved, which, i, j);
                stats.judge(
                    || format!("{} {which:?}[{i}][{j}]", case.name),
                    analytic(grads, params, which, i, j),
                    h,
                    upstream,
                    |offset| {
                        *entry(&mut moved, which, i, j) = x0 + offset;
                        render_params(&moved, cam, settings)
                    },
                );
            }
        }
    }
}

/// FD-checks every visible Gaussian's screen-space values (mean2d, conic, opacity, color)
/// by moving the projected Gaussian and compositing again.
fn fd_check_screen_space(
    stats: &mut FdStats,
    case: &Case,
    screen: &ScreenSpace,
    grads: &ParamGrads,
    upstream: &PixelGrads,
) {
    let Case { cam, settings, .. } = case;
    for (slot, p) in screen.projected.iter().enumerate() {
        let i = p.id as usize;
        // Conic steps relative to each entry's natural scale (B's is sqrt(AC) > |B|).
        let [a, _, c] = p.conic;
        let checks: [(Screen, usize, f64, f64); 9] = [
            (Screen::Mean2d, 0, STEP_PX, grads.mean2d[i][0]),
            (Screen::Mean2d, 1, STEP_PX, grads.mean2d[i][1]),
            (Screen::Conic, 0, STEP * a, grads.conic[i][0]),
            (Screen::Conic, 1, STEP * (a * c).sqrt(), grads.conic[i][1]),
            (Screen::Conic, 2, STEP * c, grads.conic[i][2]),
            (Screen::Opacity, 0, STEP, grads.opacity[i]),
            (Screen::Color, 0, STEP_LINEAR, grads.color[i][0]),
            (Screen::Color, 1, STEP_LINEAR, grads.color[i][1]),
            (Screen::Color, 2, STEP_LINEAR, grads.color[i][2]),
        ];
        for (which, j, h, value) in checks {
            let mut moved = screen.clone();
            stats.judge(
                || format!("{} screen {which:?}[{i}][{j}]", case.name),
                value,
                h,
                upstream,
                |offset| {
                    let p = &mut moved.projected[slot];
                    let original = &screen.projected[slot];
                    match which {
                        Screen::Mean2d => p.mean2d[j] = original.mean2d[j] + offset,
                        Screen::Conic => p.conic[j] = original.conic[j] + offset,
                        Screen::Opacity => p.opacity = original.opacity + offset,
                        Screen::Color => p.color[j] = original.color[j] + offset,
                    }
                    render_screen(&moved, cam, settings)
                },
            );
        }
    }
}

/// Prints which non-smooth pieces of the forward the case reached and how its FD checks
/// went (shown with --nocapture).
fn print_case_summary(case: &Case, visible: usize, stats: &FdStats, start: Instant) {
    let cov = coverage(&case.g, &case.cam, &case.settings);
    println!(
        "{}: {} Gaussians ({} visible; Jacobian-clamped {}, alpha-clamped pairs {}, \
         T-stopped pixels {}, color-clamped {}), {} FD-checked ({} nonzero), {} excluded as kinks \
         ({:.2}%), worst |err|/tol {:.3}, {:.1} s",
        case.name,
        case.g.len(),
        visible,
        cov.jacobian_clamped.len(),
        cov.alpha_clamped_pairs,
        cov.t_stopped_pixels,
        cov.color_clamped,
        stats.checked,
        stats.nonzero,
        stats.kinks,
        100.0 * stats.kink_fraction(),
        stats.worst_ratio,
        start.elapsed().as_secs_f64()
    );
}

fn assert_finite(grads: &ParamGrads, name: &str) {
    let flat = |v: &[f64]| v.iter().all(|x| x.is_finite());
    let all = [
        flat(grads.means.as_flattened()),
        flat(grads.log_scales.as_flattened()),
        flat(grads.quats.as_flattened()),
        flat(&grads.opacity_logits),
        flat(&grads.sh),
        flat(&grads.logits),
        flat(grads.mean2d.as_flattened()),
        flat(grads.conic.as_flattened()),
        flat(&grads.opacity),
        flat(grads.color.as_flattened()),
    ];
    assert!(all.iter().all(|&ok| ok), "{name}: non-finite gradient");
}

/// Runs the cases, then asserts no FD mismatch, few kinks and that the checks were not
/// vacuous (most checked gradients nonzero).
fn check_cases(cases: &[Case]) -> FdStats {
    let mut total = FdStats::default();
    for case in cases {
        let stats = check_case(case);
        assert!(
            stats.kink_fraction() <= MAX_KINK_FRACTION,
            "{}: {} of {} values excluded as kinks",
            case.name,
            stats.kinks,
            stats.checked + stats.kinks
        );
        total.add(stats);
    }
    assert!(
        total.failures.is_empty(),
        "{} FD mismatches, first ones:\n{}",
        total.failures.len(),
        total.failures[..total.failures.len().min(20)].join("\n")
    );
    // Guards against a vacuous pass (an empty view, gradients all zero): culled Gaussians,
    // SH bands past a cap and logits with semantics off are legitimately zero, but a fifth
    // of all checked values are not in any case here.
    assert!(
        total.nonzero * 5 > total.checked,
        "too few nonzero gradients were checked: {} of {}",
        total.nonzero,
        total.checked
    );
    total
}

// ---------------------------------------------------------------- tests

#[test]
fn random_scenes_every_sh_degree_channel_count_and_mode() {
    let bg = [0.2, 0.5, 0.9];
    let mut cases = Vec::new();
    let configs = [
        (0, 0, SemanticMode::RawLogits),
        (1, 1, SemanticMode::Softmax),
        (2, 5, SemanticMode::RawLogits),
        (3, 5, SemanticMode::Softmax),
        (3, 1, SemanticMode::RawLogits),
    ];
    for (k, &(degree, channels, mode)) in configs.iter().enumerate() {
        let cam = posed_camera(48, 40);
        cases.push(Case {
            name: format!("posed random (SH {degree}, C {channels}, {mode:?})"),
            g: posed_random_scene(10 + k as u64, 24, &cam, degree, channels),
            cam,
            settings: settings(bg, mode),
            seed: 100 + k as u64,
        });
    }
    // The crate's own generator: camera at the origin looking down +z.
    let g = random_scene(&RandomSceneSpec {
        n: 30,
        sh_degree: 3,
        channels: 5,
        depth: (1.0, 4.0),
        spread: 0.8,
        scale: (0.01, 0.3),
        opacity_logit: (-3.0, 7.0),
        seed: 7,
    });
    cases.push(Case {
        name: "random_scene".into(),
        g,
        cam: axis_camera(64, 48, 50.0),
        settings: settings(bg, SemanticMode::Softmax),
        seed: 200,
    });
    check_cases(&cases);
}

#[test]
fn capped_sh_degree_and_semantics_off() {
    let cam = posed_camera(40, 32);
    let g = posed_random_scene(31, 20, &cam, 3, 5);
    let capped = RenderSettings {
        sh_degree: Some(1),
        ..settings([0.1, 0.0, 0.7], SemanticMode::Softmax)
    };
    let no_semantics = RenderSettings {
        semantics: false,
        ..settings([0.6, 0.3, 0.0], SemanticMode::RawLogits)
    };
    check_cases(&[
        Case {
            name: "sh capped at 1".into(),
            g: g.clone(),
            cam: cam.clone(),
            settings: capped,
            seed: 1,
        },
        Case {
            name: "semantics off".into(),
            g: g.clone(),
            cam: cam.clone(),
            settings: no_semantics,
            seed: 2,
        },
    ]);
    // Coefficients past the cap and logits with semantics off get exactly zero.
    let grads = backward(&g, &cam, &capped, &random_upstream(&cam, 5, 1));
    for i in 0..g.len() {
        let row = &grads.sh[i * 48..(i + 1) * 48];
        assert!(
            row[12..].iter().all(|&v| v == 0.0),
            "degree 2-3 coefficients"
        );
    }
    let grads = backward(&g, &cam, &no_semantics, &random_upstream(&cam, 0, 2));
    assert_eq!(grads.logits.len(), g.len() * 5);
    assert!(grads.logits.iter().all(|&v| v == 0.0));
}

/// Nearly opaque Gaussians stacked along the view axis: alphas at the 0.999 clamp (only
/// where sigma < ln(o / 0.999) < 0.001, i.e. within 0.045 std of a center, hence one huge
/// Gaussian in front whose clamped disc spans ~60 pixels) and pixels that stop at T <= 1e-4
/// behind it, with softer ones in between so the stop moves across pixels.
#[test]
fn deep_overlap_hits_alpha_clamp_and_t_stop() {
    let cam = axis_camera(32, 32, 30.0);
    let mut rng = Rng::new(5);
    let mut specs: Vec<Spec> = (0..12)
        .map(|k| {
            // A 4 x 3 grid of centers 7 px apart, each jittered, deeper row by row.
            let at = (
                5.5 + 7.0 * (k % 4) as f64 + rng.range_f64(-1.0, 1.0),
                9.0 + 7.0 * (k / 4) as f64 + rng.range_f64(-1.0, 1.0),
                1.0 + 0.2 * k as f64,
            );
            let logit = if k % 3 == 2 { 1.0 } else { 12.0 };
            let ls = [(); 3].map(|_| rng.range_f64(-0.6, -0.3) as f32);
            spec_at(&mut rng, &cam, at, ls, logit, 2, 5)
        })
        .collect();
    // In front: std ~ 100 px.
    let huge = spec_at(
        &mut rng,
        &cam,
        (15.3, 16.6, 0.8),
        [1.0, 1.1, 0.9],
        12.0,
        2,
        5,
    );
    specs.push(huge);
    let g = scene(&specs);
    let settings = settings([0.3, 0.3, 0.3], SemanticMode::Softmax);
    let cov = coverage(&g, &cam, &settings);
    assert!(cov.alpha_clamped_pairs >= 5, "{cov:?}");
    assert!(cov.t_stopped_pixels >= 100, "{cov:?}");
    check_cases(&[Case {
        name: "deep overlap".into(),
        g,
        cam,
        settings,
        seed: 3,
    }]);
}

/// Gaussians centered outside the image (beyond the Jacobian's widened frustum) but wide
/// enough to reach into it, and others straddling the border.
#[test]
fn border_and_outside_frustum_hit_jacobian_clamp() {
    let cam = posed_camera(48, 32);
    let (w, h) = (48.0, 32.0);
    let mut rng = Rng::new(9);
    let places = [
        (1.4 * w, 0.5 * h, 2.05),
        (-0.5 * w, 0.3 * h, 1.5),
        (0.5 * w, 1.6 * h, 2.5),
        (0.4 * w, -0.6 * h, 1.8),
        (1.35 * w, 1.4 * h, 2.2),
        (-1.0, 0.5 * h, 3.0),
        (w + 1.0, 0.2 * h, 1.2),
        (0.5 * w, h - 0.5, 2.0),
    ];
    let specs: Vec<Spec> = places
        .iter()
        .map(|&at| {
            let ls = [(); 3].map(|_| rng.range_f64(-1.2, -0.3) as f32);
            spec_at(&mut rng, &cam, at, ls, 3.0, 1, 1)
        })
        .collect();
    let g = scene(&specs);
    let settings = settings([0.0, 0.4, 0.2], SemanticMode::RawLogits);
    let cov = coverage(&g, &cam, &settings);
    assert!(cov.jacobian_clamped.len() >= 4, "{cov:?}");
    check_cases(&[Case {
        name: "border".into(),
        g: g.clone(),
        cam: cam.clone(),
        settings,
        seed: 4,
    }]);
    // The clamped Gaussians' means really received (checked) gradients.
    let grads = backward(&g, &cam, &settings, &random_upstream(&cam, 1, 4));
    for &id in &cov.jacobian_clamped {
        let m = grads.means[id as usize];
        assert!(
            m.iter().any(|v| v.abs() > 1e-6),
            "clamped Gaussian {id}: {m:?}"
        );
    }
}

/// Needle- and disc-like Gaussians (one or two scales e^-12), whose 2D covariance is nearly
/// the 0.3 px^2 dilation alone in one direction, and a color channel clamped at 0.
#[test]
fn degenerate_thin_gaussians_and_color_clamp() {
    let cam = axis_camera(40, 32, 36.0);
    let mut rng = Rng::new(11);
    let shapes: [[f32; 3]; 4] = [
        [-12.0, -0.8, -1.5],
        [-12.0, -12.0, -0.6],
        [-1.0, -12.0, -12.0],
        [-1.5, -1.5, -1.5],
    ];
    let mut specs: Vec<Spec> = shapes
        .iter()
        .enumerate()
        .map(|(k, &ls)| {
            let at = (
                10.0 + 7.0 * k as f64,
                16.0 + 3.0 * k as f64 - 4.0,
                1.5 + 0.4 * k as f64,
            );
            spec_at(&mut rng, &cam, at, ls, 4.0, 3, 5)
        })
        .collect();
    // Strongly negative red DC: red clamps at 0 on the last Gaussian.
    specs[3].sh[0][0] = -4.0;
    let g = scene(&specs);
    let settings = settings([0.5, 0.5, 0.5], SemanticMode::RawLogits);
    let cov = coverage(&g, &cam, &settings);
    assert!(cov.color_clamped >= 1, "{cov:?}");
    assert_eq!(cov.visible, 4, "{cov:?}");
    check_cases(&[Case {
        name: "thin".into(),
        g,
        cam,
        settings,
        seed: 5,
    }]);
}

/// Gaussians the projection culls (behind the near plane, opacity below 1/255, off
/// screen, a NaN mean) get exactly zero gradients, and the FD agree (their parameters move
/// no pixel, so the FD are exactly 0 too).
#[test]
fn culled_gaussians_get_zero_gradients() {
    let cam = posed_camera(32, 32);
    let mut rng = Rng::new(19);
    let mut specs = vec![
        spec_at(&mut rng, &cam, (16.0, 15.0, 2.0), [-2.0; 3], 2.0, 1, 5),
        spec_at(&mut rng, &cam, (16.0, 15.0, -1.0), [-2.0; 3], 2.0, 1, 5),
        spec_at(&mut rng, &cam, (12.0, 18.0, 1.5), [-2.0; 3], -8.0, 1, 5),
        spec_at(&mut rng, &cam, (200.0, 15.0, 2.0), [-3.0; 3], 2.0, 1, 5),
        spec_at(&mut rng, &cam, (16.0, 15.0, 3.0), [-2.0; 3], 2.0, 1, 5),
        spec_at(&mut rng, &cam, (9.0, 20.0, 2.5), [-1.5; 3], 0.5, 1, 5),
        spec_at(&mut rng, &cam, (22.0, 8.0, 1.7), [-1.8; 3], 1.0, 1, 5),
    ];
    specs[4].mean[1] = f32::NAN;
    let g = scene(&specs);
    let settings = settings([0.2, 0.2, 0.2], SemanticMode::Softmax);
    assert_eq!(coverage(&g, &cam, &settings).visible, 3);
    check_cases(&[Case {
        name: "culled".into(),
        g: g.clone(),
        cam: cam.clone(),
        settings,
        seed: 7,
    }]);
    let grads = backward(&g, &cam, &settings, &random_upstream(&cam, 5, 7));
    for i in 1..5 {
        let row = |v: &[f64], k: usize| v[i * k..(i + 1) * k].iter().all(|&x| x == 0.0);
        assert!(row(grads.means.as_flattened(), 3) && row(grads.log_scales.as_flattened(), 3));
        assert!(row(grads.quats.as_flattened(), 4) && row(&grads.opacity_logits, 1));
        assert!(row(&grads.sh, 12) && row(&grads.logits, 5));
        assert!(row(grads.mean2d.as_flattened(), 2) && row(grads.conic.as_flattened(), 3));
        assert!(row(&grads.opacity, 1) && row(grads.color.as_flattened(), 3));
    }
}

/// One Gaussian, every stored parameter: the smallest scene, so a failure is easy to read.
#[test]
fn single_gaussian() {
    let cam = posed_camera(32, 32);
    let mut rng = Rng::new(13);
    let g = scene(&[spec_at(
        &mut rng,
        &cam,
        (15.0, 17.0, 2.0),
        [-2.0, -1.6, -2.4],
        1.5,
        3,
        5,
    )]);
    check_cases(&[Case {
        name: "single".into(),
        g,
        cam,
        settings: settings([0.9, 0.1, 0.4], SemanticMode::Softmax),
        seed: 6,
    }]);
}

/// The SH basis gradient against central differences of the basis itself, at unit and
/// non-unit points (it is the gradient of the polynomials).
#[test]
fn sh_basis_gradient_matches_differences() {
    let mut rng = Rng::new(17);
    for _ in 0..50 {
        let d = DVec3::new(rng.normal(), rng.normal(), rng.normal());
        let grad = sh_basis_grad(d);
        let h = 1e-5;
        for axis in 0..3 {
            let mut step = DVec3::ZERO;
            step[axis] = h;
            let (plus, minus) = (sh_basis(d + step), sh_basis(d - step));
            for k in 0..16 {
                let fd = (plus[k] - minus[k]) / (2.0 * h);
                // Cubic polynomials: the central difference errs by h^2 |f'''| / 6 < 1e-8.
                assert!(
                    (fd - grad[k][axis]).abs() < 1e-8 * (1.0 + d.length_squared()),
                    "basis {k} axis {axis}: {fd} vs {}",
                    grad[k][axis]
                );
            }
        }
    }
}
