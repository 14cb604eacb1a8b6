//! `semsplat synth` (placeholder until the scene-formats work lands).

use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct SynthArgs {}

pub fn run(_args: SynthArgs) -> Result<()> {
    bail!("'synth' is not implemented yet")
}
