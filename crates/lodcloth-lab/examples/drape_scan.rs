//! What a mesh cloth's drape coefficient depends on: the mesh's resolution,
//! the level's bending and stretch coefficients, and where the level starts.
//! Every run steps a level of the scene (any vertex count, its own mesh at
//! 100 %) with the scene's material made there (`same`), its bend class
//! and stretch classes' K optionally scaled, and prints the Cusick drape
//! coefficient at every whole second, the folds at the end and the strain
//! of the stretch springs over the overhang.
//!
//! ```text
//! cargo run --release -p lodcloth-lab --example drape_scan -- run SCENE --levels 721v,100% [--bend 1,1.35] [--stretch 2] [--dt 1e-4] [--integrator symplectic_euler] [--live] [--twins 8 [--jitter 1e-6]] [--stencils-from MESH.obj | --stencils triangle|quartic|mixed|mixed-exact] [--csv FILE]
//! cargo run --release -p lodcloth-lab --example drape_scan -- restart SCENE --levels 1081v,721v [--bend 1,1.35] [--stretch 2] [--unstressed] [--settle 0.005] [--csv FILE]
//! cargo run --release -p lodcloth-lab --example drape_scan -- spectrum SCENE --levels 100%,60%,40% [--modes 24] [--stencils triangle|quartic|mixed|mixed-exact] [--drape] [--clamped]
//! cargo run --release -p lodcloth-lab --example drape_scan -- membrane SCENE --levels 100%,60%,40% [--rings 2,3,4]
//! cargo run --release -p lodcloth-lab --example drape_scan -- write SCENE --levels 1800v [--relax 20 --flip] [--shuffle 0.05 [--seed 1]] [--top-radius 0.08 [--top-vertices 40]] --out LEVEL.obj
//! cargo run --release -p lodcloth-lab --example drape_scan -- chart --csv FILE[,FILE …] [--names A,B …] [--unscaled] [--legend upper-right] --out CHART.svg
//! ```
//!
//! `restart` steps the scene's reference for its duration and prints, at
//! every second, the bending energy each level's stencils read on the
//! reference's own vertices (a level's vertices are reference vertices)
//! against the reference's; then each level starts from the reference's
//! last shape, at rest, and runs 3 s, printing how far each band of it
//! moves in the first 0.2 s, the forces there and its springs' strain on
//! that shape (`--unstressed`: with those lengths as rest lengths;
//! `--settle H`: the start settled first, `lodcloth_core::lod::settle`).
//! `spectrum` prints the softest modes of each level's bending operator
//! against the first level's (and, with `--drape`, weighted by where the
//! first level's drape holds its bending energy; with `--clamped`, of the
//! free vertices with every pin held, so a clamp's inside does not count
//! as zero modes). `write` saves a level as OBJ, to be
//! used as another scene's mesh (a reference of that resolution), and can
//! remesh it in its rest plane first (Delaunay flips, tangential
//! relaxation; border fixed; flat meshes only) or flip a share of its
//! edges at random with its vertices kept (`--shuffle`), printing how even
//! its triangles and valences were and are. `run --stencils-from` bends a
//! mesh with another triangulation's stencils over the same vertices, to
//! tell the springs' connectivity from the stencils', and `run --stencils`
//! bends every level with another of the core's stencil rules
//! (`lodcloth_lab::stencils::Stencils`). `write --top-radius` grades a level
//! by hand: the cloth inside that radius (the support's top, which stays
//! flat) is collapsed to a few vertices first, so the level's count is
//! spent on the overhang.
//! `--csv` appends every run to FILE (made with its header when absent);
//! `chart` draws the runs from rest of one or more such files: the DC at
//! their end (the mean over twins) against the vertex count, one series
//! per file, bend and stretch scale.
//! Runs go two at a time (rayon). Measured with it: docs/results.md,
//! "Mesh cloths".
use std::collections::{HashMap, HashSet};
use std::ops::Range;
use std::path::{Path, PathBuf};

use lodcloth_core::drape::{drape_coefficient, fold_count, jitter_heights, shadow_area};
use lodcloth_core::level::GridLevel;
use lodcloth_core::lod;
use lodcloth_core::mesh::{triangle_area, TriMesh};
use lodcloth_core::scene::{ClothLevel, Scene};
use lodcloth_core::sim::vec3::{add, cross, dist, dot, norm, normalize, scale, sub};
use lodcloth_core::sim::{Integrator, Material, Shape, Simulation, SpringKind, SpringPrecision};
use lodcloth_lab::experiments::generalise::parse_band;
use lodcloth_lab::modal::{self, ClampedModes};
use rayon::prelude::*;

/// Shadow pixels (m), as the drape bench.
const PIXEL: f64 = 1e-3;

#[derive(clap::Parser)]
#[command(about = "The Cusick drape coefficient of a mesh cloth's levels and meshes")]
enum Command {
    /// Step each level from rest, its bend class scaled by each --bend.
    Run {
        #[command(flatten)]
        runs: Runs,
        /// The time step (s); default the scene's.
        #[arg(long)]
        dt: Option<f64>,
        /// The integrator; default the scene's (e.g. `symplectic_euler`,
        /// as config/cusick.toml serves the scene).
        #[arg(long)]
        integrator: Option<String>,
        /// Step the levels as a daemon steps its live level with
        /// `spring_precision = "f32"`: f32 springs and the bending's
        /// assembled operator (`lodcloth_core::sim::SpringPrecision::F32`).
        #[arg(long)]
        live: bool,
        /// Runs per level and bend scale: the first from the scene's rest
        /// shape, every other with each vertex raised or lowered by a
        /// seeded normal draw of --jitter (its twins). Where the overhang
        /// breaks into folds is decided by rounding on a symmetric disc, so
        /// one run is one draw of the DC; the twins give its spread.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
        twins: u64,
        /// The twins' vertical jitter's standard deviation (m).
        #[arg(long, default_value_t = 1e-6)]
        jitter: f64,
        /// Bend with the stencils of this mesh instead of the level's own:
        /// an OBJ with the level's vertices (as `write` makes them) and
        /// other triangles. Springs, masses and shadow stay the level's.
        /// Tells the springs' connectivity from the stencils'.
        #[arg(long)]
        stencils_from: Option<PathBuf>,
        /// How the levels' curvature is read (`vertex`, the scenes' own;
        /// `triangle`, six-point patches; `quartic`, a quartic over the
        /// nearest 19 or more points at every interior vertex;
        /// `lodcloth_lab::stencils::Stencils`).
        #[arg(long, value_parser = ["vertex", "triangle", "quartic", "mixed", "mixed-exact"], default_value = "vertex")]
        stencils: String,
    },
    /// Step the reference, then each level from its last shape, at rest.
    Restart {
        #[command(flatten)]
        runs: Runs,
        /// Give each level's stretch springs their lengths on the
        /// reference's shape as rest lengths: a level whose membrane holds
        /// no stress there, to tell the springs' part in its departure
        /// from the bending's.
        #[arg(long)]
        unstressed: bool,
        /// Settle each level's start by one backward-Euler step of this
        /// length (s) from rest, with its own forces
        /// (`lodcloth_core::lod::settle`).
        #[arg(long)]
        settle: Option<f64>,
    },
    /// The spectrum of each level's bending operator on its flat rest
    /// shape: the lowest eigenvalues λ of W z = λ M z (W the stencils'
    /// quadratic form for a vertical displacement z, M the lumped areas),
    /// printed as wavenumbers λ^¼ (1/m) and against the first level's. A
    /// plate's ∫|∇²z|² has three zero modes (the affine ones); any more, or
    /// smooth modes that come out lower than the first level's, are folds
    /// a level makes for less than its fabric's rigidity.
    Spectrum {
        #[command(flatten)]
        levels: Levels,
        /// How many of the lowest modes to print.
        #[arg(long, default_value_t = 24)]
        modes: usize,
        /// The levels' stencil rule, as `run --stencils`.
        #[arg(long, value_parser = ["vertex", "triangle", "quartic", "mixed", "mixed-exact"], default_value = "vertex")]
        stencils: String,
        /// Also step the first level (the reference: `100%`) for the
        /// scene's duration and weigh the other levels' eigenvalue ratios
        /// by where its drape's bending energy lies: `Σ e_j·λ_j/λ'_j / Σ e_j`
        /// over the modes a level has (e_j the drape's energy in the first
        /// level's mode j, λ' the level's j-th eigenvalue), the factor on
        /// D that gives the level the reference's stiffness at the drape's
        /// wavenumbers.
        #[arg(long)]
        drape: bool,
        /// Modes of the cloth that moves: every pinned vertex held at 0
        /// (the clamp's Dirichlet problem, on the free vertices alone),
        /// with --drape weighing by the drape's displacement from the
        /// start (zero on the pins).
        /// Without it a clamp's inside is a block of zero modes (its
        /// stencils store nothing), as many as it has vertices, and the
        /// levels' modes no longer line up with the reference's.
        #[arg(long)]
        clamped: bool,
        /// With --clamped: stiffen every level but the reference as `run
        /// --modal` does first, to see its modes in the band meet the
        /// reference's and the others stay.
        #[arg(long, value_parser = parse_band, requires = "clamped")]
        modal: Option<Range<usize>>,
    },
    /// The spring membrane of each level under a homogeneous in-plane
    /// strain: its energy with every vertex moved affinely, and with the
    /// border moved affinely and the inside left to relax (the network's
    /// own response), each against the isotropic membrane the springs
    /// stand for (λ = μ, the biaxial stiffness the scene's material gives
    /// them). A regular triangular network holds the affine field in
    /// equilibrium; an irregular one relaxes off it and is softer than its
    /// coefficients say.
    Membrane {
        #[command(flatten)]
        levels: Levels,
        /// Also the same measure on every interior vertex's patch of this
        /// many rings (its outermost ring held), summed over the patches.
        #[arg(long, value_delimiter = ',')]
        rings: Vec<usize>,
    },
    /// Save the (first) level as OBJ, optionally remeshed in its rest
    /// plane (to tell a level's uneven triangles from its size).
    Write {
        #[command(flatten)]
        levels: Levels,
        #[arg(long)]
        out: PathBuf,
        /// Sweeps of tangential relaxation: every vertex off the border
        /// moves to the area-weighted mean of its triangles' centroids (a
        /// step towards a centroidal Voronoi tessellation).
        #[arg(long, default_value_t = 0)]
        relax: usize,
        /// Delaunay edge flips in the rest plane, before and after relaxing.
        #[arg(long)]
        flip: bool,
        /// Flip this share of the interior edges, drawn at random, with
        /// every vertex kept where it is (after any --relax/--flip): a
        /// mesh's connectivity made irregular, its vertices not. A flip is
        /// taken only where the two triangles make a convex quad, neither
        /// triangle was flipped already, and valences stay 4–9 inside and
        /// ≥ 2 triangles on the border.
        #[arg(long, default_value_t = 0.0)]
        shuffle: f64,
        /// The seed of --shuffle's draw.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Collapse the cloth inside this radius (m, in the rest plane)
        /// to --top-vertices first, every vertex outside it locked, then
        /// simplify the rest to the level's count: a level graded by hand.
        #[arg(long)]
        top_radius: Option<f64>,
        #[arg(long, default_value_t = 40)]
        top_vertices: usize,
    },
    /// Draw the runs from rest in CSVs written by --csv (one series per
    /// file, bend and stretch scale).
    Chart {
        #[arg(long, value_delimiter = ',', required = true)]
        csv: Vec<PathBuf>,
        /// Each file's name in the legend (default: its stem, when there
        /// are several files).
        #[arg(long, value_delimiter = ',')]
        names: Vec<String>,
        /// Only the runs with the scene's own coefficients (bend and
        /// stretch ×1).
        #[arg(long)]
        unscaled: bool,
        /// Where the legend goes (clear of the points).
        #[arg(long, value_enum, default_value_t = Corner::LowerRight)]
        legend: Corner,
        #[arg(long)]
        out: PathBuf,
    },
}

/// A corner of a chart.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Corner {
    UpperLeft,
    UpperRight,
    LowerLeft,
    LowerRight,
}

#[derive(clap::Args)]
struct Levels {
    /// A Cusick scene with a mesh cloth.
    scene: PathBuf,
    /// Levels: vertex counts (`721v`) or shares of the mesh (`60%`, `100%`).
    #[arg(long, value_delimiter = ',', required = true)]
    levels: Vec<GridLevel>,
}

#[derive(clap::Args)]
struct Runs {
    #[command(flatten)]
    levels: Levels,
    /// Scales of the levels' bend class (K and C).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    bend: Vec<f64>,
    /// Scale of every stretch and shear K.
    #[arg(long, default_value_t = 1.0)]
    stretch: f64,
    /// Append every run to this CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Stiffen each level's bending modes FIRST..END (softest first, every
    /// pin held) to the reference's, paired by order
    /// (`lodcloth_lab::modal`); the CSV's scene says so.
    #[arg(long, value_parser = parse_band)]
    modal: Option<Range<usize>>,
}

/// The scene, its stepping geometry and the levels asked for.
struct Setup {
    scene: Scene,
    cloth: f64,
    support: f64,
    levels: Vec<ClothLevel>,
    /// What was done to the levels, for the CSV's scene column.
    variant: String,
}

impl Setup {
    fn new(args: &Levels) -> Setup {
        let scene = Scene::load(&args.scene).unwrap_or_else(|e| panic!("{}: {e}", args.scene.display()));
        let mesh = scene.mesh.as_ref().expect("a mesh scene");
        let support = match scene.colliders().first().map(|c| &c.shape) {
            Some(&Shape::Cylinder { radius, .. }) => std::f64::consts::PI * radius * radius,
            _ => panic!("a Cusick scene: its first collider an upright cylinder"),
        };
        let levels = args
            .levels
            .iter()
            .map(|l| {
                let level = l
                    .on(scene.width, scene.height, Some(mesh.reference.vertices()))
                    .unwrap_or_else(|e| panic!("--levels {l}: {e}"));
                scene.cloth_level(level).unwrap_or_else(|e| panic!("--levels {l}: {e}"))
            })
            .collect();
        Setup {
            cloth: mesh.area,
            support,
            levels,
            scene,
            variant: String::new(),
        }
    }

    /// The scene's material on `cloth`, bend class and stretch K scaled.
    fn material(&self, cloth: &ClothLevel, bend: f64, stretch: f64) -> Material {
        self.scene
            .material_on(cloth)
            .kind_scaled(SpringKind::Bend, bend, bend)
            .kind_scaled(SpringKind::Structural, stretch, 1.0)
            .kind_scaled(SpringKind::Shear, stretch, 1.0)
    }

    fn dc(&self, sim: &Simulation) -> f64 {
        drape_coefficient(
            shadow_area(&sim.topology().triangles, &sim.state().pos, PIXEL),
            self.cloth,
            self.support,
        )
    }

    /// `sim` stepped `seconds` more, DC after each.
    fn stepped(&self, sim: &mut Simulation, seconds: usize) -> Vec<f64> {
        let (dt, t0) = (sim.params().dt, sim.state().time);
        (1..=seconds)
            .map(|t| {
                while sim.state().time < t0 + t as f64 - 0.5 * dt {
                    assert!(sim.step().finite, "diverged");
                }
                self.dc(sim)
            })
            .collect()
    }

    /// Every level with every bend scale.
    fn jobs<'a>(&'a self, bends: &'a [f64]) -> Vec<(&'a ClothLevel, f64)> {
        self.levels
            .iter()
            .flat_map(|l| bends.iter().map(move |&b| (l, b)))
            .collect()
    }

    /// The scene's file name, for CSV rows.
    fn name(&self) -> String {
        self.scene.origin.rsplit('/').next().unwrap_or_default().to_string() + &self.variant
    }

    /// Every level but the reference with its bending modes in `band`
    /// stiffened to the reference's.
    fn stiffen(&mut self, band: Option<&Range<usize>>) {
        let Some(band) = band else { return };
        let held = |cloth: &ClothLevel| {
            let loads = self
                .scene
                .loads_on(&cloth.topology, cloth.mesh.as_deref())
                .expect("the scene's pins resolve");
            modal::pinned_flags(cloth.topology.n_nodes, loads.pins.iter().map(|p| p.node))
        };
        let reference = self
            .scene
            .cloth_level(self.scene.reference_level())
            .expect("the reference");
        let target = ClampedModes::of(&reference.topology, &held(&reference), "reference").expect("stencils");
        for cloth in &mut self.levels {
            if cloth.topology.n_nodes == reference.topology.n_nodes {
                continue;
            }
            let pinned = held(cloth);
            let modes = ClampedModes::of(&cloth.topology, &pinned, "level").expect("stencils");
            let upto = band.end.min(modes.len()).min(target.len());
            let rows = modal::stiffening(&cloth.topology, &pinned, &modes, &target, band.clone())
                .unwrap_or_else(|e| panic!("--modal {}..{}: {e}", band.start, band.end));
            println!(
                "{}: {} of its modes {}..{upto} stiffened to the reference's ({} entries)",
                cloth.level,
                rows.len(),
                band.start,
                rows.nodes.len()
            );
            let mut topology = (*cloth.topology).clone();
            topology.bending = topology.bending.extended(&rows);
            cloth.topology = std::sync::Arc::new(topology);
        }
        self.variant = match band.end {
            usize::MAX => format!(" modal {}..", band.start),
            end => format!(" modal {}..{end}", band.start),
        };
    }
}

const HEADER: [&str; 10] = [
    "scene",
    "vertices",
    "bend_scale",
    "stretch_scale",
    "dt_s",
    "start",
    "time_s",
    "drape_coefficient",
    "folds_at_end",
    "twin",
];

/// One run's rows (one per second) for `--csv`.
struct Run<'a> {
    scene: String,
    vertices: usize,
    bend: f64,
    stretch: f64,
    dt: f64,
    start: &'a str,
    dc: Vec<f64>,
    folds: Option<usize>,
    twin: u64,
}

impl Run<'_> {
    fn rows(&self) -> impl Iterator<Item = [String; 10]> + '_ {
        let folds = self.folds.map_or(String::new(), |f| f.to_string());
        self.dc.iter().enumerate().map(move |(t, dc)| {
            [
                self.scene.clone(),
                self.vertices.to_string(),
                self.bend.to_string(),
                self.stretch.to_string(),
                format!("{:e}", self.dt),
                self.start.to_string(),
                (t + 1).to_string(),
                format!("{dc:.5}"),
                folds.clone(),
                self.twin.to_string(),
            ]
        })
    }

    fn cells(&self) -> String {
        self.dc.iter().map(|d| format!(" {d:.4}")).collect()
    }
}

fn failed<T>(path: &Path, e: impl std::fmt::Display) -> T {
    panic!("{}: {e}", path.display())
}

/// Append `runs` to the `--csv` file, if one was given.
fn append(csv: Option<&Path>, runs: &[Run<'_>]) {
    let Some(path) = csv else { return };
    let fresh = !path.exists();
    let file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .unwrap_or_else(|e| failed(path, e));
    let mut out = csv::Writer::from_writer(file);
    if fresh {
        out.write_record(HEADER).unwrap_or_else(|e| failed(path, e));
    }
    for row in runs.iter().flat_map(Run::rows) {
        out.write_record(&row).unwrap_or_else(|e| failed(path, e));
    }
    out.flush().unwrap_or_else(|e| failed(path, e));
}

/// 5th percentile, median and mean compression of the stretch springs whose
/// two ends lie beyond the support (rest distance from the axis).
fn overhang_strain(sim: &Simulation, support_radius: f64) -> String {
    let topo = sim.topology();
    let (pos, n) = (&sim.state().pos, topo.n_nodes);
    let r = |i: usize| topo.rest_positions[i][0].hypot(topo.rest_positions[i][2]);
    let mut e: Vec<f64> = Vec::new();
    for g in topo.groups.iter().filter(|g| g.class.kind() == SpringKind::Structural) {
        for k in 0..g.len() {
            let (a, b) = (g.a[k] as usize, g.b[k] as usize);
            if r(a).min(r(b)) > support_radius {
                let l = (0..3)
                    .map(|c| (pos[c * n + b] - pos[c * n + a]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                e.push(l / g.rest[k] - 1.0);
            }
        }
    }
    if e.is_empty() {
        return String::new();
    }
    e.sort_by(f64::total_cmp);
    let compression = e.iter().map(|x| (-x).max(0.0)).sum::<f64>() / e.len() as f64;
    format!(
        "; overhang strain p5 {:+.4}, median {:+.4}, mean compression {:.4}",
        e[e.len() / 20],
        e[e.len() / 2],
        compression
    )
}

/// How far the cloth's edges cut into the support between their nodes
/// (contact holds only nodes out): over every stretch spring, the deepest
/// of 15 points along it below the support's surface, as the number of
/// springs that reach inside the solid and the deepest (mm); the nodes
/// themselves stay `clearance` out.
fn cut(sim: &Simulation, scene: &Scene) -> String {
    let body = scene.colliders().first().expect("a support");
    let topo = sim.topology();
    let (pos, n, t) = (&sim.state().pos, topo.n_nodes, sim.state().time);
    let at = |k: usize| [pos[k], pos[n + k], pos[2 * n + k]];
    let (mut inside, mut deepest) = (0usize, 0.0f64);
    for g in topo.groups.iter().filter(|g| g.class.kind() == SpringKind::Structural) {
        for s in 0..g.len() {
            let (a, b) = (at(g.a[s] as usize), at(g.b[s] as usize));
            let depth = (1..16)
                .map(|j| body.distance(add(a, scale(sub(b, a), j as f64 / 16.0)), t))
                .fold(f64::INFINITY, f64::min);
            if depth < 0.0 {
                inside += 1;
                deepest = deepest.max(-depth);
            }
        }
    }
    format!("; {inside} edges cut into the support, deepest {:.2} mm", 1e3 * deepest)
}

/// Every level of `setup` bent by the `stencils` rule instead of its own
/// (`vertex`: left as it is).
fn restencil(setup: &mut Setup, stencils: &str) {
    let how = match stencils {
        "triangle" => lodcloth_lab::stencils::Stencils::Triangle,
        "quartic" => lodcloth_lab::stencils::Stencils::Quartic,
        "mixed" => lodcloth_lab::stencils::Stencils::Mixed,
        "mixed-exact" => lodcloth_lab::stencils::Stencils::MixedExact,
        _ => return,
    };
    for cloth in &mut setup.levels {
        let mesh = &cloth.mesh.as_ref().expect("a mesh level").mesh;
        let mut topology = (*cloth.topology).clone();
        topology.bending = lodcloth_lab::stencils::bending_stencils_by(mesh, &[], how).expect("a flat mesh");
        println!(
            "{}: bending with {} {stencils} stencils",
            cloth.level,
            topology.bending.len() / 3
        );
        cloth.topology = std::sync::Arc::new(topology);
    }
}

/// How `run` steps its levels beyond the scene: another dt or integrator,
/// the live fast path.
struct Stepping {
    dt: Option<f64>,
    integrator: Option<Integrator>,
    live: bool,
}

fn run(args: &Runs, stepping: Stepping, twins: u64, jitter: f64, stencils_from: Option<&Path>, stencils: &str) {
    assert!(
        jitter.is_finite() && jitter >= 0.0,
        "--jitter must be a length ≥ 0, got {jitter}"
    );
    let mut setup = Setup::new(&args.levels);
    if let Some(integrator) = stepping.integrator {
        setup.scene.params.integrator = integrator;
    }
    if let Some(path) = stencils_from {
        let other = lodcloth_core::mesh::load(path).unwrap_or_else(|e| failed(path, e));
        for cloth in &mut setup.levels {
            *cloth = bent_by(cloth, &other).unwrap_or_else(|e| failed(path, e));
        }
    }
    restencil(&mut setup, stencils);
    setup.stiffen(args.modal.as_ref());
    let (bends, stretch) = (&args.bend, args.stretch);
    let support_radius = (setup.support / std::f64::consts::PI).sqrt();
    let jobs: Vec<_> = setup
        .jobs(bends)
        .into_iter()
        .flat_map(|(cloth, bend)| (0..twins).map(move |twin| (cloth, bend, twin)))
        .collect();
    let runs: Vec<Run<'_>> = jobs
        .par_iter()
        .map(|&(cloth, bend, twin)| {
            let clock = std::time::Instant::now();
            let mut scene = setup.scene.clone();
            if let Some(dt) = stepping.dt {
                scene.params.dt = dt;
            }
            let mut sim = scene
                .build_on(cloth, setup.material(cloth, bend, stretch))
                .expect("builds");
            if stepping.live {
                sim.set_spring_precision(SpringPrecision::F32);
            }
            if twin > 0 {
                jitter_heights(&mut sim, twin, jitter);
            }
            let dc = setup.stepped(&mut sim, setup.scene.duration.round() as usize);
            let folds = fold_count(&sim.topology().rest_positions, &sim.state().pos, [0.0, 0.0]);
            let run = Run {
                scene: setup.name(),
                vertices: cloth.topology.n_nodes,
                bend,
                stretch,
                dt: sim.params().dt,
                start: "rest",
                dc,
                folds: Some(folds),
                twin,
            };
            println!(
                "{} bend ×{bend} stretch ×{stretch} dt {:e} twin {twin}: DC{}; {folds} folds{} ({:.0} s)",
                cloth.level,
                run.dt,
                run.cells(),
                overhang_strain(&sim, support_radius) + &cut(&sim, &setup.scene),
                clock.elapsed().as_secs_f64()
            );
            run
        })
        .collect();
    if twins > 1 {
        spread(&runs);
    }
    append(args.csv.as_deref(), &runs);
}

/// `cloth` bending with `other`'s stencils: a mesh of the level's
/// vertices, at the same positions (bit for bit, as `write` makes them),
/// in any order.
fn bent_by(cloth: &ClothLevel, other: &TriMesh) -> Result<ClothLevel, String> {
    let rest = &cloth.topology.rest_positions;
    if other.vertices() != rest.len() {
        return Err(format!(
            "{} vertices, the level {} has {}",
            other.vertices(),
            cloth.level,
            rest.len()
        ));
    }
    let bits = |p: [f64; 3]| p.map(f64::to_bits);
    let at: HashMap<[u64; 3], u32> = (0..rest.len()).map(|i| (bits(rest[i]), i as u32)).collect();
    let index = other
        .positions
        .iter()
        .enumerate()
        .map(|(k, &p)| {
            at.get(&bits(p))
                .copied()
                .ok_or_else(|| format!("vertex {k} at {p:?} is not one of the level's"))
        })
        .collect::<Result<Vec<u32>, String>>()?;
    // `other` renumbered as the level.
    let mut other = other.clone();
    other.positions = rest.clone();
    for t in &mut other.triangles {
        *t = t.map(|k| index[k as usize]);
    }
    let mut topology = (*cloth.topology).clone();
    topology.bending = lodcloth_core::mesh::bending_stencils(&other, &[]).map_err(|e| e.to_string())?;
    let sorted = |t: &[u32; 3]| {
        let mut t = *t;
        t.sort_unstable();
        t
    };
    let own: HashSet<[u32; 3]> = topology.triangles.iter().map(sorted).collect();
    let shared = other.triangles.iter().filter(|t| own.contains(&sorted(t))).count();
    println!(
        "{}: bending with {} stencils of another triangulation ({} triangles, {shared} shared with the level's)",
        cloth.level,
        other.vertices(),
        other.triangles.len(),
    );
    Ok(ClothLevel {
        level: cloth.level,
        topology: std::sync::Arc::new(topology),
        mesh: cloth.mesh.clone(),
    })
}

/// Per level and bend scale: the twins' DC at the end (mean, sample
/// standard deviation, range) and their fold counts.
fn spread(runs: &[Run<'_>]) {
    let mut groups: Vec<((usize, f64), Vec<&Run<'_>>)> = Vec::new();
    for r in runs {
        let key = (r.vertices, r.bend);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, g)) => g.push(r),
            None => groups.push((key, vec![r])),
        }
    }
    for ((vertices, bend), g) in groups {
        let ends: Vec<f64> = g.iter().filter_map(|r| r.dc.last().copied()).collect();
        let n = ends.len() as f64;
        let mean = ends.iter().sum::<f64>() / n;
        let sd = (ends.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
        let (lo, hi) = ends
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &d| (a.min(d), b.max(d)));
        let folds: Vec<String> = g.iter().filter_map(|r| r.folds).map(|f| f.to_string()).collect();
        println!(
            "{vertices} v bend ×{bend}: DC at the end over {} twins {mean:.4} ± {sd:.4} (sd; standard error {:.4}), {lo:.4}–{hi:.4}; folds {}",
            ends.len(),
            sd / n.sqrt(),
            folds.join(" ")
        );
    }
}

fn restart(args: &Runs, unstressed: bool, settle_by: Option<f64>) {
    let mut setup = Setup::new(&args.levels);
    setup.stiffen(args.modal.as_ref());
    let (bends, stretch) = (&args.bend, args.stretch);
    let mut reference = setup.scene.build().expect("builds");
    let n = reference.topology().n_nodes;
    let points = |pos: &[f64], of: &[u32]| -> Vec<[f64; 3]> {
        of.iter()
            .map(|&k| [pos[k as usize], pos[n + k as usize], pos[2 * n + k as usize]])
            .collect()
    };
    let all: Vec<u32> = (0..n as u32).collect();
    let seconds = setup.scene.duration.round() as usize;
    for t in 1..=seconds {
        setup.stepped(&mut reference, 1);
        let pos = &reference.state().pos;
        let fine = reference.topology().bending.energy_of(&points(pos, &all));
        let ratios: Vec<String> = setup
            .levels
            .iter()
            .map(|l| {
                let source = &l.mesh.as_ref().expect("a mesh level").source;
                let coarse = l.topology.bending.energy_of(&points(pos, source));
                format!("{} {:.3}", l.level, fine / coarse)
            })
            .collect();
        println!(
            "t = {t} s: reference DC {:.4}; its bending energy over each level's: {}",
            setup.dc(&reference),
            ratios.join(", ")
        );
    }
    let pos = reference.state().pos.clone();
    if unstressed {
        for cloth in &mut setup.levels {
            let source = &cloth.mesh.as_ref().expect("a mesh level").source;
            let at = |k: u32| {
                let j = source[k as usize] as usize;
                [pos[j], pos[n + j], pos[2 * n + j]]
            };
            let mut topology = (*cloth.topology).clone();
            for g in topology
                .groups
                .iter_mut()
                .filter(|g| g.class.kind() == SpringKind::Structural)
            {
                for s in 0..g.len() {
                    g.rest[s] = dist(at(g.a[s]), at(g.b[s]));
                    g.inv_rest[s] = 1.0 / g.rest[s];
                }
            }
            cloth.topology = std::sync::Arc::new(topology);
        }
    }
    let jobs = setup.jobs(bends);
    let start = if unstressed {
        format!("reference at {seconds} s, springs unstressed")
    } else {
        format!("reference at {seconds} s")
    };
    let runs: Vec<Run<'_>> = jobs
        .par_iter()
        .map(|&(cloth, bend)| {
            let mut sim = setup
                .scene
                .build_on(cloth, setup.material(cloth, bend, stretch))
                .expect("builds");
            let source = &cloth.mesh.as_ref().expect("a mesh level").source;
            let m = source.len();
            let mut state = sim.state().clone();
            for c in 0..3 {
                for (k, &j) in source.iter().enumerate() {
                    state.pos[c * m + k] = pos[c * n + j as usize];
                }
            }
            sim.set_state(state).expect("same size");
            if let Some(h) = settle_by {
                let moved = lod::settle(&mut sim, h).unwrap_or_else(|e| panic!("--settle {h}: {e}"));
                println!(
                    "{} bend ×{bend}: settled by {h} s, moved rms {:.3} mm, max {:.3} mm",
                    cloth.level,
                    1e3 * moved.rms,
                    1e3 * moved.max
                );
            }
            let first = setup.dc(&sim);
            let departure = departure(&setup, cloth, stretch, &mut sim);
            let run = Run {
                scene: setup.name(),
                vertices: m,
                bend,
                stretch,
                dt: sim.params().dt,
                start: &start,
                dc: setup.stepped(&mut sim, 3),
                folds: None,
                twin: 0,
            };
            println!(
                "{} bend ×{bend} stretch ×{stretch}, from the reference's last shape: DC {first:.4} →{}{}\n{departure}",
                cloth.level,
                run.cells(),
                cut(&sim, &setup.scene)
            );
            run
        })
        .collect();
    append(args.csv.as_deref(), &runs);
}

/// Rest-radius bands of the Cusick specimen (m): the support's top, its
/// edge, the overhang and the rim's last 10 mm.
const BANDS: [(&str, f64, f64); 4] = [
    ("top", 0.0, 0.085),
    ("edge", 0.085, 0.10),
    ("overhang", 0.10, 0.14),
    ("rim", 0.14, f64::INFINITY),
];

/// Why a level leaves the shape `sim` holds (at rest): each force's
/// acceleration there, split into gravity, the stretch springs and the
/// bending stencils (a twin built with bending off tells the last two
/// apart; contact is a velocity projection, in none of them), and the
/// work each does on the displacement of the next 0.2 s, Σ m·a·d, per
/// rest-radius band (a linearisation: a fast transient of the springs
/// swamps it, so it says most with `--unstressed`). Also the strain of the level's stretch
/// springs on the shape, radial (within 30° of the rest radius) and hoop.
/// Leaves `sim` where it was.
fn departure(setup: &Setup, cloth: &ClothLevel, stretch: f64, sim: &mut Simulation) -> String {
    let start = sim.state().clone();
    let mut flat = setup
        .scene
        .build_on(cloth, setup.material(cloth, 0.0, stretch))
        .expect("builds");
    flat.set_state(start.clone()).expect("same size");
    let full = sim.accelerations().to_vec();
    let springs_and_gravity = flat.accelerations().to_vec();
    let topo = sim.topology().clone();
    let n = topo.n_nodes;
    let g = sim.params().gravity;
    let masses = sim.masses().to_vec();
    let (dt, t0) = (sim.params().dt, start.time);
    while sim.state().time < t0 + 0.2 - 0.5 * dt {
        assert!(sim.step().finite, "diverged");
    }
    let d: Vec<f64> = (0..3 * n).map(|i| sim.state().pos[i] - start.pos[i]).collect();
    sim.set_state(start.clone()).expect("same size");
    let rest_r = |k: usize| topo.rest_positions[k][0].hypot(topo.rest_positions[k][2]);
    let band = |k: usize| {
        BANDS
            .iter()
            .position(|&(_, lo, hi)| (lo..hi).contains(&rest_r(k)))
            .expect("a band")
    };
    // [band][gravity, springs, bending] work; [band][springs, bending] mean
    // horizontal outward acceleration; moved distance.
    let mut work = [[0.0; 3]; 4];
    let mut outward = [[0.0; 2]; 4];
    let mut count = [0usize; 4];
    let mut moved = [0.0; 4];
    let p = &start.pos;
    for k in 0..n {
        let b = band(k);
        count[b] += 1;
        let (x, z) = (p[k], p[2 * n + k]);
        let r = x.hypot(z).max(1e-12);
        let (ux, uz) = (x / r, z / r);
        let mut dd = 0.0;
        for c in 0..3 {
            let i = c * n + k;
            let parts = [g[c], springs_and_gravity[i] - g[c], full[i] - springs_and_gravity[i]];
            for (w, a) in work[b].iter_mut().zip(parts) {
                *w += masses[k] * a * d[i];
            }
            dd += d[i] * d[i];
        }
        moved[b] += dd.sqrt();
        let parts = [
            [springs_and_gravity[k] - g[0], springs_and_gravity[2 * n + k] - g[2]],
            [
                full[k] - springs_and_gravity[k],
                full[2 * n + k] - springs_and_gravity[2 * n + k],
            ],
        ];
        for (o, [ax, az]) in outward[b].iter_mut().zip(parts) {
            *o += ax * ux + az * uz;
        }
    }
    // Strain of the stretch springs on the shape, by band of their middle.
    let mut strains: [[Vec<f64>; 2]; 4] = Default::default();
    for grp in topo.groups.iter().filter(|g| g.class.kind() == SpringKind::Structural) {
        for s in 0..grp.len() {
            let (a, b) = (grp.a[s] as usize, grp.b[s] as usize);
            let (ra, rb) = (topo.rest_positions[a], topo.rest_positions[b]);
            let mid = [0.5 * (ra[0] + rb[0]), 0.5 * (ra[2] + rb[2])];
            let along = [rb[0] - ra[0], rb[2] - ra[2]];
            let cos = (along[0] * mid[0] + along[1] * mid[1]).abs()
                / (along[0].hypot(along[1]) * mid[0].hypot(mid[1])).max(1e-12);
            let l = (0..3)
                .map(|c| (p[c * n + b] - p[c * n + a]).powi(2))
                .sum::<f64>()
                .sqrt();
            let r = mid[0].hypot(mid[1]);
            let bi = BANDS
                .iter()
                .position(|&(_, lo, hi)| (lo..hi).contains(&r))
                .expect("a band");
            strains[bi][usize::from(cos < 0.866)].push(l / grp.rest[s] - 1.0);
        }
    }
    let median = |v: &mut Vec<f64>| {
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut lines = Vec::new();
    for (b, &(name, ..)) in BANDS.iter().enumerate() {
        let c = count[b].max(1) as f64;
        let [radial, hoop] = &mut strains[b];
        lines.push(format!(
            "  {name:>8} ({} v): moved {:.2} mm; work gravity {:+.3e} springs {:+.3e} bending {:+.3e} J; outward springs {:+.3} bending {:+.3} m/s²; strain radial {:+.4} hoop {:+.4}",
            count[b],
            1e3 * moved[b] / c,
            work[b][0],
            work[b][1],
            work[b][2],
            outward[b][0] / c,
            outward[b][1] / c,
            median(radial),
            median(hoop),
        ));
    }
    lines.join("\n")
}

fn membrane(args: &Levels, rings: &[usize]) {
    let setup = Setup::new(args);
    // Strains (ε_uu, ε_vv, ε_uv): biaxial, pure shear, simple shear.
    let strains = [
        ("biaxial", [1.0, 1.0, 0.0]),
        ("pure shear", [1.0, -1.0, 0.0]),
        ("simple shear", [0.0, 0.0, 1.0]),
    ];
    for cloth in &setup.levels {
        let topo = &cloth.topology;
        let material = setup.material(cloth, 1.0, 1.0);
        let mesh = &cloth.mesh.as_ref().expect("a mesh level").mesh;
        let (e1, e2) = tangent_plane(mesh);
        let n = topo.n_nodes;
        let uv: Vec<[f64; 2]> = topo
            .rest_positions
            .iter()
            .map(|p| {
                let d = sub(*p, topo.rest_positions[0]);
                [dot(d, e1), dot(d, e2)]
            })
            .collect();
        let off_plane = topo
            .rest_positions
            .iter()
            .map(|p| dot(sub(*p, topo.rest_positions[0]), cross(e1, e2)).abs())
            .fold(0.0, f64::max);
        assert!(
            off_plane < 1e-9,
            "{}: membrane reads flat meshes only ({off_plane:.2e} m off the plane)",
            cloth.level
        );
        // Every spring at rest (a plate's stretch springs; the stretch and
        // bend springs of a cloth that has them, which share its
        // membrane), its in-plane stiffness Σ K·d·dᵀ, and the biaxial
        // modulus the coefficients were made for.
        let springs: Vec<PlaneSpring> = topo
            .groups
            .iter()
            .flat_map(|g| {
                let k = material.springs[g.class.index()].k;
                g.a.iter()
                    .zip(&g.b)
                    .zip(&g.rest)
                    .map(move |((&a, &b), &l)| (a, b, k, l))
            })
            .map(|(a, b, k, l)| {
                let (a, b) = (a as usize, b as usize);
                let d = [(uv[b][0] - uv[a][0]) / l, (uv[b][1] - uv[a][1]) / l];
                PlaneSpring { a, b, k, l, d }
            })
            .collect();
        let mut h = nalgebra::DMatrix::<f64>::zeros(2 * n, 2 * n);
        let mut biaxial = 0.0;
        for &PlaneSpring { a, b, k, l, d } in &springs {
            biaxial += k * l * l;
            for r in 0..2 {
                for c in 0..2 {
                    let v = k * d[r] * d[c];
                    h[(2 * a + r, 2 * a + c)] += v;
                    h[(2 * b + r, 2 * b + c)] += v;
                    h[(2 * a + r, 2 * b + c)] -= v;
                    h[(2 * b + r, 2 * a + c)] -= v;
                }
            }
        }
        let area: f64 = topo.node_areas.iter().sum();
        // Σ K·L² ε² = A·T·ε² under a biaxial ε (module docs of
        // mesh::springs); the springs' isotropic membrane has λ = μ, T = 8μ.
        let mu = biaxial / area / 8.0;
        let border = mesh.border();
        let inside: Vec<usize> = (0..n).filter(|&i| !border[i]).collect();
        let dofs: Vec<usize> = inside.iter().flat_map(|&i| [2 * i, 2 * i + 1]).collect();
        let h_ii = h.select_rows(&dofs).select_columns(&dofs);
        let chol = h_ii
            .cholesky()
            .expect("the inside's stiffness with its border held is definite");
        let mut line = format!("{} ({n} v, {} inside):", cloth.level, inside.len());
        let mut sums = (0.0, 0.0);
        for (name, [euu, evv, euv]) in strains {
            let affine = nalgebra::DVector::<f64>::from_iterator(
                2 * n,
                uv.iter()
                    .flat_map(|p| [euu * p[0] + euv * p[1], euv * p[0] + evv * p[1]]),
            );
            let energy = |u: &nalgebra::DVector<f64>| 0.5 * u.dot(&(&h * u));
            let e_affine = energy(&affine);
            // The inside relaxed: H_II·u_I = −H_IB·u_B with u_B affine.
            let mut held = affine.clone();
            for &d in &dofs {
                held[d] = 0.0;
            }
            let rhs = -(&h * &held).select_rows(&dofs);
            let u_inside = chol.solve(&rhs);
            let mut relaxed = held;
            for (k, &d) in dofs.iter().enumerate() {
                relaxed[d] = u_inside[k];
            }
            let e_relaxed = energy(&relaxed);
            sums.0 += e_affine;
            sums.1 += e_relaxed;
            let tr = euu + evv;
            let contraction = euu * euu + evv * evv + 2.0 * euv * euv;
            let e_continuum = area * 0.5 * mu * (tr * tr + 2.0 * contraction);
            line += &format!(
                "\n  {name:>12}: affine {:.4}, relaxed {:.4} of the membrane's",
                e_affine / e_continuum,
                e_relaxed / e_continuum
            );
        }
        line += &format!("\n  all three: relaxed {:.4} of affine", sums.1 / sums.0);
        for &k in rings {
            line += &format!(
                "\n  {k}-ring patches: relaxed {:.4} of affine",
                patch_relaxation(&springs, &uv, &border, k, &strains)
            );
        }
        println!("{line}");
    }
}

/// `membrane`'s relaxed-over-affine energy, summed over three strains and
/// over every interior vertex's patch of `k` rings of springs (its ring `k`
/// held affine, the rest relaxed), counting the springs with an end inside.
fn patch_relaxation(
    springs: &[PlaneSpring],
    uv: &[[f64; 2]],
    border: &[bool],
    k: usize,
    strains: &[(&str, [f64; 3]); 3],
) -> f64 {
    let n = uv.len();
    let mut next: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (s, spring) in springs.iter().enumerate() {
        next[spring.a].push(s);
        next[spring.b].push(s);
    }
    let (mut affine_sum, mut relaxed_sum) = (0.0, 0.0);
    let mut depth = vec![usize::MAX; n];
    for centre in (0..n).filter(|&i| !border[i]) {
        // Breadth first to ring k.
        let mut patch = vec![centre];
        depth[centre] = 0;
        let mut head = 0;
        while head < patch.len() {
            let i = patch[head];
            head += 1;
            if depth[i] == k {
                continue;
            }
            for &s in &next[i] {
                let PlaneSpring { a, b, .. } = springs[s];
                let j = if a == i { b } else { a };
                if depth[j] == usize::MAX {
                    depth[j] = depth[i] + 1;
                    patch.push(j);
                }
            }
        }
        let inner: Vec<usize> = patch.iter().copied().filter(|&i| depth[i] < k && !border[i]).collect();
        let index: HashMap<usize, usize> = inner.iter().enumerate().map(|(m, &i)| (i, m)).collect();
        let mut local: Vec<usize> = patch
            .iter()
            .flat_map(|&i| next[i].iter().copied())
            .filter(|&s| {
                let PlaneSpring { a, b, .. } = springs[s];
                depth[a] != usize::MAX && depth[b] != usize::MAX && (index.contains_key(&a) || index.contains_key(&b))
            })
            .collect();
        local.sort_unstable();
        local.dedup();
        let m = 2 * inner.len();
        let mut h = nalgebra::DMatrix::<f64>::zeros(m, m);
        for &s in &local {
            let PlaneSpring { a, b, k: kk, d, .. } = springs[s];
            for (p, q, sign) in [(a, a, 1.0), (b, b, 1.0), (a, b, -1.0), (b, a, -1.0)] {
                if let (Some(&mp), Some(&mq)) = (index.get(&p), index.get(&q)) {
                    for r in 0..2 {
                        for c in 0..2 {
                            h[(2 * mp + r, 2 * mq + c)] += sign * kk * d[r] * d[c];
                        }
                    }
                }
            }
        }
        let chol = h.cholesky().expect("a held patch is definite");
        for &(_, [euu, evv, euv]) in strains {
            let field = |i: usize| [euu * uv[i][0] + euv * uv[i][1], euv * uv[i][0] + evv * uv[i][1]];
            // The held ring's pull on the inside: −H_IB·u_B.
            let mut rhs = nalgebra::DVector::<f64>::zeros(m);
            for &s in &local {
                let PlaneSpring { a, b, k: kk, d, .. } = springs[s];
                for (p, q) in [(a, b), (b, a)] {
                    if let (Some(&mp), None) = (index.get(&p), index.get(&q)) {
                        let u = field(q);
                        let pull = kk * (d[0] * u[0] + d[1] * u[1]);
                        rhs[2 * mp] += pull * d[0];
                        rhs[2 * mp + 1] += pull * d[1];
                    }
                }
            }
            let x = chol.solve(&rhs);
            let at = |i: usize| match index.get(&i) {
                Some(&mi) => [x[2 * mi], x[2 * mi + 1]],
                None => field(i),
            };
            for &s in &local {
                let PlaneSpring { a, b, k: kk, d, .. } = springs[s];
                let stretch = |u: [f64; 2], w: [f64; 2]| d[0] * (w[0] - u[0]) + d[1] * (w[1] - u[1]);
                affine_sum += 0.5 * kk * stretch(field(a), field(b)).powi(2);
                relaxed_sum += 0.5 * kk * stretch(at(a), at(b)).powi(2);
            }
        }
        for &i in &patch {
            depth[i] = usize::MAX;
        }
    }
    relaxed_sum / affine_sum
}

/// A spring in a flat mesh's plane: its ends, K, rest length and unit
/// direction in plane coordinates.
#[derive(Clone, Copy)]
struct PlaneSpring {
    a: usize,
    b: usize,
    k: f64,
    l: f64,
    d: [f64; 2],
}

/// An orthonormal basis of a flat mesh's plane (its first triangle's).
fn tangent_plane(mesh: &TriMesh) -> ([f64; 3], [f64; 3]) {
    let [a, b, c] = mesh.triangles[0].map(|i| mesh.positions[i as usize]);
    lodcloth_core::sim::vec3::tangent_basis(normalize(cross(sub(b, a), sub(c, a))).expect("a triangle with an area"))
}

fn spectrum(args: &Levels, modes: usize, stencils: &str, drape: bool) {
    let mut setup = Setup::new(args);
    restencil(&mut setup, stencils);
    let drape = drape.then(|| {
        let mut reference = setup
            .scene
            .build_on(&setup.levels[0], setup.material(&setup.levels[0], 1.0, 1.0))
            .expect("builds");
        let dc = setup.stepped(&mut reference, setup.scene.duration.round() as usize);
        println!(
            "{}: drape stepped, DC {:.4}",
            setup.levels[0].level,
            dc.last().expect("a second")
        );
        reference.state().pos.clone()
    });
    // The first level's eigenvalues (all, ascending) and the drape's
    // bending energy in each of its modes.
    let mut drape_energy: Option<(Vec<f64>, Vec<f64>)> = None;
    // The first level's modes (its k, and its mode shapes z as values per
    // reference vertex), to read on the others.
    let mut first: Option<(Vec<f64>, Vec<Vec<f64>>)> = None;
    for cloth in &setup.levels {
        let topo = &cloth.topology;
        let n = topo.n_nodes;
        let mut form = nalgebra::DMatrix::<f64>::zeros(n, n);
        for s in 0..topo.bending.len() {
            let (nodes, weights) = topo.bending.row(s);
            for (&i, &wi) in nodes.iter().zip(weights) {
                for (&j, &wj) in nodes.iter().zip(weights) {
                    form[(i as usize, j as usize)] += wi * wj;
                }
            }
        }
        let areas = &topo.node_areas;
        let mut b = form.clone();
        for i in 0..n {
            for j in 0..n {
                b[(i, j)] /= (areas[i] * areas[j]).sqrt();
            }
        }
        let eigen = b.symmetric_eigen();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&i, &j| eigen.eigenvalues[i].total_cmp(&eigen.eigenvalues[j]));
        let values: Vec<f64> = order.iter().map(|&i| eigen.eigenvalues[i]).collect();
        let top = values[n - 1];
        let zero = values.iter().take_while(|&&v| v < 1e-9 * top).count();
        let k: Vec<f64> = values.iter().map(|v| v.max(0.0).powf(0.25)).collect();
        let shown: Vec<usize> = (zero..(zero + modes).min(n)).collect();
        let source = &cloth.mesh.as_ref().expect("a mesh level").source;
        let mut line = format!(
            "{} ({n} v): {zero} zero modes; wavenumbers of the next {} (1/m): {}; largest {:.0}",
            cloth.level,
            shown.len(),
            shown
                .iter()
                .map(|&j| format!("{:.1}", k[j]))
                .collect::<Vec<_>>()
                .join(" "),
            k[n - 1],
        );
        if let (Some((v0, energy)), true) = (&drape_energy, first.is_some()) {
            let upto = n.min(v0.len());
            let (mut num, mut den) = (0.0, 0.0);
            for j in zero..upto {
                num += energy[j] * v0[j] / values[j];
                den += energy[j];
            }
            let total: f64 = energy.iter().sum();
            line += &format!(
                "\n  the drape's energy-weighted λ ratio (first level's over this one's): {:.3}, over the {:.1} % of its energy in this level's {upto} modes",
                num / den,
                100.0 * den / total
            );
        }
        if let Some((k0, shapes)) = &first {
            let ratio = |a: f64, b: f64| format!("{:.3}", (a / b).powi(4));
            let own: Vec<String> = shown.iter().zip(k0).map(|(&j, &b)| ratio(k[j], b)).collect();
            // The first level's mode shapes at this level's vertices: their
            // Rayleigh quotient zᵀWz / zᵀMz here.
            let read: Vec<String> = shapes
                .iter()
                .zip(k0)
                .map(|(shape, &b)| {
                    let z = nalgebra::DVector::from_iterator(n, source.iter().map(|&r| shape[r as usize]));
                    let mass: f64 = (0..n).map(|i| areas[i] * z[i] * z[i]).sum();
                    ratio((z.dot(&(&form * &z)) / mass).powf(0.25), b)
                })
                .collect();
            line += &format!(
                "\n  λ against the first level's: {}\n  the first level's modes read here: {}",
                own.join(" "),
                read.join(" ")
            );
            // Where this level's lowest modes leave the first level's: each
            // mode less its M-projection on the affine fields and the first
            // level's modes at these vertices, as a share of its mass, and
            // that remainder's mass by band (border vertices apart).
            let rest = &topo.rest_positions;
            let mut basis: Vec<nalgebra::DVector<f64>> = vec![
                nalgebra::DVector::from_element(n, 1.0),
                nalgebra::DVector::from_iterator(n, rest.iter().map(|p| p[0])),
                nalgebra::DVector::from_iterator(n, rest.iter().map(|p| p[2])),
            ];
            basis.extend(
                shapes
                    .iter()
                    .map(|shape| nalgebra::DVector::from_iterator(n, source.iter().map(|&r| shape[r as usize]))),
            );
            let m = nalgebra::DVector::from_column_slice(areas);
            let inner = |a: &nalgebra::DVector<f64>, b: &nalgebra::DVector<f64>| a.component_mul(&m).dot(b);
            // M-orthonormalise (modified Gram–Schmidt).
            let mut ortho: Vec<nalgebra::DVector<f64>> = Vec::new();
            for mut v in basis {
                for q in &ortho {
                    v -= q * inner(q, &v);
                }
                let len = inner(&v, &v).sqrt();
                if len > 1e-9 {
                    ortho.push(v / len);
                }
            }
            let border = cloth.mesh.as_ref().expect("a mesh level").mesh.border();
            let r = |i: usize| rest[i][0].hypot(rest[i][2]);
            let mut cells = Vec::new();
            for &j in shown.iter().take(6) {
                let v = eigen.eigenvectors.column(order[j]);
                let mut z = nalgebra::DVector::from_iterator(n, (0..n).map(|i| v[i] / areas[i].sqrt()));
                let total = inner(&z, &z);
                for q in &ortho {
                    z -= q * inner(q, &z);
                }
                let left = inner(&z, &z);
                let share = |keep: &dyn Fn(usize) -> bool| {
                    (0..n).filter(|&i| keep(i)).map(|i| areas[i] * z[i] * z[i]).sum::<f64>() / left
                };
                cells.push(format!(
                    "{:.1} % (border {:.2}, rest of r > 0.14 {:.2}, 0.10–0.14 {:.2}, < 0.10 {:.2})",
                    100.0 * left / total,
                    share(&|i| border[i]),
                    share(&|i| !border[i] && r(i) >= 0.14),
                    share(&|i| (0.10..0.14).contains(&r(i))),
                    share(&|i| r(i) < 0.10),
                ));
            }
            line += &format!("\n  off the first level's modes: {}", cells.join("; "));
        } else {
            let shapes = shown
                .iter()
                .map(|&j| {
                    let v = eigen.eigenvectors.column(order[j]);
                    (0..n).map(|i| v[i] / areas[i].sqrt()).collect()
                })
                .collect();
            first = Some((shown.iter().map(|&j| k[j]).collect(), shapes));
            if let Some(pos) = &drape {
                // E = Σ_j λ_j Σ_c (v_jᵀ M^½ x_c)², x_c one coordinate of the
                // drape (the stencils vanish on the affine rest positions).
                let energy = mode_energies(&eigen.eigenvectors, &order, &values, |row, c| {
                    areas[row].sqrt() * pos[c * n + row]
                });
                let total: f64 = energy.iter().sum();
                let bands = [(0, 12), (12, 24), (24, 50), (50, 100), (100, 200), (200, n - zero)];
                line += &format!(
                    "\n  the drape's bending energy by mode (past the affine ones): {}",
                    bands
                        .iter()
                        .map(|&(a, b)| format!("{a}–{b} {:.3}", energy[zero + a..zero + b].iter().sum::<f64>() / total))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                drape_energy = Some((values.clone(), energy));
            }
        }
        println!("{line}");
    }
}

/// A shape's bending energy in each mode, `λ_j Σ_c (v_jᵀ y_c)²`, the
/// modes the columns `order` of `vectors` (eigenvalues `values`, in that
/// order) and `y(row, c)` the shape's coordinate `c` at a row, scaled by
/// `M^½` (`√A` of the row's vertex).
fn mode_energies(
    vectors: &nalgebra::DMatrix<f64>,
    order: &[usize],
    values: &[f64],
    y: impl Fn(usize, usize) -> f64,
) -> Vec<f64> {
    order
        .iter()
        .zip(values)
        .map(|(&col, &value)| {
            let v = vectors.column(col);
            (0..3)
                .map(|c| (0..v.len()).map(|row| v[row] * y(row, c)).sum::<f64>().powi(2))
                .sum::<f64>()
                * value.max(0.0)
        })
        .collect()
}

/// `spectrum --clamped`: the vertical modes of each level's bending
/// stencils on the free vertices, `W_ff z = λ M_f z` (every pinned vertex
/// held at 0), the ratio of the first level's j-th eigenvalue over each
/// level's, and with `drape` that ratio weighed by the first level's drape
/// energy in each of its modes (its displacement from the start, zero on
/// the pins, so `uᵀWu = u_fᵀ W_ff u_f`).
fn spectrum_clamped(args: &Levels, modes: usize, stencils: &str, drape: bool, modal: Option<&Range<usize>>) {
    let mut setup = Setup::new(args);
    restencil(&mut setup, stencils);
    setup.stiffen(modal);
    let drape = drape.then(|| {
        let first = &setup.levels[0];
        let mut reference = setup
            .scene
            .build_on(first, setup.material(first, 1.0, 1.0))
            .expect("builds");
        let dc = setup.stepped(&mut reference, setup.scene.duration.round() as usize);
        println!("{}: drape stepped, DC {:.4}", first.level, dc.last().expect("a second"));
        reference.state().pos.clone()
    });
    // The first level's eigenvalues (ascending) and its drape's energy per mode.
    let mut first: Option<(Vec<f64>, Option<Vec<f64>>)> = None;
    for cloth in &setup.levels {
        let topo = &cloth.topology;
        let n = topo.n_nodes;
        let sim = setup
            .scene
            .build_on(cloth, setup.material(cloth, 1.0, 1.0))
            .expect("builds");
        let pinned = modal::pinned_flags(n, sim.loads().pins.iter().map(|p| p.node));
        let areas = &topo.node_areas;
        let ClampedModes { free, values, vectors } = ClampedModes::of(topo, &pinned, "level").expect("stencils");
        let m = free.len();
        let order: Vec<usize> = (0..m).collect();
        let k = |v: f64| v.max(0.0).powf(0.25);
        let mut line = format!(
            "{} ({n} v, {m} free): wavenumbers of the {} softest (1/m): {}; largest {:.0}",
            cloth.level,
            modes.min(m),
            values
                .iter()
                .take(modes)
                .map(|&v| format!("{:.1}", k(v)))
                .collect::<Vec<_>>()
                .join(" "),
            k(values[m - 1]),
        );
        match &first {
            None => {
                let energy = drape.as_ref().map(|pos| {
                    // The displacement from the start, where the pins hold.
                    let start = &sim.state().pos;
                    let e = mode_energies(&vectors, &order, &values, |f, c| {
                        let i = free[f] as usize;
                        areas[i].sqrt() * (pos[c * n + i] - start[c * n + i])
                    });
                    let total: f64 = e.iter().sum();
                    let bands = [(0, 12), (12, 24), (24, 50), (50, 100), (100, 200), (200, m)];
                    line += &format!(
                        "\n  the drape's bending energy by mode: {}",
                        bands
                            .iter()
                            .filter(|&&(a, _)| a < m)
                            .map(|&(a, b)| format!("{a}–{b} {:.3}", e[a..b.min(m)].iter().sum::<f64>() / total))
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                    e
                });
                first = Some((values, energy));
            }
            Some((v0, energy)) => {
                let upto = m.min(v0.len());
                line += &format!(
                    "\n  first level's λ over this one's, softest {}: {}",
                    modes.min(upto),
                    (0..modes.min(upto))
                        .map(|j| format!("{:.3}", v0[j] / values[j]))
                        .collect::<Vec<_>>()
                        .join(" ")
                );
                let bands = [(0, 12), (12, 24), (24, 50), (50, 100), (100, 200), (200, upto)];
                line += &format!(
                    "\n  by band (mean): {}",
                    bands
                        .iter()
                        .filter(|&&(a, b)| a < b.min(upto))
                        .map(|&(a, b)| {
                            let b = b.min(upto);
                            format!(
                                "{a}–{b} {:.3}",
                                (a..b).map(|j| v0[j] / values[j]).sum::<f64>() / (b - a) as f64
                            )
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                if let Some(e) = energy {
                    let (num, den) = (0..upto).fold((0.0, 0.0), |(n, d), j| (n + e[j] * v0[j] / values[j], d + e[j]));
                    let total: f64 = e.iter().sum();
                    line += &format!(
                        "\n  the drape's energy-weighted λ ratio (first level's over this one's): {:.3}, over the {:.1} % of its energy in this level's {upto} modes",
                        num / den,
                        100.0 * den / total
                    );
                }
            }
        }
        println!("{line}");
    }
}

/// `write`'s remeshing.
struct Remesh {
    relax: usize,
    flip: bool,
    shuffle: f64,
    seed: u64,
    top: Option<(f64, usize)>,
}

fn write(args: &Levels, out: &Path, how: &Remesh) {
    assert!(
        (0.0..=1.0).contains(&how.shuffle),
        "--shuffle must be a share in [0, 1], got {}",
        how.shuffle
    );
    let setup = Setup::new(args);
    let level = setup.levels.first().expect("one level");
    let mut mesh = level.mesh.as_ref().expect("a mesh level").mesh.clone();
    let mut comment = format!("level {} of {}", level.level, args.scene.display());
    if let Some((radius, top)) = how.top {
        let cloth = setup.scene.mesh.as_ref().expect("a mesh scene");
        let r = &cloth.reference;
        let outside: Vec<bool> = r
            .positions
            .iter()
            .zip(&cloth.locked)
            .map(|(p, &l)| l || p[0].hypot(p[2]) >= radius)
            .collect();
        let kept = outside.iter().filter(|&&o| o).count();
        let first = lodcloth_core::mesh::simplify(r, kept + top, &outside, "top").expect("simplifies");
        let locked: Vec<bool> = first.source.iter().map(|&j| cloth.locked[j as usize]).collect();
        let target = mesh.vertices();
        mesh = lodcloth_core::mesh::simplify(&first.mesh, target, &locked, "graded")
            .expect("simplifies")
            .mesh;
        comment += &format!(", graded: inside r = {radius} m collapsed to {top} vertices first");
    }
    let before = Shapes::of(&mesh);
    if how.relax > 0 || how.flip {
        let flips = remesh(&mut mesh, how.relax, how.flip);
        comment += &format!(
            ", remeshed in its rest plane: {} relaxation sweeps, {flips} Delaunay flips",
            how.relax
        );
    }
    if how.shuffle > 0.0 {
        let (flips, interior) = shuffled(&mut mesh, how.shuffle, how.seed);
        comment += &format!(
            ", {flips} of its {interior} interior edges flipped at random (seed {}), vertices kept",
            how.seed
        );
    }
    println!("{comment}\n  before: {before}\n  after:  {}", Shapes::of(&mesh));
    std::fs::write(out, lodcloth_core::mesh::generate::to_obj(&mesh, &comment))
        .unwrap_or_else(|e| panic!("{}: {e}", out.display()));
}

/// How even a mesh's triangles are: the CV of their areas, the 10th
/// percentile and median of their quality (4√3·A / Σ edge², 1 for an
/// equilateral triangle) and the interior vertices' valences.
struct Shapes {
    area_cv: f64,
    quality: [f64; 2],
    valence: [usize; 2],
    /// The interior valences' standard deviation (0 on a regular mesh).
    valence_sd: f64,
}

impl Shapes {
    fn of(mesh: &TriMesh) -> Shapes {
        let p = &mesh.positions;
        let areas: Vec<f64> = mesh.triangles.iter().map(|&t| triangle_area(p, t)).collect();
        let mean = areas.iter().sum::<f64>() / areas.len() as f64;
        let var = areas.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / areas.len() as f64;
        let d2 = |a: u32, b: u32| dist(p[a as usize], p[b as usize]).powi(2);
        let mut quality: Vec<f64> = mesh
            .triangles
            .iter()
            .zip(&areas)
            .map(|(&[a, b, c], area)| 4.0 * 3f64.sqrt() * area / (d2(a, b) + d2(b, c) + d2(c, a)))
            .collect();
        quality.sort_by(f64::total_cmp);
        let border = mesh.border();
        let mut valence = vec![0usize; mesh.vertices()];
        for t in &mesh.triangles {
            for &i in t {
                valence[i as usize] += 1;
            }
        }
        let interior = || valence.iter().zip(&border).filter(|(_, &b)| !b).map(|(&v, _)| v);
        let count = interior().count().max(1) as f64;
        let valence_mean = interior().sum::<usize>() as f64 / count;
        Shapes {
            area_cv: var.sqrt() / mean,
            quality: [quality[quality.len() / 10], quality[quality.len() / 2]],
            valence: [interior().min().unwrap_or(0), interior().max().unwrap_or(0)],
            valence_sd: (interior().map(|v| (v as f64 - valence_mean).powi(2)).sum::<f64>() / count).sqrt(),
        }
    }
}

impl std::fmt::Display for Shapes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "area CV {:.3}, quality p10 {:.3} median {:.3}, interior valences {}-{} (sd {:.2})",
            self.area_cv, self.quality[0], self.quality[1], self.valence[0], self.valence[1], self.valence_sd
        )
    }
}

/// Remesh a flat `mesh` in its rest plane, border fixed: Delaunay flips
/// (when `flip`), `sweeps` of tangential relaxation, flips again. Returns
/// the flips made. Panics if a triangle turns over.
fn remesh(mesh: &mut TriMesh, sweeps: usize, flip: bool) -> usize {
    let normal = |p: &[[f64; 3]], [a, b, c]: [u32; 3]| {
        let a = p[a as usize];
        cross(sub(p[b as usize], a), sub(p[c as usize], a))
    };
    let up = mesh
        .triangles
        .iter()
        .fold([0.0; 3], |s, &t| add(s, normal(&mesh.positions, t)));
    for &t in &mesh.triangles {
        let m = normal(&mesh.positions, t);
        assert!(
            dot(m, up) > (1.0 - 1e-9) * norm(m) * norm(up),
            "--relax/--flip need a flat rest shape: triangle {t:?} is tilted"
        );
    }
    let mut flips = if flip {
        lodcloth_lab::stencils::delaunay_flips(mesh)
    } else {
        0
    };
    let border = mesh.border();
    let n = mesh.vertices();
    for _ in 0..sweeps {
        let mut sum = vec![[0.0; 3]; n];
        let mut weight = vec![0.0; n];
        for &t in &mesh.triangles {
            let area = triangle_area(&mesh.positions, t);
            let c = t.iter().fold([0.0; 3], |s, &i| add(s, mesh.positions[i as usize]));
            for &i in &t {
                sum[i as usize] = add(sum[i as usize], scale(c, area / 3.0));
                weight[i as usize] += area;
            }
        }
        for i in (0..n).filter(|&i| !border[i] && weight[i] > 0.0) {
            mesh.positions[i] = sum[i].map(|x| x / weight[i]);
        }
    }
    if flip {
        flips += lodcloth_lab::stencils::delaunay_flips(mesh);
    }
    for &t in &mesh.triangles {
        let m = normal(&mesh.positions, t);
        assert!(dot(m, up) > 0.0, "triangle {t:?} turned over");
    }
    flips
}

/// Directed edge a→b → (its triangle, the vertex facing it).
type Facing = HashMap<(u32, u32), (usize, u32)>;

/// Each directed edge of `mesh`'s triangles with its triangle and the
/// vertex facing it, and the undirected edges (lower index first).
fn adjacency(mesh: &TriMesh) -> (Facing, HashSet<(u32, u32)>) {
    let mut facing = HashMap::new();
    let mut edges = HashSet::new();
    for (k, &[a, b, c]) in mesh.triangles.iter().enumerate() {
        for (x, y, z) in [(a, b, c), (b, c, a), (c, a, b)] {
            facing.insert((x, y), (k, z));
            edges.insert((x.min(y), x.max(y)));
        }
    }
    (facing, edges)
}

/// Flip `share` of `mesh`'s interior edges, drawn at random (seeded), its
/// vertices kept: each edge once, in a seeded shuffle, where its two
/// triangles make a convex quad (the new edge inside it), neither was
/// flipped already, the new edge is not one already, and valences stay
/// 4–9 inside and ≥ 2 on the border. Returns the flips made and the
/// interior edges.
fn shuffled(mesh: &mut TriMesh, share: f64, seed: u64) -> (usize, usize) {
    let (facing, mut edges) = adjacency(mesh);
    let mut interior: Vec<(u32, u32)> = facing
        .keys()
        .copied()
        .filter(|&(a, b)| a < b && facing.contains_key(&(b, a)))
        .collect();
    interior.sort_unstable();
    let mut rng = lodcloth_core::points::generate::SplitMix(seed);
    for i in (1..interior.len()).rev() {
        interior.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let border = mesh.border();
    let mut valence = vec![0usize; mesh.vertices()];
    for t in &mesh.triangles {
        for &i in t {
            valence[i as usize] += 1;
        }
    }
    let up = mesh.triangles.iter().fold([0.0; 3], |s, &[a, b, c]| {
        let p = &mesh.positions;
        add(
            s,
            cross(sub(p[b as usize], p[a as usize]), sub(p[c as usize], p[a as usize])),
        )
    });
    let turns = |p: &[[f64; 3]], [a, b, c]: [u32; 3]| {
        dot(
            cross(sub(p[b as usize], p[a as usize]), sub(p[c as usize], p[a as usize])),
            up,
        ) > 0.0
    };
    let target = (share * interior.len() as f64).round() as usize;
    let mut touched = vec![false; mesh.triangles.len()];
    let mut flips = 0;
    for &(a, b) in &interior {
        if flips == target {
            break;
        }
        let (t1, c) = facing[&(a, b)];
        let (t2, d) = facing[&(b, a)];
        // After losing a triangle: ≥ 4 neighbours inside, ≥ 2 triangles on the border.
        let loses = |v: u32| valence[v as usize] > if border[v as usize] { 2 } else { 4 };
        let gains = |v: u32| border[v as usize] || valence[v as usize] < 9;
        if touched[t1]
            || touched[t2]
            || edges.contains(&(c.min(d), c.max(d)))
            || !(loses(a) && loses(b) && gains(c) && gains(d))
        {
            continue;
        }
        // a→b→c and b→a→d counter-clockwise: the quad is a, d, b, c.
        let (n1, n2) = ([a, d, c], [d, b, c]);
        if !(turns(&mesh.positions, n1) && turns(&mesh.positions, n2)) {
            continue;
        }
        mesh.triangles[t1] = n1;
        mesh.triangles[t2] = n2;
        edges.insert((c.min(d), c.max(d)));
        touched[t1] = true;
        touched[t2] = true;
        for (v, by) in [(a, -1), (b, -1), (c, 1), (d, 1)] {
            valence[v as usize] = valence[v as usize].wrapping_add_signed(by);
        }
        flips += 1;
    }
    (flips, interior.len())
}

/// The runs from rest in the `--csv` files: DC at each run's end against
/// its vertex count (the mean over its twins), one series per file, bend
/// and stretch scale.
fn chart(paths: &[PathBuf], names: &[String], unscaled: bool, legend: Corner, out: &Path) {
    assert!(
        names.is_empty() || names.len() == paths.len(),
        "--names: one per --csv file ({} files, {} names)",
        paths.len(),
        names.len()
    );
    use lodcloth::output::{line_chart_svg_legend, Series, PALETTE};
    use plotters::prelude::SeriesLabelPosition;
    use std::collections::BTreeMap;
    // (file, bend, stretch) → run (scene, vertices, dt, twin) → (last time, DC).
    type Key = (usize, String, String);
    type RunKey = (Key, String, String, String, String);
    let mut last: BTreeMap<RunKey, (f64, f64)> = Default::default();
    for (file, path) in paths.iter().enumerate() {
        let shown = path.display();
        let mut reader = csv::Reader::from_path(path).unwrap_or_else(|e| panic!("{shown}: {e}"));
        for row in reader.records() {
            let row = row.unwrap_or_else(|e| panic!("{shown}: {e}"));
            if &row[5] != "rest" || (unscaled && (&row[2] != "1" || &row[3] != "1")) {
                continue;
            }
            let number = |i: usize| {
                row[i]
                    .parse::<f64>()
                    .unwrap_or_else(|_| panic!("{shown}: column {i}: {}", &row[i]))
            };
            number(1); // the vertex count, checked here to be a number
            let key = (
                (file, row[2].to_string(), row[3].to_string()),
                row[0].to_string(),
                row[1].to_string(),
                row[4].to_string(),
                // Files written before twins have no such column: one run each.
                row.get(9).unwrap_or("0").to_string(),
            );
            let (t, dc) = (number(6), number(7));
            let e = last.entry(key).or_insert((t, dc));
            if t >= e.0 {
                *e = (t, dc);
            }
        }
    }
    // (file, bend, stretch) → (scene, vertices, dt) → the twins' DC.
    type Twins = BTreeMap<(String, String, String), Vec<f64>>;
    let mut twins: BTreeMap<Key, Twins> = Default::default();
    for ((key, scene, vertices, dt, _), (_, dc)) in last {
        twins
            .entry(key)
            .or_default()
            .entry((scene, vertices, dt))
            .or_default()
            .push(dc);
    }
    let series: BTreeMap<Key, Vec<(f64, f64)>> = twins
        .into_iter()
        .map(|(key, runs)| {
            let mut points: Vec<(f64, f64)> = runs
                .into_iter()
                .map(|((_, vertices, _), dc)| {
                    let x: f64 = vertices.parse().expect("checked above");
                    (x, dc.iter().sum::<f64>() / dc.len() as f64)
                })
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            (key, points)
        })
        .collect();
    let labels: Vec<String> = series
        .keys()
        .map(|(file, b, s)| {
            let scales = format!("bend ×{b}, stretch ×{s}");
            let name = names.get(*file).cloned().or_else(|| {
                (paths.len() > 1).then(|| {
                    paths[*file]
                        .file_stem()
                        .unwrap_or_default()
                        .to_string_lossy()
                        .into_owned()
                })
            });
            match name {
                Some(name) if b == "1" && s == "1" => name,
                Some(name) => format!("{name}: {scales}"),
                None => scales,
            }
        })
        .collect();
    let drawn: Vec<Series<'_>> = series
        .into_values()
        .zip(&labels)
        .enumerate()
        .map(|(i, (points, name))| Series {
            name,
            points,
            markers: true,
            color: PALETTE[i % PALETTE.len()],
        })
        .collect();
    line_chart_svg_legend(
        out,
        "Cusick drape coefficient at the end of each run, from rest",
        ("vertices", "drape coefficient"),
        &drawn,
        (true, false),
        match legend {
            Corner::UpperLeft => SeriesLabelPosition::UpperLeft,
            Corner::UpperRight => SeriesLabelPosition::UpperRight,
            Corner::LowerLeft => SeriesLabelPosition::LowerLeft,
            Corner::LowerRight => SeriesLabelPosition::LowerRight,
        },
    )
    .unwrap_or_else(|e| panic!("{}: {e}", out.display()));
}

fn main() {
    match <Command as clap::Parser>::parse() {
        Command::Run {
            runs,
            dt,
            integrator,
            live,
            twins,
            jitter,
            stencils_from,
            stencils,
        } => {
            let integrator = integrator.map(|name| {
                Integrator::from_name(&name).unwrap_or_else(|| panic!("--integrator: no integrator named {name}"))
            });
            let stepping = Stepping { dt, integrator, live };
            run(&runs, stepping, twins, jitter, stencils_from.as_deref(), &stencils)
        }
        Command::Restart {
            runs,
            unstressed,
            settle,
        } => restart(&runs, unstressed, settle),
        Command::Spectrum {
            levels,
            modes,
            stencils,
            drape,
            clamped,
            modal,
        } => {
            if clamped {
                spectrum_clamped(&levels, modes, &stencils, drape, modal.as_ref())
            } else {
                spectrum(&levels, modes, &stencils, drape)
            }
        }
        Command::Membrane { levels, rings } => membrane(&levels, &rings),
        Command::Write {
            levels,
            out,
            relax,
            flip,
            shuffle,
            seed,
            top_radius,
            top_vertices,
        } => write(
            &levels,
            &out,
            &Remesh {
                relax,
                flip,
                shuffle,
                seed,
                top: top_radius.map(|r| (r, top_vertices)),
            },
        ),
        Command::Chart {
            csv,
            names,
            unscaled,
            legend,
            out,
        } => chart(&csv, &names, unscaled, legend, &out),
    }
}
