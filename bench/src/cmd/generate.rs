//! `probe-bench generate-captures` (hidden): rewrite the golden captures of `tests/data/`.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct GenerateArgs {
    /// Directory to write into (the repository's `tests/data`).
    #[arg(long, default_value = "tests/data")]
    pub out_dir: PathBuf,
}

/// Run the subcommand.
pub fn run(a: GenerateArgs) -> Result<()> {
    for name in crate::gen::write_golden(&a.out_dir)? {
        println!("{}", a.out_dir.join(name).display());
    }
    Ok(())
}
