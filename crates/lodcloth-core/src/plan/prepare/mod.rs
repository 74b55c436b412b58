//! Getting a level ready to run: the instance's reference recording,
//! coefficients (from the on-disk cache or estimated), a stable dt and the
//! level's predicted error (calibration against the reference). Blocking and
//! possibly slow (seconds to minutes); the service runs it on background
//! threads, never on a stepping thread.

use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex, TryLockError};
use std::time::Instant;

use rayon::prelude::*;

use super::estimator::{default_problem, progress_every, record_reference_while, stable_problem, Estimator, PlanError};
use super::{EstimationPlan, InstanceKind, InstancePlan, Level};
use crate::cache::CoefficientCache;
use crate::estimate::{no_progress, FitOptions, LodProblem, Method, Reference};
use crate::points::estimate::{self as surface_fit, SurfaceReference};
use crate::points::model::PointModel;
use crate::points::scene::SurfaceScene;
use crate::scene::{MassConvention, Scene};
use crate::sim::{Material, Simulation, StabilityCheck, State};
use crate::turns::Turns;

use crate::points::cloud::CloudMap;

mod error;
mod surface;

pub use error::{PrepareError, PrepareFailure};

/// A level ready to switch to.
#[derive(Debug)]
pub struct Prepared {
    /// The level.
    pub level: Level,
    /// The method its coefficients come from.
    pub method: Method,
    /// Its coefficients (K, C per spring type).
    pub material: Material,
    /// The level's time step (s).
    pub dt: f64,
    /// Predicted stability limit of `material` at this level (s).
    pub dt_limit: f64,
    /// Mean relative error over the recorded reference.
    pub predicted_error: f64,
    /// The reference's largest displacement (m), the error normaliser.
    pub o_max: f64,
    /// Wall seconds the estimate took (0 on a cache hit).
    pub estimate_seconds: f64,
    /// The coefficients came from the on-disk cache.
    pub cached: bool,
    /// What the level was measured against (and how to rebuild it).
    pub basis: Basis,
}

/// What a prepared level was measured against.
#[derive(Debug)]
pub enum Basis {
    /// A cloth level against its reference (the problem's `dt` is the level's).
    Cloth(Arc<LodProblem>),
    /// A surface level: its model (the fitted material applied, at rest)
    /// and the all-points reference.
    Surface {
        /// The level's point model, the fitted material applied, at rest.
        model: Box<PointModel>,
        /// The reference run that simulates every point of the cloud.
        reference: Arc<SurfaceReference>,
    },
}

impl Prepared {
    /// A simulation of this level at rest.
    pub fn simulation(&self) -> Result<Simulation, PrepareError> {
        let failed = |source: PrepareFailure| PrepareError::Failed {
            level: self.level,
            method: self.method,
            source: Box::new(source),
        };
        match &self.basis {
            Basis::Cloth(problem) => problem.simulation(self.material).map_err(|e| failed(e.into())),
            Basis::Surface { model, .. } => surface_fit::restart(model).map_err(|e| failed(e.into())),
        }
    }

    /// How a surface level moves the full cloud (None for a cloth).
    pub fn cloud_map(&self) -> Option<CloudMap> {
        match &self.basis {
            Basis::Cloth(_) => None,
            Basis::Surface { model, .. } => Some(CloudMap::of(model)),
        }
    }
}

/// What an instance starts stepping with, before any estimate.
pub struct Start {
    /// The start level's simulation, at rest, with the scene's coefficients.
    pub sim: Simulation,
    /// Its time step (s).
    pub dt: f64,
    /// Surfaces: how the simulated points move the cloud.
    pub cloud: Option<CloudMap>,
}

/// Prepares the levels of one instance; remembers what it prepared.
#[derive(Debug)]
pub struct Preparer {
    plan: Arc<InstancePlan>,
    estimation: EstimationPlan,
    estimator: Estimator,
    /// The cloth reference, recorded once by whoever needs it first
    /// ([`Preparer::reference_now`] for who may not wait).
    reference: Mutex<ReferenceSlot>,
    /// Notified when a recording of the reference ends.
    reference_ended: Condvar,
    surface_reference: Mutex<Option<Arc<SurfaceReference>>>,
    /// A surface's all-points run recorded as a cloth reference.
    surface_samples: Mutex<Option<Arc<Reference>>>,
    prepared: Mutex<HashMap<(Level, Method), Arc<Prepared>>>,
    /// One preparation at a time per level and method: a second request for
    /// the same waits for the first and then finds it prepared, while other
    /// levels and methods (a client's switch beside the background's fit)
    /// go on.
    work: Mutex<HashMap<(Level, Method), WorkLock>>,
    /// The standard drags' references and each level's prediction under
    /// them ([`Preparer::predict_touched`]).
    pub(super) touched: super::touched::TouchedCache,
    /// Where its recordings and every prepared level's runs give way
    /// ([`Preparer::with_turns`]).
    turns: Turns,
}

/// Held while one level and method is prepared.
type WorkLock = Arc<Mutex<()>>;

/// Takes a finished (or abandoned) recording out of the reference's
/// count and wakes whoever waits for it.
struct CountedOut<'a>(&'a Preparer);

impl Drop for CountedOut<'_> {
    fn drop(&mut self) {
        lock(&self.0.reference).recording -= 1;
        self.0.reference_ended.notify_all();
    }
}

/// The cloth reference and who is recording it.
#[derive(Debug, Default)]
struct ReferenceSlot {
    recorded: Option<Arc<Reference>>,
    /// Threads recording it now: one, or a client's copy beside a
    /// background recording ([`Preparer::reference_now`]).
    recording: usize,
}

impl Preparer {
    /// A preparer for `plan`'s levels, estimating as `estimation` says and
    /// through `cache` when there is one. Records nothing until asked.
    pub fn new(plan: Arc<InstancePlan>, estimation: EstimationPlan, cache: Option<CoefficientCache>) -> Preparer {
        let tag = format!(
            "daemon;ref={};ms={};es={}",
            estimation.spec.frames, estimation.spec.metric_stride, estimation.spec.estimate_stride
        );
        Preparer {
            plan,
            estimation,
            estimator: Estimator { cache, tag },
            reference: Mutex::new(ReferenceSlot::default()),
            reference_ended: Condvar::new(),
            surface_reference: Mutex::new(None),
            surface_samples: Mutex::new(None),
            prepared: Mutex::new(HashMap::new()),
            work: Mutex::new(HashMap::new()),
            touched: Default::default(),
            turns: Turns::none(),
        }
    }

    /// The same preparer, its reference recording and every level's runs
    /// giving way as `turns` says, and its waits for other threads' work
    /// (a level another thread prepares, a reference it records) made
    /// inside [`Turns::waiting`].
    pub fn with_turns(self, turns: Turns) -> Preparer {
        Preparer { turns, ..self }
    }

    /// The instance this preparer prepares levels of.
    pub fn plan(&self) -> &Arc<InstancePlan> {
        &self.plan
    }

    /// Already prepared, without waiting.
    pub fn get(&self, level: Level, method: Method) -> Option<Arc<Prepared>> {
        lock(&self.prepared).get(&(level, method)).cloned()
    }

    /// Predicted error of every prepared level with `method`.
    pub fn predicted(&self, method: Method) -> Vec<(Level, Arc<Prepared>)> {
        let map = lock(&self.prepared);
        let mut out: Vec<_> = map
            .iter()
            .filter(|((_, m), _)| *m == method)
            .map(|((l, _), p)| (*l, p.clone()))
            .collect();
        out.sort_by_key(|(l, _)| l.nodes());
        out
    }

    /// The cloth reference run, recorded on first use. A thread that finds
    /// it being recorded waits for that recording.
    fn reference(&self, scene: &Scene) -> Result<Arc<Reference>, PrepareError> {
        self.reference_or_record(scene, true)
    }

    /// The cloth reference for work a client waits for: recorded on this
    /// thread unless it is recorded already, and if another thread is
    /// recording it, recorded again here rather than waited for. That
    /// thread may be background work, which the daemon runs only on cycles
    /// nothing else wants (`SCHED_IDLE`, a class an unprivileged thread
    /// cannot be raised from), so waiting for it would put the client
    /// behind everything: at a cold start the background records every
    /// instance's reference in turn, and a first switch of the instance
    /// whose turn it is waited for it. The first copy to finish is kept;
    /// the other stops at its next 1 % of the run. Nothing to do for a
    /// surface.
    pub fn reference_now(&self) -> Result<(), PrepareError> {
        match &self.plan.kind {
            InstanceKind::Cloth(scene) => self.reference_or_record(scene, false).map(|_| ()),
            InstanceKind::Surface(_) => Ok(()),
        }
    }

    /// The recorded reference, else recorded here; a recording in progress
    /// is waited for when `wait`, else recorded again beside it.
    fn reference_or_record(&self, scene: &Scene, wait: bool) -> Result<Arc<Reference>, PrepareError> {
        let mut slot = lock(&self.reference);
        loop {
            if let Some(r) = &slot.recorded {
                return Ok(r.clone());
            }
            if !wait || slot.recording == 0 {
                break;
            }
            slot = self
                .turns
                .waiting(|| self.reference_ended.wait(slot).unwrap_or_else(|e| e.into_inner()));
        }
        slot.recording += 1;
        drop(slot);
        self.record(scene)
    }

    /// Record the reference (the caller has counted itself in
    /// `recording`), stopping when another copy is kept first.
    fn record(&self, scene: &Scene) -> Result<Arc<Reference>, PrepareError> {
        // Counted out, and the waiters woken, however this ends (a panic
        // too: they would otherwise wait for it forever). Dropped last,
        // after the slot's guard.
        let _counted = CountedOut(self);
        let name = self.plan.name.clone();
        let recorded = record_reference_while(
            scene,
            self.estimation.spec,
            &mut |line| tracing::info!(instance = %name, "{line}"),
            &|| {
                self.turns.checkpoint();
                lock(&self.reference).recorded.is_none()
            },
        );
        let mut slot = lock(&self.reference);
        match (recorded, slot.recorded.clone()) {
            (_, Some(first)) => {
                tracing::info!(instance = %self.plan.name, "reference recorded by another thread first; this copy stopped or dropped");
                Ok(first)
            }
            (Ok((reference, _)), None) => {
                tracing::info!(
                    instance = %self.plan.name,
                    frames = reference.frames.len(),
                    o_max = reference.o_max,
                    "reference recorded"
                );
                slot.recorded = Some(reference.clone());
                Ok(reference)
            }
            (Err(e), None) => Err(PrepareError::Reference {
                scene: scene.name.clone(),
                source: Box::new(e.into()),
            }),
        }
    }

    /// The cloth scene with the instance's integrator: what its levels run.
    /// The reference runs the scene as written (its own integrator and
    /// dt): it is the truth the levels are estimated and scored against,
    /// and an integrator chosen to serve a level cheaply may not be stable
    /// at the scene's dt (symplectic Euler at the Cusick scene's 1e-4 s is
    /// beyond its 6.2e-5 s limit).
    fn cloth_scene(scene: &Scene, plan: &InstancePlan) -> Scene {
        let mut scene = scene.clone();
        scene.params.integrator = plan.integrator;
        scene
    }

    /// `NotAllowed` unless `level` is one the instance may run.
    fn check_allowed(&self, level: Level) -> Result<(), PrepareError> {
        if self.plan.levels.contains(&level) {
            Ok(())
        } else {
            Err(PrepareError::NotAllowed {
                level,
                allowed: allowed(&self.plan.levels),
            })
        }
    }

    /// Prepare `level` with `method` (blocking; cached after the first time).
    pub fn prepare(&self, level: Level, method: Method) -> Result<Arc<Prepared>, PrepareError> {
        self.prepare_with(level, method, false)
            .map(|p| p.expect("an estimate is made when not cached"))
    }

    /// `level` with `method` prepared only if no estimate has to be made: it
    /// is prepared already, or a cloth whose coefficients the on-disk cache
    /// holds (then the reference is recorded if need be, and the level
    /// scored). `None` otherwise, and while another thread prepares it.
    pub fn prepare_if_cached(&self, level: Level, method: Method) -> Result<Option<Arc<Prepared>>, PrepareError> {
        self.prepare_with(level, method, true)
    }

    fn prepare_with(
        &self,
        level: Level,
        method: Method,
        cached_only: bool,
    ) -> Result<Option<Arc<Prepared>>, PrepareError> {
        self.check_allowed(level)?;
        if let Some(p) = self.get(level, method) {
            return Ok(Some(p));
        }
        let work = lock(&self.work).entry((level, method)).or_default().clone();
        // Asked only for what is ready: an estimate another thread is
        // making now is not (it may be the background's, run on cycles
        // nothing else wants; a daemon's switch waited 67 s for one).
        let _guard = match (cached_only, work.try_lock()) {
            (_, Ok(guard)) => guard,
            (_, Err(TryLockError::Poisoned(e))) => e.into_inner(),
            (true, Err(TryLockError::WouldBlock)) => return Ok(None),
            (false, Err(TryLockError::WouldBlock)) => self.turns.waiting(|| lock(&work)),
        };
        if let Some(p) = self.get(level, method) {
            return Ok(Some(p));
        }
        let prepared = match (&self.plan.kind, level) {
            (InstanceKind::Cloth(scene), Level::Grid { .. } | Level::Vertices(_)) => {
                match self.prepare_cloth(scene, &Self::cloth_scene(scene, &self.plan), level, method, cached_only)? {
                    Some(p) => p,
                    None => return Ok(None),
                }
            }
            (InstanceKind::Surface(_), Level::Points(_)) if cached_only => return Ok(None),
            (InstanceKind::Surface(scene), Level::Points(n)) => self.prepare_surface(scene, level, n, method)?,
            _ => {
                return Err(PrepareError::NotAllowed {
                    level,
                    allowed: allowed(&self.plan.levels),
                })
            }
        };
        let prepared = Arc::new(prepared);
        lock(&self.prepared).insert((level, method), prepared.clone());
        Ok(Some(prepared))
    }

    /// What a first switch may go live with while a slow estimate is made:
    /// methods that do not re-simulate the level (only their scores run it,
    /// one run each, side by side). On a cloth `same` and BCD: GKD costs
    /// more (its kernel sums, 1.6 s against BCD's 0.1 s at 40×40 of a 64²
    /// reference) and least squares a run too, and over Table 1
    /// (docs/table1.csv) neither is ahead of both on average at any level
    /// (GKD 3.1–12 %, lsq over 100 %, against `same` 1.3–3.1 % and BCD
    /// 2.1–6.1 %). On a surface `same` (its inverse fits need another
    /// all-points recording).
    pub fn quick_methods(&self) -> &'static [Method] {
        match self.plan.kind {
            InstanceKind::Cloth(_) => &[Method::Same, Method::Bcd],
            InstanceKind::Surface(_) => &[Method::Same],
        }
    }

    /// `level` with the lowest predicted error of the [`quick_methods`](Self::quick_methods),
    /// prepared side by side (rayon) after the reference: what a first
    /// switch goes live with while a slow estimate (`fit`) is prepared.
    /// Every method prepared stays prepared. Err: the first method's error
    /// when none could be prepared.
    pub fn prepare_quick_best(&self, level: Level) -> Result<Arc<Prepared>, PrepareError> {
        self.check_allowed(level)?;
        // The reference first, on this thread: every method needs it.
        match &self.plan.kind {
            InstanceKind::Cloth(scene) => {
                self.reference(scene)?;
            }
            InstanceKind::Surface(scene) => {
                self.surface_reference(scene)?;
            }
        }
        let results: Vec<Result<Arc<Prepared>, PrepareError>> = self
            .quick_methods()
            .par_iter()
            .map(|&method| self.prepare(level, method))
            .collect();
        let best = results
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .min_by(|a, b| a.predicted_error.total_cmp(&b.predicted_error))
            .cloned();
        match best {
            Some(p) => Ok(p),
            None => Err(results
                .into_iter()
                .find_map(Result::err)
                .expect("no method prepared, so one failed")),
        }
    }

    /// `level` of `scene` (the instance's integrator) estimated against
    /// the reference of `own` (the scene as written).
    fn prepare_cloth(
        &self,
        own: &Scene,
        scene: &Scene,
        level: Level,
        method: Method,
        cached_only: bool,
    ) -> Result<Option<Prepared>, PrepareError> {
        let started = Instant::now();
        let reference = self.reference(own)?;
        let failed = |e: PlanError| PrepareError::Failed {
            level,
            method,
            source: Box::new(e.into()),
        };
        let mass = MassConvention::Lumped;
        let integrator = self.plan.integrator;
        // One build of the level (a mesh level is simplified and correlated
        // once): at the configured dt, or as `default_problem` makes it (the
        // scene carries the plan's integrator).
        let problem = match self.plan.dt {
            Some(dt) => {
                LodProblem::at(scene, reference.clone(), level, mass, integrator, dt).map_err(|e| failed(e.into()))?
            }
            None => default_problem(scene, &reference, level).map_err(failed)?,
        }
        .with_turns(self.turns.clone());
        let dt = problem.dt;
        let frames = problem.frames();
        let fit = FitOptions {
            train: Some(0..frames),
            max_frames: self.estimation.fit_frames.min(frames),
            max_iterations: self.estimation.fit_iterations as usize,
            ..FitOptions::default()
        };
        // `follow` fits the level's restarts from the reference as a switch
        // down makes them: settled when the instance settles its switches.
        let settled;
        let estimating = match (method, self.plan.switch_settle) {
            (Method::Follow, Some(h)) => {
                settled = problem.clone().with_settling(h);
                &settled
            }
            _ => &problem,
        };
        let estimated = if cached_only {
            match self.estimator.cached(estimating, method, &fit) {
                Some(e) => e,
                None => return Ok(None),
            }
        } else {
            let name = &self.plan.name;
            let mut progress = progress_every(
                10.0,
                |p| tracing::info!(instance = %name, %level, %method, stage = p.stage, done = p.done, total = p.total, "estimating"),
            );
            self.estimator
                .estimate_reporting(estimating, method, &fit, &mut progress)
                .map_err(failed)?
        };
        let material = estimated.material;
        let (problem, limit) = if self.plan.dt.is_some() {
            let limit = problem.simulation(material).map_err(|e| failed(e.into()))?.dt_limit();
            if dt > limit {
                return Err(PrepareError::Unstable {
                    level,
                    method,
                    dt,
                    limit,
                });
            }
            (problem, limit)
        } else {
            stable_problem(&problem, material).map_err(failed)?
        };
        let report = problem
            .score(material, 0..frames, &mut no_progress)
            .map_err(|e| failed(e.into()))?;
        if report.diverged {
            return Err(PrepareError::Unstable {
                level,
                method,
                dt: problem.dt,
                limit,
            });
        }
        tracing::info!(
            instance = %self.plan.name,
            %level,
            %method,
            dt = problem.dt,
            predicted_error = report.mean,
            cached = estimated.cached,
            seconds = started.elapsed().as_secs_f64(),
            "level prepared"
        );
        Ok(Some(Prepared {
            level,
            method,
            material,
            dt: problem.dt,
            dt_limit: limit,
            predicted_error: report.mean,
            o_max: reference.o_max,
            estimate_seconds: estimated.seconds,
            cached: estimated.cached,
            basis: Basis::Cloth(Arc::new(problem)),
        }))
    }

    /// The start level with the scene's own coefficients, without a
    /// reference. Instant (a surface is simplified first: milliseconds to
    /// seconds); lets an instance step at once while its estimate is
    /// prepared.
    pub fn quick_start(&self) -> Result<Start, PrepareError> {
        self.quick(self.plan.start)
    }

    /// Any allowed `level` at rest with the scene's own coefficients at that
    /// resolution (what `same` estimates), without a reference: what an
    /// at-once switch goes live with while the level is prepared. A cloth
    /// takes milliseconds; a surface is simplified first.
    pub fn quick(&self, level: Level) -> Result<Start, PrepareError> {
        self.check_allowed(level)?;
        let failed = |source: PrepareFailure| PrepareError::Failed {
            level,
            method: Method::Same,
            source: Box::new(source),
        };
        match (&self.plan.kind, level) {
            (InstanceKind::Cloth(scene), Level::Grid { .. } | Level::Vertices(_)) => {
                let scene = Self::cloth_scene(scene, &self.plan);
                let (sim, dt) = self.cloth_at(&scene, level, None, self.plan.dt).map_err(failed)?;
                Ok(Start {
                    sim: self.live(sim),
                    dt,
                    cloud: None,
                })
            }
            (InstanceKind::Surface(scene), Level::Points(n)) => {
                let model = scene
                    .model(n, self.plan.integrator, None, &mut |_, _| {})
                    .map_err(|e| failed(e.into()))?;
                let cloud = CloudMap::of(&model);
                let dt = model.sim.params().dt;
                Ok(Start {
                    sim: self.live(model.sim),
                    dt,
                    cloud: Some(cloud),
                })
            }
            _ => Err(PrepareError::NotAllowed {
                level,
                allowed: allowed(&self.plan.levels),
            }),
        }
    }

    /// A cloth `level` at rest with `material` at `dt`, without its
    /// reference: what a snapshot's instance resumes with while its level
    /// is prepared again. `None` for a surface (its model comes from the
    /// simplification, which preparing does anyway).
    pub fn resume_simulation(
        &self,
        level: Level,
        material: Material,
        dt: f64,
    ) -> Option<Result<Simulation, PrepareError>> {
        let (InstanceKind::Cloth(scene), Level::Grid { .. } | Level::Vertices(_)) = (&self.plan.kind, level) else {
            return None;
        };
        let failed = |source: PrepareFailure| PrepareError::Failed {
            level,
            method: Method::Same,
            source: Box::new(source),
        };
        if let Err(e) = self.check_allowed(level) {
            return Some(Err(e));
        }
        let scene = Self::cloth_scene(scene, &self.plan);
        Some(
            self.cloth_at(&scene, level, Some(material), Some(dt))
                .map(|(sim, _)| self.live(sim))
                .map_err(failed),
        )
    }

    /// `prepared`'s level at rest, as the instance steps it live (its
    /// spring precision applied).
    pub fn live_simulation(&self, prepared: &Prepared) -> Result<Simulation, PrepareError> {
        prepared.simulation().map(|sim| self.live(sim))
    }

    /// `sim` made the instance's live simulation: springs in the configured
    /// precision (estimation and references never pass through here).
    fn live(&self, mut sim: Simulation) -> Simulation {
        sim.set_spring_precision(self.plan.spring_precision);
        sim
    }

    /// A cloth level at rest with lumped masses and `material` (`None`: the
    /// scene's own at that level, what `same` estimates); at `dt`, or when
    /// `None` at the largest step ≤ 0.75 × the predicted limit that divides
    /// the metric frame interval the reference will have (so the estimated
    /// model later lines up with it).
    fn cloth_at(
        &self,
        scene: &Scene,
        level: Level,
        material: Option<Material>,
        dt: Option<f64>,
    ) -> Result<(Simulation, f64), PrepareFailure> {
        let cloth = scene.cloth_level(level)?;
        let topology = cloth.topology.clone();
        let masses: Vec<f64> = topology.node_areas.iter().map(|a| a * scene.areal_density).collect();
        let loads = scene.loads_on(&topology, cloth.mesh.as_deref())?;
        let material = material.unwrap_or_else(|| scene.material_on(&cloth));
        let interval = scene.params.dt * self.estimation.spec.metric_stride as f64;
        let params = crate::sim::SimParams {
            material,
            ..scene.params
        };
        let build = |dt: f64, check| {
            Simulation::new(
                topology.clone(),
                masses.clone(),
                crate::sim::SimParams { dt, ..params },
                loads.clone(),
                State::at_rest(&topology),
                check,
            )
        };
        let dt = match dt {
            Some(dt) => dt,
            None => {
                let limit = build(interval, StabilityCheck::Force)?.dt_limit();
                super::estimator::frame_dt(interval, limit, 0.75)
            }
        };
        // A scene that says `force_unstable` gets its configured dt even
        // beyond the limit (the engine then rolls back and halts it).
        let sim = build(dt, scene.stability)?;
        Ok((sim, dt))
    }
}

/// The value in `slot`, or `record()`'s, stored there first: an instance's
/// references are recorded once.
fn once<T>(
    slot: &Mutex<Option<Arc<T>>>,
    record: impl FnOnce() -> Result<T, PrepareError>,
) -> Result<Arc<T>, PrepareError> {
    let mut slot = lock(slot);
    if let Some(r) = slot.as_ref() {
        return Ok(r.clone());
    }
    let r = Arc::new(record()?);
    *slot = Some(r.clone());
    Ok(r)
}

fn reference_failed(scene: &SurfaceScene, source: PrepareFailure) -> PrepareError {
    PrepareError::Reference {
        scene: scene.name.clone(),
        source: Box::new(source),
    }
}

/// `16x16, 24x24, …`
pub fn allowed(levels: &[Level]) -> String {
    levels.iter().map(|l| l.to_string()).collect::<Vec<_>>().join(", ")
}

/// Lock, ignoring poisoning: the guarded maps stay consistent because every
/// critical section only inserts finished values.
pub(crate) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
