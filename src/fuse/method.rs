//! The training-free lifting methods and how they are named. [`SPELLINGS`] is the one
//! source of every name: the display name ("vote --occlusion", as `fuse` reports it), the
//! `--methods` key ("vote-occlusion", demo, sweep and bench fuse) and the `fuse` flags
//! (`--method vote --occlusion`) are all built from a base method and a variant flag.

use serde::Serialize;

use crate::render::gpu_scene::SceneAttributes;

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
    /// Segment consensus: neighbouring Gaussians that share a connected label region in the
    /// views that see both form 3D segments; each segment's class is voted with every view
    /// counting once, and each Gaussian takes its segment's class (src/fuse/consensus.rs).
    /// Robust to per-view label flicker.
    SegmentConsensus,
    /// Segment consensus, then FlashSplat on every view's label regions relabeled with the
    /// consensus classes of the Gaussians observed in them (src/fuse/consensus_relabel.rs):
    /// the consensus decides what an object is, the pixels each Gaussian covers where its
    /// edges are.
    SegmentConsensusRelabel,
}

impl Method {
    /// What of the scene the method reads, so only that is uploaded: plain vote projects
    /// the centers; the others project and blend shapes and opacities but never colour.
    pub fn scene_attributes(self) -> SceneAttributes {
        match self {
            Method::Vote => SceneAttributes::Centers,
            _ => SceneAttributes::Geometry,
        }
    }

    /// Whether the method builds 3D segments (and flags them): `segment-consensus` and its
    /// `--relabel` variant.
    pub fn is_consensus(self) -> bool {
        matches!(
            self,
            Method::SegmentConsensus | Method::SegmentConsensusRelabel
        )
    }

    /// Whether the method's visibility test reads `--depth-tol`: the occlusion-checked vote
    /// and the consensus methods (the others weigh every Gaussian a pixel blends).
    pub fn reads_depth_tolerance(self) -> bool {
        self == Method::VoteOcclusion || self.is_consensus()
    }

    /// Whether `--float-atomics` (float sums instead of fixed point) changes how the method
    /// sums: the votes are integers, and segment consensus counts views on the host
    /// (`--relabel`'s FlashSplat sums do read it).
    pub fn reads_accumulation(self) -> bool {
        !matches!(
            self,
            Method::Vote | Method::VoteOcclusion | Method::SegmentConsensus
        )
    }

    /// Whether the method accumulates over each view's tile lists (alpha * T per pixel and
    /// Gaussian), as the weighted vote and FlashSplat do.
    pub fn is_tiled(self) -> bool {
        matches!(
            self,
            Method::VoteWeighted | Method::FlashSplat | Method::FlashSplatPerView
        )
    }
}

/// How one method is spelled everywhere.
#[derive(Clone, Copy, Debug)]
pub struct Spelling {
    pub method: Method,
    /// `fuse --method <base>`.
    pub base: &'static str,
    /// The variant flag of `fuse` (without its dashes), if the method is a variant.
    pub flag: Option<&'static str>,
    /// "<base> --<flag>": how `fuse` and the reports name the method.
    pub name: &'static str,
    /// "<base>-<flag>": how `--methods` takes it.
    pub key: &'static str,
}

/// Builds each spelling from the base and flag, so the name and key cannot disagree.
macro_rules! spellings {
    ($($method:ident: $base:literal $(--$flag:literal)?;)*) => {
        [$(Spelling {
            method: Method::$method,
            base: $base,
            flag: spellings!(@flag $($flag)?),
            name: concat!($base $(, " --", $flag)?),
            key: concat!($base $(, "-", $flag)?),
        }),*]
    };
    (@flag) => { None };
    (@flag $flag:literal) => { Some($flag) };
}

/// Every method, in the order tables and charts list them.
pub const SPELLINGS: [Spelling; 7] = spellings! {
    Vote: "vote";
    VoteOcclusion: "vote" --"occlusion";
    VoteWeighted: "vote" --"weighted";
    FlashSplat: "flashsplat";
    FlashSplatPerView: "flashsplat" --"per-view";
    SegmentConsensus: "segment-consensus";
    SegmentConsensusRelabel: "segment-consensus" --"relabel";
};

impl Method {
    pub fn spelling(self) -> &'static Spelling {
        SPELLINGS
            .iter()
            .find(|s| s.method == self)
            .expect("every method has a spelling")
    }

    /// How the CLI spells the method ("vote --occlusion").
    pub fn name(self) -> &'static str {
        self.spelling().name
    }

    /// The short name `--methods` takes ("vote-occlusion").
    pub fn key(self) -> &'static str {
        self.spelling().key
    }

    pub fn from_key(key: &str) -> Option<Method> {
        SPELLINGS.iter().find(|s| s.key == key).map(|s| s.method)
    }

    /// The method `fuse --method <base>` with the variant `flags` given selects. A flag of
    /// another base is an error naming that base's variants; of several variants of the
    /// same base, the first in [`SPELLINGS`] wins.
    pub fn from_flags(base: &str, flags: &[&str]) -> Result<Method, String> {
        for &flag in flags {
            let owner = SPELLINGS
                .iter()
                .find(|s| s.flag == Some(flag))
                .ok_or_else(|| format!("unknown variant flag --{flag}"))?;
            if owner.base != base {
                return Err(variants_error(owner.base));
            }
        }
        SPELLINGS
            .iter()
            .filter(|s| s.base == base)
            .find(|s| s.flag.is_some_and(|f| flags.contains(&f)))
            .or_else(|| {
                SPELLINGS
                    .iter()
                    .find(|s| s.base == base && s.flag.is_none())
            })
            .map(|s| s.method)
            .ok_or_else(|| format!("unknown method '{base}'"))
    }
}

/// "--a is a variant of --method b", or "--a and --c are variants of --method b".
fn variants_error(base: &str) -> String {
    let flags: Vec<String> = SPELLINGS
        .iter()
        .filter(|s| s.base == base)
        .filter_map(|s| s.flag.map(|f| format!("--{f}")))
        .collect();
    if flags.len() == 1 {
        format!("{} is a variant of --method {base}", flags[0])
    } else {
        format!("{} are variants of --method {base}", flags.join(" and "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spellings_derive_from_base_and_flag() {
        assert_eq!(Method::VoteOcclusion.name(), "vote --occlusion");
        assert_eq!(Method::VoteOcclusion.key(), "vote-occlusion");
        assert_eq!(Method::FlashSplat.name(), "flashsplat");
        assert_eq!(
            Method::from_flags("flashsplat", &["per-view"]),
            Ok(Method::FlashSplatPerView)
        );
        assert_eq!(
            Method::from_flags("vote", &["per-view"]).unwrap_err(),
            "--per-view is a variant of --method flashsplat"
        );
        assert_eq!(
            Method::from_flags("flashsplat", &["weighted"]).unwrap_err(),
            "--occlusion and --weighted are variants of --method vote"
        );
        for s in SPELLINGS {
            assert_eq!(Method::from_key(s.key), Some(s.method));
        }
    }
}
