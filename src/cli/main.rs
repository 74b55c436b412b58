//! The `lodcloth` command line.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use tracing::info;

use lodcloth::experiments::{stability_sweep, StabilityRow, StabilitySweep};
use lodcloth::output::{
    line_chart_svg, render_png, report_csv_line, Precision, Series, TrajectoryReader, TrajectoryWriter, PALETTE,
    REPORT_CSV_HEADER,
};
use lodcloth::scene::Scene;
use lodcloth::sim::{Integrator, StabilityCheck};

#[derive(Parser)]
#[command(name = "lodcloth", version, about = "Mass-spring cloth at several levels of detail")]
struct Cli {
    /// Log as JSON lines (for containers and log collectors) instead of text.
    #[arg(long, global = true, env = "LODCLOTH_LOG_JSON", value_parser = clap::builder::FalseyValueParser::new())]
    log_json: bool,
    #[command(subcommand)]
    command: Command,
}

/// Command-line integrator names: the config files' names, `-` allowed for `_`.
pub(crate) fn integrator_arg(name: &str) -> Result<Integrator, lodcloth::names::UnknownName> {
    lodcloth::names::parse_arg(name)
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
        #[arg(long, value_parser = integrator_arg)]
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
    },
    /// Measure each integrator's stability threshold by bisection over dt and
    /// stiffness/mass ratios; write CSV and an SVG chart of predicted vs measured.
    Stability {
        /// Scene whose material is used (default config/scenes/hanging.toml).
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
    /// Level-of-detail experiments: table1, pareto, lod-plan, switch-test.
    #[command(subcommand)]
    Experiment(experiment::Experiment),
    /// Point-sampled surfaces: generate, simulate (simplified, moved back to
    /// every point), accuracy against simplification size.
    #[command(subcommand)]
    Points(points::Points),
    /// Print the header and a summary of a trajectory file.
    Inspect {
        /// Trajectory file (.lct).
        file: PathBuf,
    },
}

mod experiment;
mod points;
mod serve;

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
        } => simulate(SimulateArgs {
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
        }),
        Command::Stability {
            scene,
            sizes,
            factors,
            steps,
            bisections,
            out,
        } => stability(&scene, sizes, factors, steps, bisections, &out),
        Command::Experiment(e) => experiment::run(e),
        Command::Points(p) => points::run(p),
        Command::Inspect { file } => inspect(&file),
    }
}

struct SimulateArgs {
    scene: PathBuf,
    nx: Option<usize>,
    ny: Option<usize>,
    integrator: Option<Integrator>,
    dt: Option<f64>,
    duration: Option<f64>,
    out: Option<PathBuf>,
    fps: f64,
    precision: Precision,
    velocities: bool,
    force_unstable: bool,
}

pub(crate) fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta} left)")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

fn simulate(a: SimulateArgs) -> Result<()> {
    let mut scene = Scene::load(&a.scene)?;
    if let Some(i) = a.integrator {
        scene.params.integrator = i;
    }
    if let Some(dt) = a.dt {
        scene.params.dt = dt;
    }
    if let Some(d) = a.duration {
        if !(d.is_finite() && d > 0.0) {
            bail!("--duration must be positive, got {d}");
        }
        scene.duration = d;
    }
    if a.force_unstable {
        scene.stability = StabilityCheck::Force;
    }
    if !(a.fps.is_finite() && a.fps > 0.0) {
        bail!("--fps must be positive, got {}", a.fps);
    }
    let (nx, ny) = (a.nx.unwrap_or(scene.nx), a.ny.unwrap_or(scene.ny));
    let mut sim = scene.build_at(nx, ny)?;
    let dt = sim.params().dt;
    let steps = scene.steps();
    let frame_every = ((1.0 / a.fps / dt).round() as u64).max(1);
    let out = a.out.unwrap_or_else(|| PathBuf::from("out").join(&scene.name));
    fs::create_dir_all(&out).with_context(|| format!("cannot create output directory {}", out.display()))?;
    let modal = *sim.modal();
    info!(
        scene = %scene.name, nx, ny, integrator = %sim.params().integrator, dt, steps,
        springs = sim.topology().spring_count(),
        omega_max = format_args!("{:.0}", modal.omega_max),
        dt_limit = format_args!("{:.3e}", sim.dt_limit()),
        "simulating"
    );

    let traj_path = out.join("trajectory.lct");
    let mut traj = TrajectoryWriter::create(
        &traj_path,
        sim.topology().n_nodes,
        Some((nx, ny)),
        dt,
        u32::try_from(frame_every).context("frame interval too large")?,
        a.precision,
        a.velocities,
    )?;
    let csv_path = out.join("report.csv");
    let mut csv = std::io::BufWriter::new(
        fs::File::create(&csv_path).with_context(|| format!("cannot create {}", csv_path.display()))?,
    );
    writeln!(csv, "{REPORT_CSV_HEADER}")?;
    traj.write(sim.state())?;

    let bar = progress_bar(steps, "simulating");
    let mut energy: [Vec<(f64, f64)>; 3] = Default::default();
    let started = Instant::now();
    let mut last_log = Instant::now();
    let mut last = None;
    let mut first_total = None;
    for s in 1..=steps {
        let r = sim.step();
        last = Some(r);
        if !r.finite {
            bar.abandon();
            traj.finish()?;
            csv.flush()?;
            bail!(
                "the simulation diverged at step {} (t = {:.4} s): a position or velocity became non-finite; \
                 lower dt (predicted limit {:.3e} s) or use implicit_euler",
                r.step,
                r.time,
                sim.dt_limit()
            );
        }
        if s % frame_every == 0 || s == steps {
            traj.write(sim.state())?;
            writeln!(csv, "{}", report_csv_line(&r))?;
            energy[0].push((r.time, r.kinetic_energy));
            energy[1].push((r.time, r.elastic_energy));
            let e0 = *first_total.get_or_insert(r.total_energy());
            energy[2].push((r.time, r.total_energy() - e0));
            bar.set_position(s);
            if bar.is_hidden() && last_log.elapsed().as_secs() >= 5 {
                info!(step = s, of = steps, "progress {:.0}%", 100.0 * s as f64 / steps as f64);
                last_log = Instant::now();
            }
        }
    }
    bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    let header = traj.finish()?;
    csv.flush()?;

    let pinned: Vec<u32> = sim.loads().pins.iter().map(|p| p.node).collect();
    let png = out.join("final.png");
    render_png(&png, sim.topology(), sim.state(), &pinned, 800)?;
    let svg = out.join("energy.svg");
    line_chart_svg(
        &svg,
        &format!(
            "{} — energy ({}, dt = {:e} s, {}×{})",
            scene.name,
            sim.params().integrator,
            dt,
            nx,
            ny
        ),
        "time (s)",
        "energy (J)",
        &[
            Series {
                name: "kinetic",
                points: energy[0].clone(),
                markers: false,
                color: PALETTE[0],
            },
            Series {
                name: "elastic",
                points: energy[1].clone(),
                markers: false,
                color: PALETTE[1],
            },
            Series {
                name: "total − initial",
                points: energy[2].clone(),
                markers: false,
                color: PALETTE[2],
            },
        ],
        false,
        false,
    )?;
    let r = last.context("the run has no step (duration shorter than dt)")?;
    println!(
        "scene            {} ({}×{}, {} springs)",
        scene.name,
        nx,
        ny,
        sim.topology().spring_count()
    );
    println!(
        "integrator       {} at dt = {:e} s (predicted limit {:.3e} s)",
        sim.params().integrator,
        dt,
        sim.dt_limit()
    );
    println!(
        "steps            {} ({:.3} s simulated) in {:.3} s wall",
        steps, r.time, wall
    );
    println!(
        "cost             {:.1} µs/step, real-time factor {:.2}",
        wall * 1e6 / steps as f64,
        r.time / wall
    );
    println!(
        "final energy     kinetic {:.4e} J, elastic {:.4e} J, gravity {:.4e} J",
        r.kinetic_energy, r.elastic_energy, r.gravity_energy
    );
    println!(
        "final max strain structural {:.2}%, shear {:.2}%, bend {:.2}%",
        100.0 * r.max_strain[0],
        100.0 * r.max_strain[1],
        100.0 * r.max_strain[2]
    );
    println!("wrote            {} ({} frames)", traj_path.display(), header.n_frames);
    println!(
        "                 {}, {}, {}",
        csv_path.display(),
        svg.display(),
        png.display()
    );
    Ok(())
}

fn stability(
    scene_path: &Path,
    sizes: Vec<usize>,
    factors: Vec<f64>,
    steps: u32,
    bisections: u32,
    out: &Path,
) -> Result<()> {
    let scene = Scene::load(scene_path)?;
    if sizes.iter().any(|&n| n < 2) {
        bail!("--sizes: every size must be at least 2");
    }
    if factors.iter().any(|f| !(f.is_finite() && *f > 0.0)) {
        bail!("--factors: every stiffness factor must be positive");
    }
    fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let cfg = StabilitySweep {
        sizes,
        stiffness_factors: factors,
        integrators: Integrator::ALL.to_vec(),
        material: scene.params.material,
        side: scene.width,
        areal_density: scene.areal_density,
        steps,
        bisections,
    };
    let total = cfg.integrators.len() * cfg.sizes.len() * cfg.stiffness_factors.len();
    let bar = progress_bar(total as u64, "stability sweep");
    let rows = stability_sweep(&cfg, &mut |done, total| {
        bar.set_position(done as u64);
        if bar.is_hidden() {
            info!("stability sweep: {done}/{total}");
        }
    });
    bar.finish_and_clear();

    let csv_path = out.join("stability.csv");
    let mut csv = String::from(
        "integrator,n,stiffness_factor,omega_gershgorin,omega_max,damping_rate,predicted_dt,measured_stable_dt,measured_unstable_dt,measured_over_predicted\n",
    );
    println!(
        "{:<17} {:>4} {:>7} {:>10} {:>12} {:>12} {:>8}",
        "integrator", "n", "k×", "ω_max", "predicted dt", "measured dt", "ratio"
    );
    for r in &rows {
        // Implicit Euler has no predicted limit: no ratio (NaN in the CSV).
        let ratio = if r.predicted_dt.is_finite() {
            r.measured_dt() / r.predicted_dt
        } else {
            f64::NAN
        };
        csv.push_str(&format!(
            "{},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.4}\n",
            r.integrator,
            r.n,
            r.stiffness_factor,
            r.omega_gershgorin,
            r.omega_max,
            r.damping_rate,
            r.predicted_dt,
            r.measured_stable,
            r.measured_unstable,
            ratio
        ));
        let measured = if r.measured_unstable.is_finite() {
            format!("{:.3e}", r.measured_dt())
        } else {
            format!("≥{:.2e}", r.measured_stable)
        };
        println!(
            "{:<17} {:>4} {:>7} {:>10.0} {:>12.3e} {:>12} {:>8.3}",
            r.integrator.name(),
            r.n,
            r.stiffness_factor,
            r.omega_max,
            r.predicted_dt,
            measured,
            ratio
        );
    }
    fs::write(&csv_path, csv).with_context(|| format!("cannot write {}", csv_path.display()))?;

    // Chart: measured threshold against ω_max, with each integrator's
    // prediction as a line (implicit Euler: lower bounds only).
    let mut series = Vec::new();
    let names: Vec<String> = Integrator::ALL.iter().map(|i| i.name().to_string()).collect();
    let pred_names: Vec<String> = names.iter().map(|n| format!("{n} predicted")).collect();
    for (i, integrator) in Integrator::ALL.iter().enumerate() {
        let mut of: Vec<&StabilityRow> = rows.iter().filter(|r| r.integrator == *integrator).collect();
        of.sort_by(|a, b| a.omega_max.total_cmp(&b.omega_max));
        let color = PALETTE[i];
        series.push(Series {
            name: &pred_names[i],
            points: of.iter().map(|r| (r.omega_max, r.predicted_dt)).collect(),
            markers: false,
            color,
        });
        series.push(Series {
            name: &names[i],
            points: of.iter().map(|r| (r.omega_max, r.measured_dt())).collect(),
            markers: true,
            color,
        });
    }
    let svg = out.join("stability.svg");
    line_chart_svg(
        &svg,
        "Largest stable dt: predicted (lines) vs measured (dots)",
        "ω_max (rad/s)",
        "dt (s)",
        &series,
        true,
        true,
    )?;
    println!("wrote {} and {}", csv_path.display(), svg.display());
    Ok(())
}

fn inspect(file: &Path) -> Result<()> {
    let mut reader = TrajectoryReader::open(file)?;
    let h = *reader.header();
    println!("file        {}", file.display());
    println!("nodes       {} ({}×{})", h.n_nodes, h.nx, h.ny);
    println!("precision   {:?}, velocities {}", h.precision, h.velocities);
    println!("dt          {:e} s, a frame every {} steps", h.dt, h.frame_every);
    println!("frames      {}", h.n_frames);
    let first = reader.next_frame()?.context("the file has no frame")?;
    let mut last = first.clone();
    while let Some(f) = reader.next_frame()? {
        last = f;
    }
    let max_disp = first
        .positions
        .iter()
        .zip(&last.positions)
        .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt())
        .fold(0.0, f64::max);
    println!(
        "time        {:.4} s … {:.4} s (steps {} … {})",
        first.time, last.time, first.step, last.step
    );
    println!("largest displacement first → last frame: {max_disp:.4} m");
    Ok(())
}
