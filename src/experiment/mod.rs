//! Experiments on synthetic scenes with exact truth: lift the labels with each method
//! (fusion or joint optimization), score the results on held-out views and per Gaussian,
//! and follow mislabeled objects. Behind `semsplat demo` and `sweep`; the metrics
//! themselves live in `crate::eval`.

pub mod lifter;
pub mod mislabel;
pub mod oracle;
pub mod score;

pub use lifter::{JointSchedule, Lifter, ALL_METHODS};
pub use mislabel::{mislabel_follow, MislabelFollow};
pub use oracle::{instance_oracle_classes, score_instance_oracle, ORACLE_NAME};
pub use score::{
    held_out_quality, held_out_segmentation, score_methods, synth_train_views, LiftedScene,
    MethodScore, TrainLabels,
};
