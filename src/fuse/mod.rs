//! Training-free lifting: majority vote (Semantic Fusion) and FlashSplat's optimal assignment
//! (docs/papers.md), from per-view label maps to a class per Gaussian.

pub mod accumulate;
pub mod assign;
pub mod method;
pub mod partial;
pub mod scores;

pub use accumulate::{
    accumulate, accumulate_raw, Accumulation, FuseConfig, FuseStats, LabelSource, NO_LABEL,
};
pub use assign::{assign_one_vs_rest, assign_semantic, Assignment};
pub use method::{Method, SPELLINGS};
pub use partial::{EvidenceKind, PartManifest, RawEvidence, Shard};
pub use scores::ClassScores;
