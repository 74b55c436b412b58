//! The `lodcloth` command line.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{CommandFactory, Parser, Subcommand};

use lodcloth::output::Precision;
use lodcloth::sim::Integrator;

#[derive(Parser)]
#[command(
    name = "lodcloth",
    version = lodcloth::VERSION,
    about = "Mass-spring cloth at several levels of detail"
)]
struct Cli {
    /// Log as JSON lines (for containers and log collectors) instead of text.
    #[arg(long, global = true, env = "LODCLOTH_LOG_JSON", value_parser = clap::builder::FalseyValueParser::new())]
    log_json: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the daemon: cloth instances stepping in real time, published on
    /// zenoh, switching levels on request (config/default.toml by default).
    Serve(serve::ServeArgs),
    /// Run a zenoh router, for daemons and clients in client mode (across
    /// networks, or where peers cannot reach each other directly).
    Router(serve::RouterArgs),
    /// List the instances of every reachable daemon.
    List {
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Live view of an instance's metrics.
    Watch {
        instance: String,
        /// Stop after this many metrics messages.
        #[arg(long)]
        count: Option<u64>,
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Switch an instance to another level (or the cheapest meeting --max-error).
    Switch {
        #[command(flatten)]
        args: serve::SwitchArgs,
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Touch a running cloth: grab, move, release, move a pin, set the
    /// wind, strike it (operators only on a secured daemon).
    Input {
        #[command(flatten)]
        args: input::InputArgs,
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Record an instance's published states to a trajectory file (.lct), or
    /// its Foxglove channels (coloured mesh, metrics) to an MCAP file.
    Record {
        instance: String,
        /// How long to record (wall seconds).
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// Output trajectory file.
        #[arg(long, required_unless_present = "mcap", conflicts_with = "mcap")]
        out: Option<PathBuf>,
        /// Output MCAP file: the channels `lodcloth foxglove` serves, for
        /// Foxglove to open.
        #[arg(long)]
        mcap: Option<PathBuf>,
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Serve a live browser view of the daemon's instances (WebGL mesh
    /// coloured by error or strain, level switches, metrics charts).
    View {
        /// HTTP address of the page.
        #[arg(long, env = "LODCLOTH_VIEW_LISTEN", default_value = "127.0.0.1:8080")]
        listen: std::net::SocketAddr,
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Expose the instances on the Foxglove WebSocket protocol: a coloured
    /// `foxglove.SceneUpdate` mesh and the metrics per instance.
    Foxglove {
        /// Address of the Foxglove WebSocket server.
        #[arg(long, default_value = "127.0.0.1")]
        host: String,
        #[arg(long, default_value_t = 8765)]
        port: u16,
        /// Only this instance (default: every instance).
        #[arg(long)]
        instance: Option<String>,
        /// Meshes per second per instance, at most.
        #[arg(long, default_value_t = 30.0)]
        max_hz: f64,
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Exit 0 when the daemon answers (every instance, or --instance).
    Health {
        #[arg(long)]
        instance: Option<String>,
        #[command(flatten)]
        connect: serve::Connect,
    },
    /// Run a scene and write its trajectory (.lct), a per-frame CSV report, an
    /// energy chart (SVG) and a PNG of the final shape.
    Simulate {
        /// Scene file (TOML).
        #[arg(long)]
        scene: PathBuf,
        /// Nodes per row (default: the scene's).
        #[arg(long)]
        nx: Option<usize>,
        /// Nodes per column (default: the scene's).
        #[arg(long)]
        ny: Option<usize>,
        /// Override the scene's integrator.
        #[arg(long, value_parser = lodcloth::args::integrator_arg)]
        integrator: Option<Integrator>,
        /// Override the scene's time step (s).
        #[arg(long)]
        dt: Option<f64>,
        /// Override the scene's duration (s).
        #[arg(long)]
        duration: Option<f64>,
        /// Output directory (default: out/<scene name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Frames per simulated second written to the trajectory and CSV.
        #[arg(long, default_value_t = 100.0)]
        fps: f64,
        /// Store f64 values in the trajectory (default f32, half the size).
        #[arg(long)]
        f64: bool,
        /// Also store velocities in the trajectory.
        #[arg(long)]
        velocities: bool,
        /// Run even when dt is beyond the integrator's predicted stability limit.
        #[arg(long)]
        force_unstable: bool,
        /// Replay the inputs of a recording (`lodcloth record`, .lct or
        /// .mcap): grabs, moves, pin moves, wind and impulses at the
        /// simulated times they took effect, at this run's level. Without
        /// --duration the run lasts until 1 s after the last input (at
        /// least the scene's duration).
        #[arg(long)]
        inputs: Option<PathBuf>,
        /// The recording's episode to replay (default: the first with inputs).
        #[arg(long, requires = "inputs")]
        episode: Option<u64>,
    },
    /// Point-sampled surfaces: generate, simulate (simplified, moved back to
    /// every point).
    #[command(subcommand)]
    Points(points::Points),
    /// Cloth meshes: write a generated one (disc, sheet, skirt), or read a
    /// file as a scene would and show the level chain it makes.
    #[command(subcommand)]
    Mesh(mesh::Mesh),
    /// Print the header and a summary of a trajectory file.
    Inspect {
        /// Trajectory file (.lct).
        file: PathBuf,
    },
    /// Print a shell completion script, e.g.
    /// `lodcloth completions bash > ~/.local/share/bash-completion/completions/lodcloth`.
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// Write the manual pages (roff): `lodcloth.1` and one per subcommand
    /// (`lodcloth-serve.1`, …) into --out; without it, print `lodcloth.1`.
    Man {
        /// Directory for the pages (created if missing), e.g.
        /// ~/.local/share/man/man1.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

mod input;
mod mesh;
mod points;
mod serve;
mod simulate;

fn main() -> Result<()> {
    let cli = Cli::parse();
    let filter = || tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info,zenoh=warn".into());
    if cli.log_json {
        tracing_subscriber::fmt()
            .json()
            .with_env_filter(filter())
            .with_writer(std::io::stderr)
            .init();
    } else {
        tracing_subscriber::fmt()
            .with_env_filter(filter())
            .with_writer(std::io::stderr)
            .init();
    }
    match cli.command {
        Command::Serve(args) => serve::serve(args),
        Command::Router(args) => serve::router(args),
        Command::List { connect } => serve::list(connect),
        Command::Watch {
            instance,
            count,
            connect,
        } => serve::watch(connect, instance, count),
        Command::Switch { args, connect } => serve::switch(connect, args),
        Command::Input { args, connect } => input::run(connect, args),
        Command::Record {
            instance,
            seconds,
            out,
            mcap,
            connect,
        } => match (out, mcap) {
            (_, Some(mcap)) => serve::record_mcap(connect, instance, seconds, mcap),
            (Some(out), None) => serve::record(connect, instance, seconds, out),
            (None, None) => bail!("give --out FILE.lct or --mcap FILE.mcap"),
        },
        Command::View { listen, connect } => serve::view(connect, listen),
        Command::Foxglove {
            host,
            port,
            instance,
            max_hz,
            connect,
        } => serve::foxglove(connect, host, port, instance, max_hz),
        Command::Health { instance, connect } => serve::health(connect, instance),
        Command::Simulate {
            scene,
            nx,
            ny,
            integrator,
            dt,
            duration,
            out,
            fps,
            f64,
            velocities,
            force_unstable,
            inputs,
            episode,
        } => simulate::simulate(simulate::SimulateArgs {
            scene,
            nx,
            ny,
            integrator,
            dt,
            duration,
            out,
            fps,
            precision: if f64 { Precision::F64 } else { Precision::F32 },
            velocities,
            force_unstable,
            inputs,
            episode,
        }),
        Command::Points(p) => points::run(p),
        Command::Mesh(m) => mesh::run(m),
        Command::Inspect { file } => simulate::inspect(&file),
        Command::Completions { shell } => {
            clap_complete::generate(shell, &mut Cli::command(), "lodcloth", &mut std::io::stdout());
            Ok(())
        }
        Command::Man { out } => man(out),
    }
}

/// `lodcloth man`: every page into `out`, or the top page to stdout.
fn man(out: Option<PathBuf>) -> Result<()> {
    let cmd = Cli::command();
    match out {
        Some(dir) => {
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            clap_mangen::generate_to(cmd, &dir)
                .with_context(|| format!("writing manual pages to {}", dir.display()))?;
            eprintln!("manual pages written to {}", dir.display());
        }
        None => clap_mangen::Man::new(cmd)
            .render(&mut std::io::stdout())
            .context("writing the manual page")?,
    }
    Ok(())
}
