//! `runner`: the command line. Parses arguments, calls the library, and is the only place
//! that turns results into exit codes: 0 success, 1 internal or I/O error, 2 bad input (CLI or
//! manifest), 3 simulation failed, 130 interrupted.
use clap::{Parser, Subcommand};
use mps_runner::manifest;
use mps_runner::record::Outcome;
use mps_runner::run::{RunOptions, run};
use std::path::PathBuf;
use std::process::ExitCode;

const EXIT_INTERNAL: u8 = 1;
const EXIT_BAD_INPUT: u8 = 2;
const EXIT_SIM_FAILED: u8 = 3;
const EXIT_INTERRUPTED: u8 = 130;

#[derive(Parser, Debug)]
#[command(
    name = "runner",
    version,
    about = "Run an MPS experiment manifest and record it into one MCAP file",
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Experiment manifest (YAML).
    manifest: Option<PathBuf>,
    /// Output directory for the MCAP file.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// Override a manifest field before validation and hashing, e.g. --set spacing_m=0.02
    /// (repeatable; dotted paths).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Worker threads (default: all cores). Results are bitwise identical for any count.
    #[arg(long)]
    threads: Option<usize>,
    /// No progress lines on stderr.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print the SHA-256 experiment hash of a manifest (after --set overrides).
    Hash {
        manifest: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Print the canonical form as well.
        #[arg(long)]
        canonical: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Hash {
            manifest: path,
            set,
            canonical,
        }) => match manifest::load(&path, &set) {
            Ok(resolved) => {
                if canonical {
                    println!("{}", resolved.canonical);
                }
                println!("{}", resolved.hash_hex);
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(EXIT_BAD_INPUT)
            }
        },
        None => run_command(cli.run),
    }
}

fn run_command(args: RunArgs) -> ExitCode {
    let Some(path) = args.manifest else {
        eprintln!(
            "error: no manifest given (usage: runner <MANIFEST> [--out DIR] [--set KEY=VALUE]... [--threads N])"
        );
        return ExitCode::from(EXIT_BAD_INPUT);
    };
    if args.threads == Some(0) {
        eprintln!("error: --threads must be at least 1");
        return ExitCode::from(EXIT_BAD_INPUT);
    }
    let resolved = match manifest::load(&path, &args.set) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_BAD_INPUT);
        }
    };
    let options = RunOptions {
        out_dir: args.out,
        threads: args.threads,
        progress: !args.quiet,
        interrupt: None,
    };
    if !args.quiet {
        eprintln!(
            "{}: experiment {} ({}D, spacing {} m, to t = {} s)",
            resolved.manifest.name,
            resolved.hash_hex,
            resolved.manifest.dimension,
            resolved.manifest.spacing_m,
            resolved.manifest.time.end_s
        );
    }
    match run(&resolved, &options) {
        Ok(result) => {
            let metric = |k: &str| result.summary.metrics.get(k).copied().unwrap_or(f64::NAN);
            let steps = metric("steps");
            let particles = metric("particle_count");
            eprintln!(
                "{}: {} after {} steps, t = {} s; {} particles; wall time {:.2} s ({:.0} particle-steps/s)",
                resolved.manifest.name,
                result.outcome.as_str(),
                steps,
                metric("simulated_time_s"),
                particles,
                result.wall_time_s,
                steps * particles / result.wall_time_s.max(1e-9)
            );
            if !result.summary.reason.is_empty() {
                eprintln!("reason: {}", result.summary.reason);
            }
            println!("{}", result.path.display());
            match result.outcome {
                Outcome::Completed => ExitCode::SUCCESS,
                Outcome::Failed(_) => ExitCode::from(EXIT_SIM_FAILED),
                Outcome::Interrupted(_) => ExitCode::from(EXIT_INTERRUPTED),
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(EXIT_INTERNAL)
        }
    }
}
