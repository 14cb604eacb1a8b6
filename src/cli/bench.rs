//! `semsplat bench`.
use anyhow::Result;
use clap::Subcommand;

#[derive(Subcommand)]
pub enum BenchCommand {
    Sort,
}

pub fn run(_cmd: BenchCommand) -> Result<()> {
    Ok(())
}
