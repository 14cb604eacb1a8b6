//! Small shared utilities.

pub mod atomic_write;
pub mod interrupt;
pub mod memory;
pub mod npy;
pub mod parallel;
pub mod quad_heap;
pub mod rng;

pub use atomic_write::{
    check_output_file, check_output_folder, stage_atomic, write_atomic, write_bytes_atomic,
    StagedFile,
};
pub use parallel::{parallel_map, prefetch_ordered, split_parts, take_part};
pub use rng::Rng;
