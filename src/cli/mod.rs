//! One module per subcommand.

pub mod bench;
pub mod fuse;
pub mod info;
pub mod inspect;
pub mod render;
pub mod synth;
