//! `lodcloth-lab`: the studies, each writing its CSV, markdown and charts.
//! The service's own commands are `lodcloth`'s.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

use lodcloth::args::points::ModelArgs;

mod cli;

#[derive(Parser)]
#[command(
    name = "lodcloth-lab",
    version = lodcloth::VERSION,
    about = "lodcloth's studies: Table 1 and its readings, Pareto fronts, level planning, \
             generalisation, touched sessions, switch tests, stability sweeps, point-surface accuracy"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    #[command(flatten)]
    Lod(cli::experiment::Experiment),
    /// Measure each integrator's stability threshold by bisection over dt and
    /// stiffness/mass ratios; write CSV and an SVG chart of predicted vs measured.
    Stability {
        /// Scene whose material is used.
        #[arg(long, default_value = "config/scenes/hanging.toml")]
        scene: PathBuf,
        /// Square grid sizes, comma separated.
        #[arg(long, value_delimiter = ',', default_values_t = vec![8usize, 16])]
        sizes: Vec<usize>,
        /// Stiffness multipliers, comma separated.
        #[arg(long, value_delimiter = ',', default_values_t = vec![0.25, 1.0, 4.0, 16.0])]
        factors: Vec<f64>,
        /// Steps per trial.
        #[arg(long, default_value_t = 3000)]
        steps: u32,
        /// Bisection iterations per threshold.
        #[arg(long, default_value_t = 14)]
        bisections: u32,
        /// Output directory.
        #[arg(long, default_value = "out/stability")]
        out: PathBuf,
    },
    /// A point-sampled surface's accuracy against simplification size: each
    /// size simulated, moved back to all points and compared with the
    /// simulation of every point (CSV + SVG charts of error vs size and
    /// error vs cost).
    PointsAccuracy {
        #[command(flatten)]
        model: ModelArgs,
        /// Simulation point counts, comma separated.
        #[arg(long, value_delimiter = ',', default_values_t = vec![85usize, 150, 273, 327, 600, 1000, 1600])]
        sizes: Vec<usize>,
        /// Simulated seconds.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
        /// Frames compared per simulated second.
        #[arg(long, default_value_t = 50.0)]
        fps: f64,
        /// Also fit the stretch and bend stiffness of every size to the
        /// reference's first half and score it (held-out second half reported).
        #[arg(long)]
        fit: bool,
        #[arg(long, default_value = "out/points-accuracy")]
        out: PathBuf,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()))
        .with_writer(std::io::stderr)
        .init();
    match cli.command {
        Command::Lod(e) => cli::experiment::run(e),
        Command::Stability {
            scene,
            sizes,
            factors,
            steps,
            bisections,
            out,
        } => cli::stability::stability(&scene, sizes, factors, steps, bisections, &out),
        Command::PointsAccuracy {
            model,
            sizes,
            seconds,
            fps,
            fit,
            out,
        } => cli::points_accuracy::accuracy(&model, &sizes, seconds, fps, fit, &out),
    }
}
