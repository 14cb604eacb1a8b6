//! Training-free lifting: majority vote (Semantic Fusion), FlashSplat's optimal assignment
//! (docs/papers.md) and segment consensus, from per-view label maps to a class per Gaussian.

pub mod accumulate;
pub mod assign;
pub mod assign_gpu;
pub mod consensus;
pub mod consensus_adjacent;
pub mod consensus_cluster;
pub mod consensus_confusion;
pub mod consensus_decide;
pub mod consensus_flags;
pub mod consensus_footprints;
pub mod consensus_observe;
pub mod consensus_order;
pub mod consensus_region_votes;
pub mod consensus_relabel;
pub mod consensus_report;
pub mod consensus_segments;
pub mod consensus_split;
pub mod consensus_surface;
pub mod method;
pub mod neighbours;
pub mod partial;
pub mod regions_gpu;
pub mod scores;
pub mod shared_counts;

pub use accumulate::{
    accumulate, accumulate_assigned, accumulate_raw, evidence_passes, gpu_assignable, Accumulation,
    AssignOnGpu, FuseConfig, FuseStats, LabelSource, ObserveTimes, RowSink, TieNeighbours, LANES,
    MAX_LANES, NO_LABEL,
};
pub use assign::{
    assign_counts_near, assign_one_vs_rest, assign_semantic, assign_semantic_near, class_totals,
    one_vs_rest_row, Assignment, TIE_NEIGHBOURS,
};
pub use consensus::{fuse_consensus, lift_by_consensus, ConsensusInput, ConsensusLift};
pub use consensus_cluster::ClusterProfile;
pub use consensus_decide::{Clustering, Consensus, ConsensusParams, DecideProfile, SegmentVotes};
pub use consensus_surface::GaussianShapes;
pub use method::{Method, SPELLINGS};
pub use neighbours::nearest_neighbours;
pub use partial::{EvidenceKind, PartManifest, RawEvidence, Shard};
pub use scores::{ClassScores, EvidenceRows, SpilledRows};
pub use shared_counts::{SharedCounts, SumsByGaussian};
