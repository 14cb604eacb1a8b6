//! `semsplat inspect` (placeholder until the scene-formats work lands).

use anyhow::{bail, Result};
use clap::Args;

#[derive(Args)]
pub struct InspectArgs {}

pub fn run(_args: InspectArgs) -> Result<()> {
    bail!("'inspect' is not implemented yet")
}
