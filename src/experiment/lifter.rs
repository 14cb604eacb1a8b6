//! The lifting methods an experiment compares: the fusion methods and joint optimization.

use serde::Serialize;

use crate::fuse::{Method, SPELLINGS};

/// A way to lift labels: a training-free fusion method, or joint optimization.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lifter {
    Fuse(Method),
    /// Joint optimization of the logits only, geometry frozen (`train --semantics-only`).
    JointSemantics,
    /// Joint optimization of geometry, appearance and logits (`train`).
    JointFull,
}

impl Lifter {
    /// The name a method goes by in tables and charts (fusion methods: [`Method::name`]).
    pub fn name(self) -> &'static str {
        match self {
            Lifter::Fuse(method) => method.name(),
            Lifter::JointSemantics => "joint --semantics-only",
            Lifter::JointFull => "joint",
        }
    }

    /// The short name `--methods` takes (fusion methods: [`Method::key`]).
    pub fn key(self) -> &'static str {
        match self {
            Lifter::Fuse(method) => method.key(),
            Lifter::JointSemantics => "joint-semantics",
            Lifter::JointFull => "joint",
        }
    }

    /// The command line the lifter stands for ("fuse --method vote --occlusion").
    pub fn command(self) -> String {
        match self {
            Lifter::Fuse(method) => {
                let s = method.spelling();
                match s.flag {
                    Some(flag) => format!("fuse --method {} --{flag}", s.base),
                    None => format!("fuse --method {}", s.base),
                }
            }
            Lifter::JointSemantics => "train --semantics-only".into(),
            Lifter::JointFull => "train".into(),
        }
    }

    pub fn from_key(key: &str) -> Option<Lifter> {
        ALL_METHODS.into_iter().find(|l| l.key() == key)
    }
}

/// Every lifter: the fusion methods in [`SPELLINGS`] order, then the joint ones.
pub const ALL_METHODS: [Lifter; 9] = [
    Lifter::Fuse(SPELLINGS[0].method),
    Lifter::Fuse(SPELLINGS[1].method),
    Lifter::Fuse(SPELLINGS[2].method),
    Lifter::Fuse(SPELLINGS[3].method),
    Lifter::Fuse(SPELLINGS[4].method),
    Lifter::Fuse(SPELLINGS[5].method),
    Lifter::Fuse(SPELLINGS[6].method),
    Lifter::JointSemantics,
    Lifter::JointFull,
];

/// Iterations of the joint methods in a benchmark (short schedules: the benchmark compares
/// methods at a budget, not joint optimization at convergence).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct JointSchedule {
    pub semantics_only_iters: u32,
    pub full_iters: u32,
    /// Joint full may grow the model to this multiple of the input's Gaussians.
    pub max_growth: f64,
}

impl Default for JointSchedule {
    fn default() -> Self {
        JointSchedule {
            semantics_only_iters: 60,
            full_iters: 60,
            max_growth: 1.5,
        }
    }
}
