//! Small shared utilities.

pub mod atomic_write;
pub mod memory;
pub mod npy;
pub mod parallel;
pub mod rng;

pub use atomic_write::{write_atomic, write_bytes_atomic};
pub use parallel::parallel_map;
pub use rng::Rng;
