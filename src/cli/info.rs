//! `semsplat info`.
use anyhow::Result;
use clap::Args;

#[derive(Args)]
pub struct InfoArgs {}

pub fn run(_args: InfoArgs) -> Result<()> {
    Ok(())
}
