//! Coefficient estimation for coherent levels of detail (Sung 2018 §5) and
//! the error metric that judges it (eq. 9). Pure library code: no I/O, no
//! clocks, no async; long work reports progress through a callback so the
//! daemon can run it in the background.
//!
//! A [`LodProblem`] ties a recorded fine [`Reference`] to one coarse level
//! (resolution, mass convention, integrator, dt). Each [`Method`] turns it
//! into a [`Material`]; [`LodProblem::score`] re-simulates the coarse cloth
//! and measures it against the reference.
//!
//! Methods:
//! - `same`: the scene's material at the level's spacing (the membrane its
//!   springs make, converted per direction: [`crate::sim::Membrane`]);
//! - `same_spring`: the paper's "same", the reference's per-spring
//!   coefficients unchanged;
//! - `bcd`, `gkd`: the paper's inverse-Hooke methods ([`inverse`]);
//! - `lsq`: one global least-squares fit of the ten per-class coefficients
//!   ([`inverse`]);
//! - `fit`: minimise the simulated displacement error directly ([`fit`]);
//!   `shape` and `follow` fit other targets with it;
//! - `drape`: `same` with its bend class scaled until the level, draped
//!   from rest, casts the reference's shadow ([`shadow`]).
//!
//! Every method but `same_spring` gives per-direction coefficients (one K and
//! C per [`crate::sim::SpringClass`]).
//!
//! Beside the coefficients, [`modal`] changes a mesh level's bending
//! operator itself: its modes in a band made as stiff as the reference's
//! ([`LodProblem::with_bending`] scores a level with it).

pub mod drape;
pub mod fit;
pub mod inverse;
pub mod metric;
pub mod reference;
pub mod replayed;
pub mod session;
pub mod touched;

use std::fmt;
use std::ops::Range;
use std::sync::Arc;

pub use fit::{FitOptions, FitReport, FitTarget};
pub use inverse::{Distribution, InverseEstimate, LsqEstimate, Reading, Rejections};
pub use metric::{ErrorAccumulator, ErrorReport};
pub use reference::{RecordSpec, Reference, ReferenceError, Sample, CHECKPOINT_SECONDS};
pub use replayed::{ReplayError, ReplayedReference};
pub use session::{score_session, SessionScore, SessionScoreError};
pub use touched::{eased_drag, probes, record_touched, Probe, TouchedError, TouchedReference, TouchedScore, PROBES};

use crate::level::Level;
use crate::lod::{Correlation, LodError};
use crate::scene::{MassConvention, Scene, SceneError};
use crate::sim::{
    Bending, Integrator, Loads, Material, SimError, SimParams, Simulation, SpringKind, SpringPrecision, StabilityCheck,
    State, Topology,
};
use crate::turns::Turns;

/// Progress of a long estimation stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// What is running ("observe", "inverse", "lsq", "fit", "score").
    pub stage: &'static str,
    /// Units of work done.
    pub done: u64,
    /// Units of work in the stage.
    pub total: u64,
}

/// Progress callback.
pub type ProgressFn<'a> = &'a mut dyn FnMut(Progress);

/// A callback that ignores progress.
pub fn no_progress(_: Progress) {}

/// An estimation method, usable by name everywhere (CLI, config, cache).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Method {
    /// The scene's material made at the level's spacing: the membrane the
    /// scene's springs make ([`crate::sim::Membrane`]) converted to springs
    /// of the level's cells, per direction. On square cells of a square-celled
    /// reference this is the reference's per-spring coefficients.
    Same,
    /// The paper's "same": the reference's per-spring coefficients copied
    /// unchanged, whatever the level's cell shape.
    SameSpring,
    /// The paper's inverse Hooke fit with barycentric shares (eq. 3).
    Bcd,
    /// The paper's inverse Hooke fit with Gaussian-kernel shares (eqs. 4–6).
    Gkd,
    /// A global least-squares inverse fit over every observation.
    Lsq,
    /// Coefficients fitted so the coarse run tracks the reference
    /// (Levenberg–Marquardt on the eq. 9 residuals).
    Fit,
    /// Coefficients fitted so the coarse run takes the reference's shape:
    /// the same Levenberg–Marquardt fit on the distribution of the cloth's
    /// positions (mass-weighted quantiles of each coordinate) instead of
    /// node by node ([`fit::FitTarget::Shape`]), for scenes whose folds form
    /// where rounding decides (a drape).
    Shape,
    /// Coefficients fitted so the coarse level follows the reference from
    /// the reference's own states: the same Levenberg–Marquardt fit on the
    /// eq. 9 residuals of the level restarted from the reference every
    /// 0.25 s (and settled, when the problem settles its restarts)
    /// ([`fit::FitTarget::Windows`]): the short horizon a level lives in
    /// after a switch, on a scene whose long horizon is chaos.
    Follow,
    /// `same` with its bend class (K and C) scaled so that the level,
    /// draped from rest over the scene's duration, casts the reference's
    /// shadow at the end ([`drape::drape_fit`]): the settled drape a Cusick
    /// tester measures, which the motion-reading methods do not aim at.
    Drape,
}

impl Method {
    /// Every method, cheapest first.
    pub const ALL: [Method; 9] = [
        Method::Same,
        Method::SameSpring,
        Method::Bcd,
        Method::Gkd,
        Method::Lsq,
        Method::Fit,
        Method::Shape,
        Method::Follow,
        Method::Drape,
    ];

    /// Name used in config files, CLI and CSV.
    pub const fn name(self) -> &'static str {
        match self {
            Method::Same => "same",
            Method::SameSpring => "same_spring",
            Method::Bcd => "bcd",
            Method::Gkd => "gkd",
            Method::Lsq => "lsq",
            Method::Fit => "fit",
            Method::Shape => "shape",
            Method::Follow => "follow",
            Method::Drape => "drape",
        }
    }

    /// Parse a [`Method::name`] (see [`crate::names`]).
    pub fn from_name(name: &str) -> Option<Method> {
        crate::names::parse(name).ok()
    }
}

/// An estimation method the daemon offers a user, in its config and in
/// switch requests (docs/model.md, "Choosing an estimation method"). The
/// others stay in the lab: `same_spring`, `bcd` and `lsq` reproduce the
/// paper's and a global reading of it, `shape` explored the drape before
/// `drape` met it. The daemon still runs BCD itself, as a quick stand-in at
/// a first switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Served(pub Method);

impl Served {
    /// Every served method, cheapest first.
    pub const ALL: [Served; 5] = [
        Served(Method::Same),
        Served(Method::Gkd),
        Served(Method::Fit),
        Served(Method::Follow),
        Served(Method::Drape),
    ];

    /// `name` as a served method; a lab method is refused with the served
    /// names and a word on where the lab's are.
    pub fn parse(name: &str) -> Result<Method, crate::names::UnknownName> {
        crate::names::parse::<Served>(name).map(|s| s.0).map_err(|e| {
            if Method::from_name(name).is_some() {
                crate::names::UnknownName {
                    choices: format!("{} (the daemon's methods; '{name}' is the lab's)", e.choices),
                    ..e
                }
            } else {
                e
            }
        })
    }
}

impl crate::names::Named for Served {
    const ALL: &'static [Served] = &Served::ALL;
    fn name(self) -> &'static str {
        self.0.name()
    }
}

impl crate::names::Named for Method {
    const ALL: &'static [Method] = &Method::ALL;
    fn name(self) -> &'static str {
        Method::name(self)
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Errors of setting up or running an estimation.
#[derive(Debug, thiserror::Error)]
pub enum EstimateError {
    /// The levels could not be correlated.
    #[error(transparent)]
    Lod(#[from] LodError),
    /// The scene could not be built.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The coarse simulation refused its parameters.
    #[error("coarse cloth {level}: {source}")]
    Sim {
        /// The coarse level.
        level: Level,
        /// The simulation's reason.
        source: SimError,
    },
    /// The coarse dt does not divide the reference's frame interval.
    #[error(
        "coarse dt {dt} s does not divide the reference's metric frame interval {interval} s; \
         pick dt = interval / k for an integer k"
    )]
    FrameMismatch {
        /// The coarse time step (s).
        dt: f64,
        /// The reference's metric frame interval (s).
        interval: f64,
    },
    /// A frame range beyond the recording.
    #[error("frame range {start}..{end} is outside the reference's {frames} metric frames")]
    FrameRange {
        /// First frame asked for.
        start: usize,
        /// One past the last.
        end: usize,
        /// Metric frames recorded.
        frames: usize,
    },
    /// A `drape` fit could not be made.
    #[error("drape: {0}")]
    Drape(String),
    /// A short-horizon window of no frame.
    #[error("a short-horizon window must hold at least one metric frame")]
    Window,
    /// A coarse level below 2×2.
    #[error("the coarse cloth needs at least 2×2 nodes, got {nx}×{ny}")]
    Resolution {
        /// Nodes per row asked for.
        nx: usize,
        /// Nodes per column asked for.
        ny: usize,
    },
}

/// One coarse level to estimate for and score against a reference.
#[derive(Debug, Clone)]
pub struct LodProblem {
    /// The scene (its params are the reference's).
    pub scene: Scene,
    /// The recorded fine run.
    pub reference: Arc<Reference>,
    /// The coarse level: a grid of the scene's grid cloth, or a vertex
    /// count of its mesh cloth.
    pub level: Level,
    /// How the coarse level's node masses are made.
    pub mass: MassConvention,
    /// The coarse level's integrator.
    pub integrator: Integrator,
    /// The coarse level's time step (s).
    pub dt: f64,
    topology: Arc<Topology>,
    correlation: Correlation,
    masses: Vec<f64>,
    loads: Loads,
    /// The scene's material made on this level.
    same: Material,
    /// Coarse steps per reference metric frame.
    steps_per_frame: u64,
    /// Given way at every metric frame of every run ([`LodProblem::with_turns`]).
    turns: Turns,
    /// The step that settles a restart from the reference
    /// ([`LodProblem::with_settling`]).
    settle: Option<f64>,
}

/// Coarse steps of `dt` per metric frame of `reference`, when `dt` divides it.
fn steps_per_frame(reference: &Reference, dt: f64) -> Result<u64, EstimateError> {
    let interval = reference.dt * reference.spec.metric_stride as f64;
    let ratio = interval / dt;
    if !(dt > 0.0) || (ratio - ratio.round()).abs() > 1e-6 || ratio.round() < 1.0 {
        return Err(EstimateError::FrameMismatch { dt, interval });
    }
    Ok(ratio.round() as u64)
}

impl LodProblem {
    /// Set up level `nx × ny` of `scene` against `reference` (a grid cloth;
    /// [`LodProblem::at`] for any level).
    pub fn new(
        scene: &Scene,
        reference: Arc<Reference>,
        nx: usize,
        ny: usize,
        mass: MassConvention,
        integrator: Integrator,
        dt: f64,
    ) -> Result<LodProblem, EstimateError> {
        if nx < 2 || ny < 2 {
            return Err(EstimateError::Resolution { nx, ny });
        }
        LodProblem::at(scene, reference, Level::new(nx, ny), mass, integrator, dt)
    }

    /// Set up `level` of `scene` against `reference`: a grid of a grid
    /// cloth, a vertex count of a mesh cloth ([`Scene::cloth_level`]),
    /// correlated with the reference by material coordinates on grids and by
    /// closest points on the rest surface on meshes ([`Correlation::between`]).
    ///
    /// Masses: [`MassConvention::Lumped`] gives each coarse node its share of
    /// the cloth's mass (total preserved); [`MassConvention::PerNode`] gives
    /// every coarse node the reference's mean node mass, the paper's
    /// convention (total shrinks with the node count).
    pub fn at(
        scene: &Scene,
        reference: Arc<Reference>,
        level: Level,
        mass: MassConvention,
        integrator: Integrator,
        dt: f64,
    ) -> Result<LodProblem, EstimateError> {
        let steps_per_frame = steps_per_frame(&reference, dt)?;
        let cloth = scene.cloth_level(level)?;
        let topology = cloth.topology.clone();
        let correlation = Correlation::between(&reference.topology, &topology)?;
        let masses = match mass {
            MassConvention::Lumped => topology.node_areas.iter().map(|a| a * scene.areal_density).collect(),
            MassConvention::PerNode => {
                let m = reference.masses.iter().sum::<f64>() / reference.masses.len() as f64;
                vec![m; topology.n_nodes]
            }
        };
        let loads = scene.loads_on(&topology, cloth.mesh.as_deref())?;
        let same = scene.material_on(&cloth);
        Ok(LodProblem {
            scene: scene.clone(),
            reference,
            level,
            mass,
            integrator,
            dt,
            topology,
            correlation,
            masses,
            loads,
            same,
            steps_per_frame,
            turns: Turns::none(),
            settle: None,
        })
    }

    /// The same level at time step `dt`: what [`LodProblem::at`] would
    /// make, without building the level's mesh, springs and correlation again.
    pub fn with_dt(&self, dt: f64) -> Result<LodProblem, EstimateError> {
        let steps_per_frame = steps_per_frame(&self.reference, dt)?;
        Ok(LodProblem {
            dt,
            steps_per_frame,
            ..self.clone()
        })
    }

    /// The same level whose runs (scores, a fit's residuals, runs under
    /// input) give way at every metric frame as `turns` says.
    pub fn with_turns(self, turns: Turns) -> LodProblem {
        LodProblem { turns, ..self }
    }

    /// The same level whose restarts from the reference (the short
    /// horizon's windows) are settled by one backward-Euler step of `h`
    /// seconds ([`crate::lod::settle`]) before they run.
    pub fn with_settling(self, h: f64) -> LodProblem {
        LodProblem {
            settle: Some(h),
            ..self
        }
    }

    /// The step that settles this level's restarts from the reference
    /// ([`LodProblem::with_settling`]), if any.
    pub fn settling(&self) -> Option<f64> {
        self.settle
    }

    /// Where this level's runs give way ([`LodProblem::with_turns`]).
    pub fn turns(&self) -> &Turns {
        &self.turns
    }

    /// The coarse cloth.
    pub fn topology(&self) -> &Arc<Topology> {
        &self.topology
    }

    /// The coarse cloth's pins and loads.
    pub fn loads(&self) -> &Loads {
        &self.loads
    }

    /// The same level with `more` bending stencils after its own (a
    /// mode-selective correction such as the lab's modal stiffening), scored and
    /// estimated like any level; the same nodes, springs and correlation.
    pub fn with_bending(&self, more: &Bending) -> LodProblem {
        let mut topology = Topology::clone(&self.topology);
        topology.bending = topology.bending.extended(more);
        LodProblem {
            topology: Arc::new(topology),
            ..self.clone()
        }
    }

    /// Reference → coarse correlation.
    pub fn correlation(&self) -> &Correlation {
        &self.correlation
    }

    /// Coarse node masses.
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }

    /// Metric frames of the reference.
    pub fn frames(&self) -> usize {
        self.reference.frames.len()
    }

    /// The `same` coefficients of this level: the scene's material made at
    /// this level's spacing, per direction ([`Scene::material_at`]; the
    /// reference ran the same material at the scene's own resolution).
    pub fn same_material(&self) -> Material {
        self.same
    }

    /// Coarse parameters with `material`.
    pub fn params(&self, material: Material) -> SimParams {
        SimParams {
            dt: self.dt,
            integrator: self.integrator,
            material,
            ..self.scene.params
        }
    }

    /// A coarse simulation at rest with `material`. Stability is not enforced
    /// here (callers compare [`Simulation::dt_limit`] with their own margin).
    pub fn simulation(&self, material: Material) -> Result<Simulation, EstimateError> {
        Simulation::new(
            self.topology.clone(),
            self.masses.clone(),
            self.params(material),
            self.loads.clone(),
            State::at_rest(&self.topology),
            StabilityCheck::Force,
        )
        .map_err(|source| EstimateError::Sim {
            level: self.level,
            source,
        })
    }

    /// Simulate the coarse cloth with `material` from rest and score metric
    /// frames `frames` against the reference.
    pub fn score(
        &self,
        material: Material,
        frames: Range<usize>,
        progress: ProgressFn<'_>,
    ) -> Result<ErrorReport, EstimateError> {
        self.score_in(material, SpringPrecision::F64, frames, progress)
    }

    /// [`LodProblem::score`] with the coarse cloth's springs evaluated in
    /// `precision` (what a live instance in f32 would show; estimation
    /// itself stays f64).
    pub fn score_in(
        &self,
        material: Material,
        precision: SpringPrecision,
        frames: Range<usize>,
        progress: ProgressFn<'_>,
    ) -> Result<ErrorReport, EstimateError> {
        self.check_range(&frames)?;
        let mut sim = self.simulation(material)?;
        sim.set_spring_precision(precision);
        let n = self.topology.n_nodes;
        let mut acc = ErrorAccumulator::new(self.reference.o_max, n, frames.len());
        let mut mapped = vec![0.0; 3 * n];
        let total = frames.end as u64;
        for f in 0..frames.end {
            self.turns.checkpoint();
            for _ in 0..self.steps_per_frame {
                sim.step();
            }
            if sim.diverged() {
                acc.mark_diverged();
                break;
            }
            if f >= frames.start {
                self.correlation.map(&self.reference.frames[f], &mut mapped);
                acc.push(self.reference.frame_times[f], &mapped, &sim.state().pos);
            }
            if f % 16 == 0 || f + 1 == frames.end {
                progress(Progress {
                    stage: "score",
                    done: f as u64 + 1,
                    total,
                });
            }
        }
        Ok(acc.report())
    }

    /// The short-horizon measure beside eq. 9: metric frames `frames` are
    /// scored in windows of `window` frames, and before each window the
    /// coarse cloth restarts from the reference's state mapped onto it, so
    /// every window measures how well the level follows the reference from
    /// the same start (a chaotic motion, cloth flapping in gusts, drifts
    /// from its reference over a long run whatever the coefficients).
    ///
    /// A window that begins at the run's first or second frame runs from
    /// rest, as the reference did. Any other restarts at the frame before
    /// the window: positions are that frame's, mapped by the barycentric
    /// correlation; velocities are central differences of the mapped
    /// neighbouring frames, (x(f+1) − x(f−1)) / 2Δ with Δ the metric
    /// interval (second-order accurate in Δ; vibrations faster than the
    /// frames are not carried, and a coarse level cannot represent them
    /// anyway). The clock and the loads restart at that frame's time.
    pub fn score_windows(
        &self,
        material: Material,
        frames: Range<usize>,
        window: usize,
        progress: ProgressFn<'_>,
    ) -> Result<ErrorReport, EstimateError> {
        let n = self.topology.n_nodes;
        let reference = &self.reference;
        let mut acc = ErrorAccumulator::new(reference.o_max, n, frames.len());
        let mut mapped = vec![0.0; 3 * n];
        let diverged = self.windows(material, frames, window, progress, &mut |f, pos| {
            self.correlation.map(&reference.frames[f], &mut mapped);
            acc.push(reference.frame_times[f], &mapped, pos);
        })?;
        if diverged {
            acc.mark_diverged();
        }
        Ok(acc.report())
    }

    /// The runs of [`LodProblem::score_windows`]: `each(f, positions)` at
    /// every metric frame `f` of `frames`, the coarse cloth restarted from
    /// the reference before each window. True when the run diverged (the
    /// frames after it are not visited).
    pub(crate) fn windows(
        &self,
        material: Material,
        frames: Range<usize>,
        window: usize,
        progress: ProgressFn<'_>,
        each: &mut dyn FnMut(usize, &[f64]),
    ) -> Result<bool, EstimateError> {
        self.check_range(&frames)?;
        if window == 0 {
            return Err(EstimateError::Window);
        }
        let n = self.topology.n_nodes;
        let reference = &self.reference;
        let interval = reference.dt * reference.spec.metric_stride as f64;
        let mut mapped = vec![0.0; 3 * n];
        let mut before = vec![0.0; 3 * n];
        let mut sim = self.simulation(material)?;
        let total = frames.end as u64;
        let mut start = frames.start;
        while start < frames.end {
            let end = (start + window).min(frames.end);
            let first = if start <= 1 {
                sim = self.simulation(material)?;
                0
            } else {
                let r = start - 1;
                let mut state = sim.state().clone();
                self.correlation.map(&reference.frames[r], &mut state.pos);
                self.correlation.map(&reference.frames[r - 1], &mut before);
                self.correlation.map(&reference.frames[r + 1], &mut mapped);
                for ((v, a), b) in state.vel.iter_mut().zip(&mapped).zip(&before) {
                    *v = (a - b) / (2.0 * interval);
                }
                state.time = reference.frame_times[r];
                state.step = (r as u64 + 1) * self.steps_per_frame;
                sim.set_state(state).map_err(|source| EstimateError::Sim {
                    level: self.level,
                    source,
                })?;
                if let Some(h) = self.settle {
                    crate::lod::settle(&mut sim, h).map_err(|source| EstimateError::Sim {
                        level: self.level,
                        source,
                    })?;
                }
                start
            };
            for f in first..end {
                self.turns.checkpoint();
                for _ in 0..self.steps_per_frame {
                    sim.step();
                }
                if sim.diverged() {
                    return Ok(true);
                }
                if f >= start {
                    each(f, &sim.state().pos);
                }
            }
            progress(Progress {
                stage: "score windows",
                done: end as u64,
                total,
            });
            start = end;
        }
        Ok(false)
    }

    fn check_range(&self, frames: &Range<usize>) -> Result<(), EstimateError> {
        if frames.start >= frames.end || frames.end > self.frames() {
            return Err(EstimateError::FrameRange {
                start: frames.start,
                end: frames.end,
                frames: self.frames(),
            });
        }
        Ok(())
    }

    /// Estimate coefficients with `method`. `fit` starts from the best (on
    /// its training frames) of `same`, `gkd` and `lsq` unless
    /// `options.start` is given.
    pub fn estimate(
        &self,
        method: Method,
        options: &FitOptions,
        progress: ProgressFn<'_>,
    ) -> Result<Estimate, EstimateError> {
        let same = self.same_material();
        let details = match method {
            Method::Same => Details::Same,
            Method::SameSpring => Details::Same,
            Method::Bcd | Method::Gkd => {
                let mut sim = self.simulation(same)?;
                let obs = inverse::observe(&self.reference, &self.correlation, &mut sim, progress);
                let dist = if method == Method::Bcd {
                    Distribution::Bcd
                } else {
                    Distribution::Gkd
                };
                Details::Inverse(inverse::inverse_estimate(
                    &same,
                    &self.reference,
                    &self.correlation,
                    &self.topology,
                    &obs,
                    dist,
                    options.reading,
                    progress,
                ))
            }
            Method::Lsq => {
                let mut sim = self.simulation(same)?;
                let obs = inverse::observe(&self.reference, &self.correlation, &mut sim, progress);
                Details::Lsq(inverse::lsq_estimate(&same, &self.topology, &obs, progress))
            }
            Method::Fit => Details::Fit(fit::fit(self, options, progress)?),
            Method::Shape => {
                let options = FitOptions {
                    target: FitTarget::Shape,
                    fd_step: options.fd_step.max(fit::SHAPE_FD_STEP),
                    ..options.clone()
                };
                Details::Fit(fit::fit(self, &options, progress)?)
            }
            Method::Follow => {
                let options = FitOptions {
                    target: FitTarget::Windows,
                    ..options.clone()
                };
                Details::Fit(fit::fit(self, &options, progress)?)
            }
            Method::Drape => {
                let start = options.start.unwrap_or(same);
                Details::Drape(drape::drape_fit(self, &start, progress)?)
            }
        };
        let material = match &details {
            Details::Same if method == Method::SameSpring => self.reference.material,
            Details::Same => same,
            Details::Inverse(e) => e.material,
            Details::Lsq(e) => e.material,
            Details::Fit(e) => e.material,
            Details::Drape(d) => options
                .start
                .unwrap_or(same)
                .kind_scaled(SpringKind::Bend, d.factor, d.factor),
        };
        Ok(Estimate {
            method,
            material,
            details,
        })
    }
}

/// Coefficients from one method, with its diagnostics.
#[derive(Debug, Clone)]
pub struct Estimate {
    /// The method.
    pub method: Method,
    /// The coefficients it gave.
    pub material: Material,
    /// What it reports besides.
    pub details: Details,
}

/// Method-specific diagnostics.
#[derive(Debug, Clone)]
pub enum Details {
    /// Nothing to report.
    Same,
    /// BCD or GKD.
    Inverse(InverseEstimate),
    /// Least squares.
    Lsq(LsqEstimate),
    /// The fit.
    Fit(FitReport),
    /// The drape fit.
    Drape(drape::DrapeReport),
}
