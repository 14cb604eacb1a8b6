//! Which methods `demo`, `sweep` and `bench fuse` run, the joint methods' schedule
//! (shared flags), and the room demo and sweep build.

use anyhow::{anyhow, ensure, Result};
use clap::Args;

use super::args;
use semsplat::experiment::{JointSchedule, Lifter, ALL_METHODS};
use semsplat::fuse::Clustering;
use semsplat::synth::{RoomSource, SynthConfig};

#[derive(Args, Clone)]
pub struct MethodArgs {
    #[arg(long, value_delimiter = ',', num_args = 1.., help = methods_help(&ALL_METHODS))]
    methods: Vec<String>,
    /// Iterations of joint-semantics (one view each).
    #[arg(long, default_value_t = JointSchedule::default().semantics_only_iters, value_parser = args::at_least_one::<u32>)]
    semantics_only_iters: u32,
    /// Iterations of full joint training (geometry, appearance and logits).
    #[arg(long, default_value_t = JointSchedule::default().full_iters, value_parser = args::at_least_one::<u32>)]
    joint_iters: u32,
    /// Segment consensus's clustering (`fuse --clustering`), for the consensus methods.
    #[arg(long, value_enum, default_value_t = Clustering::Order)]
    clustering: Clustering,
}

impl MethodArgs {
    pub fn methods(&self) -> Result<Vec<Lifter>> {
        parse_methods(&self.methods, &ALL_METHODS)
    }

    pub fn clustering(&self) -> Clustering {
        self.clustering
    }

    pub fn schedule(&self) -> JointSchedule {
        JointSchedule {
            semantics_only_iters: self.semantics_only_iters,
            full_iters: self.joint_iters,
            ..Default::default()
        }
    }
}

/// `--methods`' help: every key of `known`, with the command each stands for.
pub fn methods_help(known: &[Lifter]) -> String {
    let keys: Vec<String> = known
        .iter()
        .map(|l| format!("{} ({})", l.key(), l.command()))
        .collect();
    format!(
        "Methods to run, comma-separated (default: all): {}",
        keys.join(", ")
    )
}

/// The methods named by `--methods` keys, each one of `known`; no key: all of `known`.
pub fn parse_methods(keys: &[String], known: &[Lifter]) -> Result<Vec<Lifter>> {
    if keys.is_empty() {
        return Ok(known.to_vec());
    }
    let mut methods: Vec<Lifter> = Vec::with_capacity(keys.len());
    for m in keys {
        let lifter = Lifter::from_key(m).filter(|l| known.contains(l));
        let lifter = lifter.ok_or_else(|| {
            let keys: Vec<&str> = known.iter().map(|l| l.key()).collect();
            anyhow!("unknown method '{m}' (known: {})", keys.join(", "))
        })?;
        // Twice would run the same work twice and show it twice.
        ensure!(!methods.contains(&lifter), "--methods names '{m}' twice");
        methods.push(lifter);
    }
    Ok(methods)
}

/// The room of `demo` and `sweep`: `preset` (or a room file) seen by `train_views` +
/// `test_views` cameras of `size` pixels, without label noise.
pub fn room_config(
    preset: &str,
    train_views: usize,
    test_views: usize,
    size: (u32, u32),
    seed: u64,
) -> Result<SynthConfig> {
    let mut cfg = SynthConfig::new(RoomSource::from_arg(preset)?);
    cfg.train_views = train_views;
    cfg.test_views = test_views;
    (cfg.width, cfg.height) = size;
    cfg.seed = seed;
    Ok(cfg)
}
