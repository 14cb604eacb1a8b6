//! The Gaussian entropy regularizer (Gaussian Semantics Eq. 4-6) and its warm-up. Its value lands
//! in the same values buffer as the image losses, so one download reads them all.

use anyhow::{ensure, Result};

use super::loss::{ImageLoss, LOOP_BUDGET, LOSS_WG};
use super::loss_values::SLOT_ENTROPY;
use crate::contract::params::EntropyParams;
use crate::gpu::kernel_table::ids;
use crate::gpu::{Buffer, Recorder};

/// Most workgroups of the entropy kernel (its partials have a fixed size); each
/// invocation strides over the Gaussians past that.
pub(crate) const ENTROPY_GROUPS: u32 = 4096;

/// lambda_H at iteration `iter`: a linear warm-up from 0 over `warmup_iters` (0: none).
pub fn entropy_weight(lambda_h: f32, iter: u32, warmup_iters: u32) -> f32 {
    if warmup_iters == 0 {
        return lambda_h;
    }
    lambda_h * (iter as f32 / warmup_iters as f32).min(1.0)
}

impl ImageLoss {
    /// Records L_ent = lambda_h * (1/n) sum_i H(softmax(logits_i)), H = -sum p log p >= 0,
    /// over `n` Gaussians of `channels()` logits each (f32 [n * C]), and ADDS
    /// dL_ent/d logits into `grad_logits` (f32 [n * C], accumulated, not overwritten).
    /// Barriers before and after. The unweighted mean entropy is read with
    /// [`ImageLoss::read_values`]; n = 0 records a zero.
    pub fn record_entropy(
        &self,
        rec: &mut Recorder,
        logits: &Buffer,
        n: u32,
        lambda_h: f32,
        grad_logits: &Buffer,
    ) -> Result<()> {
        let channels = self.channels;
        ensure!(
            channels > 0,
            "the entropy regularizer needs semantic channels; this ImageLoss has none"
        );
        let bytes = n as u64 * channels as u64 * 4;
        for (what, buf) in [("logits", logits), ("grad_logits", grad_logits)] {
            ensure!(
                buf.size() >= bytes,
                "{what} holds {} bytes; {n} Gaussians with {channels} channels need {bytes}",
                buf.size()
            );
        }
        if n == 0 {
            rec.barrier();
            rec.fill(&self.values, SLOT_ENTROPY as u64 * 4, 4, 0);
            rec.barrier();
            return Ok(());
        }
        let groups = n.div_ceil(LOSS_WG).min(ENTROPY_GROUPS);
        let per_invocation = n.div_ceil(groups * LOSS_WG) as u64;
        ensure!(
            per_invocation * (4 * channels as u64 + 1) <= LOOP_BUDGET,
            "{n} Gaussians x {channels} channels exceed the entropy kernel's loop budget"
        );
        rec.barrier();
        rec.dispatch(
            ids::TRAIN_ENTROPY,
            &[("partials", &self.partials)],
            &EntropyParams {
                logits_addr: logits.address_words(4)?,
                grad_logits_addr: grad_logits.address_words(4)?,
                n,
                channels,
                stride: self.stride,
                weight: lambda_h / n as f32,
                inv_n: 1.0 / n as f32,
            },
            [groups, 1, 1],
        )?;
        rec.barrier();
        self.record_reduce(rec, SLOT_ENTROPY, 1, groups)?;
        rec.barrier();
        Ok(())
    }
}
