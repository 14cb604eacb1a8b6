//! Adam on the device, one parameter tensor per call (as torch.optim.Adam, which 3DGS
//! uses), and the 3DGS exponential learning-rate schedule for the positions.

use anyhow::{ensure, Result};

use crate::contract::params::AdamParams;
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Gpu, Recorder};
use crate::render::chunks::{chunks, part_of};

/// Most workgroups of one Adam dispatch; invocations stride over larger tensors.
const MAX_GROUPS: u32 = 65_535;

/// The hyper-parameters of one step. `step` counts from 1 (the first update). In f64:
/// the kernel gets lr / (1 - beta1^t), 1 - beta and the like rounded once from these.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamStep {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    pub step: u32,
}

impl AdamStep {
    /// 3DGS's settings: betas (0.9, 0.999), eps 1e-15.
    pub fn new(lr: f64, step: u32) -> AdamStep {
        AdamStep {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
            step,
        }
    }
}

/// One parameter tensor and its optimizer state, all f32 [count].
#[derive(Clone, Copy)]
pub struct AdamTensor<'a> {
    /// Updated in place.
    pub param: &'a Buffer,
    /// Read only: the caller zeroes it for the next iteration.
    pub grad: &'a Buffer,
    /// First moment, updated in place (zero before the first step).
    pub exp_avg: &'a Buffer,
    /// Second moment, updated in place (zero before the first step).
    pub exp_avg_sq: &'a Buffer,
    /// Elements to update (the buffers may be larger).
    pub count: u32,
}

/// Zeroed Adam moments for a tensor of `count` floats.
pub struct AdamMoments {
    pub exp_avg: Buffer,
    pub exp_avg_sq: Buffer,
}

impl AdamMoments {
    pub fn new(gpu: &Gpu, name: &str, count: u32) -> Result<AdamMoments> {
        let bytes = count as u64 * 4;
        let exp_avg = gpu.buffer(&format!("{name}-exp-avg"), bytes)?;
        let exp_avg_sq = gpu.buffer(&format!("{name}-exp-avg-sq"), bytes)?;
        let mut rec = Recorder::new(gpu)?;
        rec.fill(&exp_avg, 0, exp_avg.size(), 0);
        rec.fill(&exp_avg_sq, 0, exp_avg_sq.size(), 0);
        rec.submit_and_wait()?;
        Ok(AdamMoments {
            exp_avg,
            exp_avg_sq,
        })
    }
}

/// Records one Adam step on `t`: m = b1 m + (1-b1) g, v = b2 v + (1-b2) g^2,
/// param -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps). Barriers before (the
/// gradient written earlier in `rec` is seen) and after (the new parameters are).
pub fn record_adam(rec: &mut Recorder, t: &AdamTensor<'_>, s: AdamStep) -> Result<()> {
    ensure!(s.step >= 1, "Adam steps count from 1 (got {})", s.step);
    let bytes = t.count as u64 * 4;
    for (what, buf) in [
        ("param", t.param),
        ("grad", t.grad),
        ("exp_avg", t.exp_avg),
        ("exp_avg_sq", t.exp_avg_sq),
    ] {
        ensure!(
            buf.size() >= bytes,
            "Adam {what} ({}) holds {} bytes; {} floats need {bytes}",
            buf.name(),
            buf.size(),
            t.count
        );
    }
    if t.count == 0 {
        return Ok(());
    }
    // Bias corrections in f64: beta2^t stays accurate for large t.
    let bc1 = 1.0 - s.beta1.powf(s.step as f64);
    let bc2 = 1.0 - s.beta2.powf(s.step as f64);
    let params = AdamParams {
        count: t.count,
        beta1: s.beta1 as f32,
        beta2: s.beta2 as f32,
        one_minus_beta1: (1.0 - s.beta1) as f32,
        one_minus_beta2: (1.0 - s.beta2) as f32,
        eps: s.eps as f32,
        step_size: (s.lr / bc1) as f32,
        sqrt_bc2: bc2.sqrt() as f32,
    };
    rec.barrier();
    // Element-wise: a tensor past one binding (the SH coefficients of a million Gaussians)
    // is updated in parts that each fit one.
    let caps = rec.gpu().caps();
    let granule = (caps.min_storage_offset_alignment / 4).max(1);
    let part_len = (caps.max_storage_buffer_range / 4 / granule * granule).min(u32::MAX as u64);
    for part in chunks(t.count, part_len as u32) {
        let range = |buf| part_of(buf, &part, 4);
        let params = AdamParams {
            count: part.len() as u32,
            ..params
        };
        rec.dispatch_ranges(
            ids::TRAIN_ADAM,
            &[
                ("param", range(t.param)),
                ("grad", range(t.grad)),
                ("exp_avg", range(t.exp_avg)),
                ("exp_avg_sq", range(t.exp_avg_sq)),
            ],
            &params,
            [
                ids::TRAIN_ADAM.groups_for(params.count)[0].min(MAX_GROUPS),
                1,
                1,
            ],
        )?;
    }
    rec.barrier();
    Ok(())
}

/// The 3DGS learning-rate schedule (get_expon_lr_func): log-linear from `lr_init` at step
/// 0 to `lr_final` at `max_steps` (constant after), times an optional warm-up delay that
/// starts at `delay_mult` and eases to 1 over `delay_steps` (0: no delay).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExponentialLr {
    pub lr_init: f64,
    pub lr_final: f64,
    pub delay_steps: u32,
    pub delay_mult: f64,
    pub max_steps: u32,
}

impl ExponentialLr {
    /// 3DGS's position schedule: 1.6e-4 to 1.6e-6 times the scene extent, no delay.
    pub fn positions(spatial_scale: f64, max_steps: u32) -> ExponentialLr {
        ExponentialLr {
            lr_init: 1.6e-4 * spatial_scale,
            lr_final: 1.6e-6 * spatial_scale,
            delay_steps: 0,
            delay_mult: 0.01,
            max_steps,
        }
    }

    /// The learning rate at `step`.
    pub fn at(&self, step: u32) -> f64 {
        if self.lr_init == 0.0 && self.lr_final == 0.0 {
            return 0.0;
        }
        let delay = if self.delay_steps > 0 {
            let s = (step as f64 / self.delay_steps as f64).clamp(0.0, 1.0);
            self.delay_mult + (1.0 - self.delay_mult) * (0.5 * std::f64::consts::PI * s).sin()
        } else {
            1.0
        };
        // No steps to decay over: already at the end.
        let t = if self.max_steps == 0 {
            1.0
        } else {
            (step as f64 / self.max_steps as f64).clamp(0.0, 1.0)
        };
        delay * (self.lr_init.ln() * (1.0 - t) + self.lr_final.ln() * t).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_is_log_linear_between_its_ends() {
        let s = ExponentialLr::positions(2.0, 30_000);
        assert!((s.at(0) - 3.2e-4).abs() < 1e-15);
        assert!((s.at(30_000) - 3.2e-6).abs() < 1e-17);
        assert_eq!(s.at(40_000), s.at(30_000));
        // Halfway in steps is the geometric mean of the ends.
        assert!((s.at(15_000) - (3.2e-4f64 * 3.2e-6).sqrt()).abs() < 1e-16);
    }

    #[test]
    fn schedule_delay_eases_in() {
        let s = ExponentialLr {
            lr_init: 1e-2,
            lr_final: 1e-2,
            delay_steps: 100,
            delay_mult: 0.1,
            max_steps: 1000,
        };
        assert!((s.at(0) - 1e-3).abs() < 1e-15);
        let mid = 0.1 + 0.9 * (0.25 * std::f64::consts::PI).sin();
        assert!((s.at(50) - 1e-2 * mid).abs() < 1e-15);
        assert!((s.at(100) - 1e-2).abs() < 1e-15);
        assert!((s.at(500) - 1e-2).abs() < 1e-15);
    }

    #[test]
    fn schedule_with_zero_rates_is_zero() {
        let s = ExponentialLr {
            lr_init: 0.0,
            lr_final: 0.0,
            delay_steps: 0,
            delay_mult: 1.0,
            max_steps: 10,
        };
        assert_eq!(s.at(5), 0.0);
    }
}
