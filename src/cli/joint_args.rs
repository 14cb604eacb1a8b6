//! The joint methods' schedule in `demo` and `sweep` (shared flags).

use clap::Args;

use semsplat::eval::benchmark::JointSchedule;

#[derive(Args, Clone, Copy)]
pub struct JointArgs {
    /// Iterations of `joint --semantics-only` (one view each).
    #[arg(long, default_value_t = JointSchedule::default().semantics_only_iters)]
    semantics_only_iters: u32,
    /// Iterations of full joint training (geometry, appearance and logits).
    #[arg(long, default_value_t = JointSchedule::default().full_iters)]
    joint_iters: u32,
}

impl JointArgs {
    pub fn schedule(&self) -> JointSchedule {
        JointSchedule {
            semantics_only_iters: self.semantics_only_iters,
            full_iters: self.joint_iters,
            ..Default::default()
        }
    }
}
