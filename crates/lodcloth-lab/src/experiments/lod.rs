//! Level-of-detail experiments: the paper's Table 1 and beyond, the
//! speed/accuracy Pareto front, LOD planning and level-switch continuity.
//! No files and no printing here: results come back as values, progress as
//! log lines through a callback; the `lodcloth-lab` binary (src/cli/experiment.rs) writes CSV, markdown and charts.

use std::sync::Arc;
use std::time::Instant;

use rayon::prelude::*;

use lodcloth_core::estimate::{
    no_progress, ErrorReport, EstimateError, FitOptions, LodProblem, Method, Reading, RecordSpec, Reference,
};
use lodcloth_core::lod::transfer_state;
use lodcloth_core::plan::{default_problem, level_dt, stable_problem, Estimator, GridLevel, PlanError};
use lodcloth_core::scene::{MassConvention, Scene};
use lodcloth_core::sim::{Integrator, Material};

/// A method under a mass convention: one column of Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Variant {
    pub method: Method,
    pub mass: MassConvention,
    /// How BCD and GKD read the paper (ignored by the other methods but
    /// `fit`, whose `gkd` start candidate uses it).
    pub reading: Reading,
}

impl Variant {
    /// `method` under `mass`, with the default reading.
    pub const fn new(method: Method, mass: MassConvention) -> Variant {
        Variant {
            method,
            mass,
            reading: Reading::DEFAULT,
        }
    }

    /// `method/mass`, e.g. `gkd/per_node`; BCD and GKD under a reading
    /// other than the default name it: `gkd[totals_lsq]/per_node`.
    pub fn label(&self) -> String {
        if matches!(self.method, Method::Bcd | Method::Gkd) && self.reading != Reading::DEFAULT {
            format!("{}[{}]/{}", self.method, self.reading, self.mass.name())
        } else {
            format!("{}/{}", self.method, self.mass.name())
        }
    }
}

/// The paper's three methods under its mass convention (its "same" is the
/// per-spring copy), the same three with lumped masses (our `same`: the
/// material converted per direction), and ours.
pub const TABLE1_VARIANTS: [Variant; 8] = [
    Variant::new(Method::SameSpring, MassConvention::PerNode),
    Variant::new(Method::Bcd, MassConvention::PerNode),
    Variant::new(Method::Gkd, MassConvention::PerNode),
    Variant::new(Method::Same, MassConvention::Lumped),
    Variant::new(Method::Bcd, MassConvention::Lumped),
    Variant::new(Method::Gkd, MassConvention::Lumped),
    Variant::new(Method::Lsq, MassConvention::Lumped),
    Variant::new(Method::Fit, MassConvention::Lumped),
];

/// Options of [`table1_scene`].
#[derive(Debug, Clone)]
pub struct Table1Options {
    /// Levels as named (each resolved against the scene's aspect ratio).
    pub levels: Vec<GridLevel>,
    pub spec: RecordSpec,
    pub variants: Vec<Variant>,
    pub fit: FitOptions,
    /// dt of a level as a fraction of the `same` model's stability limit.
    pub dt_margin: f64,
    /// Level whose worst-frame error maps are kept.
    pub map_level: GridLevel,
    /// Window of the short-horizon measure (s): the level restarts from the
    /// reference's state this often ([`LodProblem::score_windows`]).
    pub short_window: f64,
}

/// One cell of Table 1 (scene × level × variant).
#[derive(Debug, Clone)]
pub struct Table1Row {
    pub scene: String,
    /// The level as named; `nx × ny` is what it is on this scene.
    pub level: GridLevel,
    pub nx: usize,
    pub ny: usize,
    pub nodes: usize,
    /// 1 − coarse nodes / reference nodes.
    pub reduction: f64,
    pub variant: Variant,
    pub material: Material,
    pub dt: f64,
    /// dt over the model's predicted stability limit.
    pub dt_ratio: f64,
    /// Over every frame.
    pub all: ErrorReport,
    /// Over the held-out frames (after the fit's training window).
    pub held_out_mean: f64,
    /// Over the held-out frames, restarted from the reference every
    /// `short_window` seconds (the short-horizon measure).
    pub short_held_out_mean: f64,
    pub estimate_seconds: f64,
    /// Wall seconds per simulated second of the coarse run.
    pub cost: f64,
    pub notes: String,
}

/// Table 1 for one scene: every level and variant.
pub fn table1_scene(
    scene: &Scene,
    reference: &Arc<Reference>,
    options: &Table1Options,
    estimator: &Estimator,
    log: &mut dyn FnMut(String),
) -> Result<Vec<Table1Row>, PlanError> {
    let frames = reference.frames.len();
    let train = options.fit.train_range(frames);
    let held_out = train.end..frames;
    if held_out.is_empty() {
        return Err(PlanError::Invalid(
            "the fit's training window covers every frame: nothing is held out".into(),
        ));
    }
    let n_ref = reference.topology.n_nodes;
    let integrator = scene.params.integrator;
    let run = |level: GridLevel, variant: &Variant| -> Result<Table1Row, PlanError> {
        let (nx, ny) = level.resolve(scene.width, scene.height);
        // dt from the `same` model, then checked against the estimate.
        let (dt, _) = level_dt(
            scene,
            reference,
            (nx, ny),
            variant.mass,
            integrator,
            scene.material_at(nx, ny),
            options.dt_margin,
        )?;
        let problem = LodProblem::new(scene, reference.clone(), nx, ny, variant.mass, integrator, dt)?;
        let mut fit = options.fit.clone();
        fit.train = Some(train.clone());
        fit.reading = variant.reading;
        let est = estimator.estimate(&problem, variant.method, &fit)?;
        // A model estimated stiffer than the level's dt allows gets its own dt.
        let (problem, limit) = stable_problem(&problem, est.material)?;
        let dt = problem.dt;
        let t1 = Instant::now();
        let all = problem.score(est.material, 0..frames, &mut no_progress)?;
        let cost = t1.elapsed().as_secs_f64() / (frames as f64 * reference.dt * reference.spec.metric_stride as f64);
        let interval = reference.dt * reference.spec.metric_stride as f64;
        let window = ((options.short_window / interval).round() as usize).max(1);
        let short = problem.score_windows(est.material, held_out.clone(), window, &mut no_progress)?;
        let keep_map = level == options.map_level;
        Ok(Table1Row {
            scene: scene.name.clone(),
            level,
            nx,
            ny,
            nodes: nx * ny,
            reduction: 1.0 - (nx * ny) as f64 / n_ref as f64,
            variant: *variant,
            material: est.material,
            dt,
            dt_ratio: dt / limit,
            held_out_mean: all.mean_over(held_out.clone()),
            short_held_out_mean: short.mean,
            all: if keep_map { all } else { strip(all) },
            estimate_seconds: est.seconds,
            cost,
            notes: est.notes,
        })
    };
    let mut rows = Vec::new();
    for &level in &options.levels {
        // Variants run side by side on both cores (each one single-threaded
        // except `fit`, which shares rayon's pool); costs are therefore
        // measured with the other core busy too, like a daemon's instances.
        let level_rows: Vec<Result<Table1Row, PlanError>> =
            options.variants.par_iter().map(|v| run(level, v)).collect();
        for row in level_rows {
            let r = row?;
            log(format!(
                "{} {}×{} {:<14} mean {:6.2}%  held-out {:6.2}% (short horizon {:5.2}%)  p95 {:6.2}%  dt {:.2e} ({:.2} of limit)  est {:.1}s  {}",
                scene.name,
                r.nx,
                r.ny,
                r.variant.label(),
                100.0 * r.all.mean,
                100.0 * r.held_out_mean,
                100.0 * r.short_held_out_mean,
                100.0 * r.all.p95,
                r.dt,
                r.dt_ratio,
                r.estimate_seconds,
                r.notes
            ));
            rows.push(r);
        }
    }
    Ok(rows)
}

/// Drop the per-node vectors of reports that no map needs.
fn strip(mut r: ErrorReport) -> ErrorReport {
    r.node_mean = Vec::new();
    r.worst_frame_nodes = Vec::new();
    r.worst_positions = Vec::new();
    r.frame_means = Vec::new();
    r
}

/// A level-switch experiment's outcome (fine → coarse and back).
#[derive(Debug, Clone)]
pub struct SwitchReport {
    pub switch_time: f64,
    /// Largest distance between a coarse node right after the switch and its
    /// coherent (mapped) reference position (m).
    pub position_jump: f64,
    /// |KE_coarse − KE_fine| / KE_fine at the switch.
    pub kinetic_jump: f64,
    /// Mean eq.-9 error over the window after the switch: switched with
    /// transfer, never switched (coarse from t = 0), switched with zeroed
    /// velocities.
    pub error_transfer: f64,
    pub error_never_switched: f64,
    pub error_zero_velocity: f64,
    /// Coarse → fine: kinetic-energy jump and the fine run's error against the
    /// reference over the window.
    pub back_kinetic_jump: f64,
    pub back_error: f64,
}

fn kinetic(masses: &[f64], vel: &[f64]) -> f64 {
    let n = masses.len();
    (0..n)
        .map(|k| 0.5 * masses[k] * (0..3).map(|c| vel[c * n + k].powi(2)).sum::<f64>())
        .sum()
}

/// Switch between the reference and `problem`'s level at metric frame
/// `at` and score the `window` frames that follow.
pub fn switch_test(
    problem: &LodProblem,
    material: Material,
    at: usize,
    window: usize,
) -> Result<SwitchReport, PlanError> {
    let reference = &problem.reference;
    let frames = reference.frames.len();
    if at == 0 || at + window > frames {
        return Err(PlanError::Invalid(format!(
            "switch at frame {at} with a {window}-frame window does not fit in {frames} frames"
        )));
    }
    // Re-run the fine reference to the switch frame (the recording keeps f32
    // positions only; a switch needs the f64 state with velocities).
    let mut fine = reference.scene_as_run(&problem.scene).build()?;
    let steps = reference.frame_steps[at - 1];
    for _ in 0..steps {
        fine.step();
    }
    let fine_state = fine.state().clone();
    let n = problem.topology().n_nodes;
    let score_from = |sim: &mut lodcloth_core::sim::Simulation| -> f64 {
        let mut acc = lodcloth_core::estimate::ErrorAccumulator::new(reference.o_max, n, window);
        let mut mapped = vec![0.0; 3 * n];
        let per = (reference.dt * reference.spec.metric_stride as f64 / problem.dt).round() as usize;
        for f in at..at + window {
            for _ in 0..per {
                sim.step();
            }
            if sim.diverged() {
                return f64::INFINITY;
            }
            problem.correlation().map(&reference.frames[f], &mut mapped);
            acc.push(reference.frame_times[f], &mapped, &sim.state().pos);
        }
        acc.mean()
    };
    // Fine → coarse with transfer.
    let coarse_state =
        transfer_state(&reference.topology, &fine_state, problem.topology()).map_err(EstimateError::from)?;
    let mut coarse = problem.simulation(material)?;
    coarse
        .set_state(coarse_state.clone())
        .map_err(|source| EstimateError::Sim {
            level: problem.level,
            source,
        })?;
    let mut mapped = vec![0.0; 3 * n];
    problem.correlation().map(&fine_state.pos, &mut mapped);
    let position_jump = (0..n)
        .map(|k| {
            (0..3)
                .map(|c| (coarse.state().pos[c * n + k] - mapped[c * n + k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    let ke_fine = kinetic(fine.masses(), &fine_state.vel);
    let ke_coarse = kinetic(coarse.masses(), &coarse.state().vel);
    let kinetic_jump = (ke_coarse - ke_fine).abs() / ke_fine.max(f64::MIN_POSITIVE);
    let error_transfer = score_from(&mut coarse);
    // Never switched: the coarse model from t = 0.
    let mut never = problem.simulation(material)?;
    let per = (reference.dt * reference.spec.metric_stride as f64 / problem.dt).round() as usize;
    for _ in 0..at * per {
        never.step();
    }
    let error_never_switched = score_from(&mut never);
    // Zeroed velocities.
    let mut zero = problem.simulation(material)?;
    let mut z = coarse_state.clone();
    z.vel.iter_mut().for_each(|v| *v = 0.0);
    zero.set_state(z).map_err(|source| EstimateError::Sim {
        level: problem.level,
        source,
    })?;
    let error_zero_velocity = score_from(&mut zero);
    // Coarse → fine: the coarse model's state at the switch back onto the
    // reference cloth, continued with the reference's coefficients.
    let mut coarse_run = problem.simulation(material)?;
    for _ in 0..at * per {
        coarse_run.step();
    }
    let back =
        transfer_state(problem.topology(), coarse_run.state(), &reference.topology).map_err(EstimateError::from)?;
    let ke_c = kinetic(coarse_run.masses(), &coarse_run.state().vel);
    let mut fine2 = reference.scene_as_run(&problem.scene).build()?;
    fine2.set_state(back).map_err(|source| EstimateError::Sim {
        level: problem.scene.reference_level(),
        source,
    })?;
    let back_kinetic_jump = (kinetic(fine2.masses(), &fine2.state().vel) - ke_c).abs() / ke_c.max(f64::MIN_POSITIVE);
    let nf = reference.topology.n_nodes;
    let mut acc = lodcloth_core::estimate::ErrorAccumulator::new(reference.o_max, nf, window);
    let mut refpos = vec![0.0; 3 * nf];
    for f in at..at + window {
        for _ in 0..reference.spec.metric_stride {
            fine2.step();
        }
        for (d, &s) in refpos.iter_mut().zip(&reference.frames[f]) {
            *d = f64::from(s);
        }
        acc.push(reference.frame_times[f], &refpos, &fine2.state().pos);
    }
    Ok(SwitchReport {
        switch_time: reference.frame_times[at - 1],
        position_jump,
        kinetic_jump,
        error_transfer,
        error_never_switched,
        error_zero_velocity,
        back_kinetic_jump,
        back_error: acc.mean(),
    })
}

/// One point of the speed/accuracy chart.
#[derive(Debug, Clone)]
pub struct ParetoPoint {
    pub nx: usize,
    pub ny: usize,
    pub method: Method,
    pub integrator: Integrator,
    pub dt: f64,
    pub dt_ratio: f64,
    /// Wall seconds per simulated second.
    pub cost: f64,
    pub mean_error: f64,
    pub on_front: bool,
}

/// Speed against accuracy over levels, methods, integrators and dt.
pub fn pareto(
    scene: &Scene,
    reference: &Arc<Reference>,
    levels: &[GridLevel],
    methods: &[Method],
    integrators: &[Integrator],
    dt_fractions: &[f64],
    implicit_fractions: &[f64],
    fit: &FitOptions,
    estimator: &Estimator,
    log: &mut dyn FnMut(String),
) -> Result<Vec<ParetoPoint>, PlanError> {
    let frames = reference.frames.len();
    let mut points = Vec::new();
    for &level in levels {
        let (nx, ny) = level.resolve(scene.width, scene.height);
        // Estimate once per method with the scene's integrator at half its limit.
        let base = default_problem(scene, reference, (nx, ny))?;
        for &method in methods {
            let material = estimator.estimate(&base, method, fit)?.material;
            for &integrator in integrators {
                // Implicit Euler and XPBD are stable at any dt: their
                // fractions are of 4× the symplectic limit, and may exceed 1.
                let (probe_integrator, scale, fractions) = if integrator.unconditionally_stable() {
                    (Integrator::SymplecticEuler, 4.0, implicit_fractions)
                } else {
                    (integrator, 1.0, dt_fractions)
                };
                for &frac in fractions {
                    let (dt, limit) = level_dt(
                        scene,
                        reference,
                        (nx, ny),
                        MassConvention::Lumped,
                        probe_integrator,
                        material,
                        frac * scale,
                    )?;
                    let p = LodProblem::new(scene, reference.clone(), nx, ny, MassConvention::Lumped, integrator, dt)?;
                    let t = Instant::now();
                    let r = p.score(material, 0..frames, &mut no_progress)?;
                    let cost = t.elapsed().as_secs_f64()
                        / (frames as f64 * reference.dt * reference.spec.metric_stride as f64);
                    log(format!(
                        "{nx}×{ny} {method:<4} {:<16} dt {dt:.2e} ({:.2} of limit): {:.3} s/s, error {:.2}%",
                        integrator.name(),
                        dt / limit,
                        cost,
                        100.0 * r.mean
                    ));
                    points.push(ParetoPoint {
                        nx,
                        ny,
                        method,
                        integrator,
                        dt,
                        dt_ratio: dt / limit,
                        cost,
                        mean_error: r.mean,
                        on_front: false,
                    });
                }
            }
        }
    }
    mark_front(&mut points);
    Ok(points)
}

/// Mark the points no other point beats in both cost and error.
pub fn mark_front(points: &mut [ParetoPoint]) {
    let snapshot: Vec<(f64, f64)> = points.iter().map(|p| (p.cost, p.mean_error)).collect();
    for (i, p) in points.iter_mut().enumerate() {
        let (c, e) = snapshot[i];
        p.on_front = e.is_finite()
            && !snapshot
                .iter()
                .enumerate()
                .any(|(j, &(cj, ej))| j != i && cj <= c && ej <= e && (cj < c || ej < e));
    }
}

/// Outcome of [`lod_plan`] for one level tried.
#[derive(Debug, Clone)]
pub struct PlanStep {
    pub nx: usize,
    pub ny: usize,
    pub material: Material,
    pub dt: f64,
    pub held_out_mean: f64,
    pub accepted: bool,
}

/// Which error a plan bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Horizon {
    /// Sung eq. 9 over one run from rest.
    Long,
    /// The level restarted from the reference every `window` seconds
    /// ([`LodProblem::score_windows`]): for motions whose long runs drift
    /// from any model (a cloth turning about one pin, flapping in wind).
    Short {
        /// Seconds between restarts.
        window: f64,
    },
}

/// The coarsest level (trying `levels` from coarsest) whose fitted model
/// stays within `max_error` on held-out frames, in `horizon`.
pub fn lod_plan(
    scene: &Scene,
    reference: &Arc<Reference>,
    levels: &[GridLevel],
    max_error: f64,
    horizon: Horizon,
    fit: &FitOptions,
    estimator: &Estimator,
    log: &mut dyn FnMut(String),
) -> Result<Vec<PlanStep>, PlanError> {
    // Levels coarser than the reference, from the fewest nodes up.
    let mut levels: Vec<(usize, usize)> = levels
        .iter()
        .map(|l| l.resolve(scene.width, scene.height))
        .filter(|&(nx, ny)| nx <= scene.nx && ny <= scene.ny && nx * ny < scene.nx * scene.ny)
        .collect();
    levels.sort_unstable_by_key(|&(nx, ny)| (nx * ny, nx));
    levels.dedup();
    let frames = reference.frames.len();
    let train = fit.train_range(frames);
    let mut steps = Vec::new();
    for (nx, ny) in levels {
        let p = default_problem(scene, reference, (nx, ny))?;
        let est = estimator.estimate(&p, Method::Fit, fit)?;
        let held = match horizon {
            Horizon::Long => p.score(est.material, train.end..frames, &mut no_progress)?.mean,
            Horizon::Short { window } => {
                let interval = reference.dt * reference.spec.metric_stride as f64;
                let window = ((window / interval).round() as usize).max(1);
                p.score_windows(est.material, train.end..frames, window, &mut no_progress)?
                    .mean
            }
        };
        let accepted = held <= max_error;
        log(format!(
            "{nx}×{ny}: held-out error {:.2}% {} {:.2}%",
            100.0 * held,
            if accepted { "≤" } else { ">" },
            100.0 * max_error
        ));
        steps.push(PlanStep {
            nx,
            ny,
            material: est.material,
            dt: p.dt,
            held_out_mean: held,
            accepted,
        });
        if accepted {
            break;
        }
    }
    Ok(steps)
}
