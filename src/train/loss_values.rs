//! The loss values a training loop logs, as the loss kernels leave them on the device:
//! one small buffer of means, read with one download after the submission.

use serde::Serialize;

/// Slot of each value in the values buffer.
pub(crate) use crate::contract::{
    SLOT_CE, SLOT_ENTROPY, SLOT_L1, SLOT_LABELED, SLOT_SE, SLOT_SSIM,
};
/// Slots in the values and partials buffers (two spare).
pub(crate) const SLOTS: u32 = 8;

/// Weights of the photometric loss (3DGS): L_rgb = 0.8 L1 + 0.2 (1 - SSIM).
pub const L1_WEIGHT: f32 = 0.8;
pub const SSIM_WEIGHT: f32 = 0.2;

/// Unweighted means from the last submission that recorded each term.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LossValues {
    /// mean |x - y| over pixels and RGB channels.
    pub l1: f32,
    /// mean SSIM over pixels and RGB channels.
    pub ssim: f32,
    /// mean (x - y)^2 over pixels and RGB channels.
    pub mse: f32,
    /// Mean cross-entropy over the labeled pixels, before lambda_sem (0 when none is).
    pub ce: f32,
    /// Pixels with a label (< channels).
    pub labeled_pixels: u32,
    /// Mean entropy of the Gaussians' class distributions, before lambda_H.
    pub entropy: f32,
}

impl LossValues {
    pub(crate) fn from_slots(v: &[f32]) -> LossValues {
        LossValues {
            l1: v[SLOT_L1 as usize],
            ssim: v[SLOT_SSIM as usize],
            mse: v[SLOT_SE as usize],
            ce: v[SLOT_CE as usize],
            // Counted in float partials, each exact (at most 256); the sum is exact below 2^24.
            labeled_pixels: v[SLOT_LABELED as usize].round() as u32,
            entropy: v[SLOT_ENTROPY as usize],
        }
    }

    /// The photometric loss 0.8 L1 + 0.2 (1 - SSIM).
    pub fn rgb_loss(&self) -> f32 {
        L1_WEIGHT * self.l1 + SSIM_WEIGHT * (1.0 - self.ssim)
    }

    /// The full loss of Gaussian Semantics Eq. 3 with the weights used this iteration.
    pub fn total(&self, lambda_sem: f32, lambda_h: f32) -> f32 {
        self.rgb_loss() + lambda_sem * self.ce + lambda_h * self.entropy
    }

    /// PSNR in dB for images in [0, 1] (infinite for identical images).
    pub fn psnr(&self) -> f32 {
        -10.0 * self.mse.log10()
    }
}

impl LossValues {
    /// The values as a sentence names them (a diverged run's error lists them).
    pub fn listed(&self) -> String {
        format!(
            "L1 {:e}, SSIM {:e}, MSE {:e}, cross-entropy {:e}, entropy {:e}",
            self.l1, self.ssim, self.mse, self.ce, self.entropy
        )
    }

    /// Whether every value is finite (a NaN or infinity means training diverged).
    pub fn is_finite(&self) -> bool {
        [self.l1, self.ssim, self.mse, self.ce, self.entropy]
            .iter()
            .all(|v| v.is_finite())
    }
}
