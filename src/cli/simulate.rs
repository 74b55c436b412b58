//! Commands on one scene file: simulate it, and inspect a trajectory it
//! wrote.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use tracing::info;

use lodcloth::args::{grid_scene, progress_bar};
use lodcloth::output::{
    line_chart_svg, recorded_inputs, render_png, report_csv_row, CsvTable, Precision, Replay, Series, TrajectoryReader,
    TrajectoryWriter, PALETTE, REPORT_CSV_HEADER,
};
use lodcloth::scene::Scene;
use lodcloth::sim::{
    crossings, GridShape, Integrator, Orientation, SelfOutcome, Simulation, StabilityCheck, StepReport, Topology,
};
use lodcloth::touch::Touch;

/// `simulate`'s arguments, as parsed.
pub(crate) struct SimulateArgs {
    pub(crate) scene: PathBuf,
    pub(crate) nx: Option<usize>,
    pub(crate) ny: Option<usize>,
    pub(crate) integrator: Option<Integrator>,
    pub(crate) dt: Option<f64>,
    pub(crate) duration: Option<f64>,
    pub(crate) out: Option<PathBuf>,
    pub(crate) fps: f64,
    pub(crate) precision: Precision,
    pub(crate) velocities: bool,
    pub(crate) force_unstable: bool,
    /// A recording whose inputs are replayed.
    pub(crate) inputs: Option<PathBuf>,
    pub(crate) episode: Option<u64>,
}

/// `simulate`: run a scene (with the command line's overrides) and write
/// its trajectory, per-frame report, energy chart and final render.
pub(crate) fn simulate(a: SimulateArgs) -> Result<()> {
    let mut scene = with_overrides(&a)?;
    let replay = match &a.inputs {
        Some(path) => Some(Replay::of(&recorded_inputs(path)?, a.episode, path)?),
        None => None,
    };
    if let Some(r) = &replay {
        let last = r.script.events().last().map_or(0.0, |e| e.0);
        if a.duration.is_none() {
            scene.duration = scene.duration.max(last + 1.0);
        } else if last > scene.duration {
            tracing::warn!(
                "--duration {} s ends before the last input ({last:.3} s): later inputs are not replayed",
                scene.duration
            );
        }
        println!(
            "replaying {} inputs of '{}' (episode {} of {:?}; {} by the idle rule), recorded at {}",
            r.script.events().len(),
            r.instance,
            r.episode,
            r.episodes,
            r.idle,
            r.level.map_or("an unknown level".to_string(), |l| l.to_string())
        );
    }
    let (nx, ny) = (a.nx.unwrap_or(scene.nx), a.ny.unwrap_or(scene.ny));
    let mut sim = scene.build_at(nx, ny)?;
    let mut touch = Touch::new(&scene);
    let mut next_input = 0usize;
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
    let mut csv = CsvTable::create(&csv_path, &REPORT_CSV_HEADER)?;
    traj.write(sim.state())?;

    let bar = progress_bar(steps, "simulating");
    let mut energy: [Vec<(f64, f64)>; 3] = Default::default();
    let started = Instant::now();
    let mut last_log = Instant::now();
    let mut last = None;
    let mut first_total = None;
    let mut selfc = SelfTotals::default();
    for s in 1..=steps {
        if let Some(r) = &replay {
            let at = next_input;
            r.script
                .apply_due(&mut next_input, &mut touch, &mut sim)
                .with_context(|| format!("replaying input {at} at t = {:.4} s", sim.state().time))?;
        }
        let r = sim.step();
        last = Some(r);
        selfc.add(&r.self_contact);
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
            csv.row(&report_csv_row(&r))?;
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
    csv.finish()?;

    let pinned: Vec<u32> = sim.loads().pins.iter().map(|p| p.node).collect();
    let png = out.join("final.png");
    render_png(&png, sim.topology(), sim.state(), &pinned, 800)?;
    let svg = out.join("energy.svg");
    let title = format!(
        "{} — energy ({}, dt = {:e} s, {}×{})",
        scene.name,
        sim.params().integrator,
        dt,
        nx,
        ny
    );
    energy_chart(&svg, &title, energy)?;
    let r = last.context("the run has no step (duration shorter than dt)")?;
    print_summary(&scene, &sim, &r, (nx, ny), steps, wall);
    if let Some(c) = sim.params().self_contact {
        println!(
            "self-contact     thickness {} m, μ {}: up to {} pairs within it, {} impacts, {} rounds of impact zones, \
             {} steps ended with a pair colliding; {:.0} % of steps certified flat; up to {} candidate pairs, \
             rebuilt every {:.1} steps",
            c.thickness,
            c.friction,
            selfc.most_near,
            selfc.impacts,
            selfc.zone_rounds,
            selfc.unresolved_steps,
            100.0 * selfc.flat as f64 / selfc.steps.max(1) as f64,
            selfc.most_candidates,
            selfc.steps as f64 / selfc.rebuilds.max(1) as f64
        );
    }
    println!("wrote            {} ({} frames)", traj_path.display(), header.n_frames);
    println!(
        "                 {}, {}, {}",
        csv_path.display(),
        svg.display(),
        png.display()
    );
    Ok(())
}

/// What self-contact did over a run.
#[derive(Default)]
struct SelfTotals {
    most_near: u32,
    impacts: u64,
    zone_rounds: u64,
    unresolved_steps: u64,
    steps: u64,
    rebuilds: u64,
    most_candidates: u32,
    flat: u64,
}

impl SelfTotals {
    fn add(&mut self, o: &SelfOutcome) {
        self.most_near = self.most_near.max(o.proximities);
        self.impacts += u64::from(o.impacts);
        self.zone_rounds += u64::from(o.zone_rounds);
        self.unresolved_steps += u64::from(o.unresolved > 0);
        self.steps += 1;
        self.rebuilds += u64::from(o.rebuilds);
        self.most_candidates = self.most_candidates.max(o.candidates);
        self.flat += u64::from(o.flat);
    }
}

/// The scene file with the command line's integrator, dt, duration and
/// stability overrides.
fn with_overrides(a: &SimulateArgs) -> Result<Scene> {
    let mut scene = grid_scene(&a.scene)?;
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
    Ok(scene)
}

/// Kinetic, elastic and total-minus-initial energy over time, as an SVG.
fn energy_chart(svg: &Path, title: &str, energy: [Vec<(f64, f64)>; 3]) -> Result<()> {
    let [kinetic, elastic, total] = energy;
    let series = |name, points, color| Series {
        name,
        points,
        markers: false,
        color,
    };
    line_chart_svg(
        svg,
        title,
        "time (s)",
        "energy (J)",
        &[
            series("kinetic", kinetic, PALETTE[0]),
            series("elastic", elastic, PALETTE[1]),
            series("total − initial", total, PALETTE[2]),
        ],
        false,
        false,
    )?;
    Ok(())
}

/// What a run was and cost, and where it ended, on stdout.
fn print_summary(scene: &Scene, sim: &Simulation, r: &StepReport, (nx, ny): (usize, usize), steps: u64, wall: f64) {
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
        sim.params().dt,
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
}

/// Frames of a trajectory that cross the cloth itself.
#[derive(Default)]
struct Crossed {
    frames: usize,
    crossing: usize,
    most: usize,
    first: Option<f64>,
}

pub(crate) fn inspect(file: &Path) -> Result<()> {
    let mut reader = TrajectoryReader::open(file)?;
    let h = *reader.header();
    println!("file        {}", file.display());
    println!("nodes       {} ({}×{})", h.n_nodes, h.nx, h.ny);
    println!("precision   {:?}, velocities {}", h.precision, h.velocities);
    println!("dt          {:e} s, a frame every {} steps", h.dt, h.frame_every);
    println!("frames      {}", h.n_frames);
    let first = reader.next_frame()?.context("the file has no frame")?;
    // A grid's triangles follow from its size (Topology::grid), so its
    // frames can be checked for the cloth crossing itself; a mesh
    // trajectory holds no triangles.
    let grid = (h.nx >= 2 && h.ny >= 2 && h.nx as u64 * h.ny as u64 == h.n_nodes).then(|| {
        let shape = GridShape {
            nx: h.nx as usize,
            ny: h.ny as usize,
            width: 1.0,
            height: 1.0,
        };
        Topology::grid(shape, Orientation::Horizontal)
    });
    let mut crossed = Crossed::default();
    let mut soa = Vec::new();
    let mut check = |f: &lodcloth::output::Frame, crossed: &mut Crossed| {
        if let Some(t) = &grid {
            soa.clear();
            soa.extend((0..3).flat_map(|c| f.positions.iter().map(move |p| p[c])));
            let c = crossings(t, &soa).len();
            crossed.frames += 1;
            if c > 0 {
                crossed.crossing += 1;
                crossed.first.get_or_insert(f.time);
                crossed.most = crossed.most.max(c);
            }
        }
    };
    check(&first, &mut crossed);
    let mut last = first.clone();
    while let Some(f) = reader.next_frame()? {
        check(&f, &mut crossed);
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
    match crossed.first {
        _ if grid.is_none() => println!("crossings   not counted: a mesh cloth's trajectory holds no triangles"),
        None => println!("crossings   none: the cloth never passes through itself in {} frames", crossed.frames),
        Some(t) => println!(
            "crossings   {} of {} frames pass through the cloth itself (up to {} edge–triangle pairs; first at {t:.4} s)",
            crossed.crossing, crossed.frames, crossed.most
        ),
    }
    if h.inputs {
        let inputs = reader.inputs()?;
        let idle = inputs.iter().filter(|e| e.idle).count();
        let span = match (inputs.first(), inputs.last()) {
            (Some(a), Some(b)) => format!(", t {:.3} s … {:.3} s (replay: simulate --inputs)", a.time, b.time),
            _ => String::new(),
        };
        println!("inputs      {} ({idle} by the idle rule){span}", inputs.len());
    }
    Ok(())
}
