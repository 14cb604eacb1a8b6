//! Training-free lifting: majority vote (Semantic Fusion), FlashSplat's optimal assignment
//! (docs/papers.md) and segment consensus, from per-view label maps to a class per Gaussian.

pub mod accumulate;
pub mod assign;
pub mod consensus;
pub mod consensus_decide;
pub mod consensus_segments;
pub mod method;
pub mod partial;
pub mod scores;

pub use accumulate::{
    accumulate, accumulate_raw, Accumulation, FuseConfig, FuseStats, LabelSource, LANES, NO_LABEL,
};
pub use assign::{assign_one_vs_rest, assign_semantic, assign_semantic_near, Assignment};
pub use consensus::fuse_consensus;
pub use consensus_decide::{Consensus, ConsensusParams, SegmentVotes};
pub use consensus_segments::nearest_neighbours;
pub use method::{Method, SPELLINGS};
pub use partial::{EvidenceKind, PartManifest, RawEvidence, Shard};
pub use scores::ClassScores;
