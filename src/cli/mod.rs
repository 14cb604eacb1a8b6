//! One module per subcommand.

pub mod bench;
pub mod demo;
pub mod eval;
pub mod fuse;
pub mod info;
pub mod inspect;
pub mod joint_args;
pub mod progress;
pub mod render;
pub mod sweep;
pub mod synth;
pub mod train;
