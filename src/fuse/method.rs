//! The training-free lifting methods and how they are named.

use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Majority vote of the projected centers.
    Vote,
    /// Votes only where the center is visible: its depth within a tolerance of the
    /// rendered expected depth at that pixel.
    VoteOcclusion,
    /// Votes weighted by the Gaussian's alpha * T at the pixel holding its center.
    VoteWeighted,
    /// FlashSplat: alpha * T of every Gaussian at every labeled pixel.
    FlashSplat,
    /// FlashSplat with each view's weights divided by the Gaussian's projected footprint in
    /// that view (2 pi opacity sqrt(det Sigma2d)): a view adds the share of the Gaussian it
    /// sees under each label, so every view counts about once, as in a vote, instead of in
    /// proportion to the pixels it covers. Robust to per-view label flicker.
    FlashSplatPerView,
}

impl Method {
    /// How the CLI spells the method.
    pub fn name(self) -> &'static str {
        match self {
            Method::Vote => "vote",
            Method::VoteOcclusion => "vote --occlusion",
            Method::VoteWeighted => "vote --weighted",
            Method::FlashSplat => "flashsplat",
            Method::FlashSplatPerView => "flashsplat --per-view",
        }
    }
}
