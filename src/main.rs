//! The `voltab` command line: parses the arguments ([`cli::args`]) and runs the command ([`cli`]).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    if let Some(code) = voltab::scene::usd_import::guarded_child_main() {
        return code; // the hidden USD import child (scene::usd_import::guard)
    }
    let cli = cli::args::Cli::parse();
    match cli::dispatch(cli.command) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("{e:#}");
            ExitCode::FAILURE
        }
    }
}
