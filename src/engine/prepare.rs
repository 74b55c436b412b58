//! Getting a level ready to run: the instance's reference recording,
//! coefficients (from the on-disk cache or estimated), a stable dt and the
//! level's predicted error (calibration against the reference). Blocking and
//! possibly slow (seconds to minutes); the service runs it on background
//! threads, never on a stepping thread.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::cache::CoefficientCache;
use crate::estimate::{no_progress, FitOptions, LodProblem, Method, Reference};
use crate::experiments::lod::{level_dt, record_reference, stable_problem, Estimator, ExperimentError};
use crate::proto::Level;
use crate::scene::MassConvention;
use crate::service::config::{EstimationConfig, InstanceConfig};
use crate::sim::{Material, Simulation, StabilityCheck, State, Topology};

/// Why a level could not be prepared.
#[derive(Debug, Clone, thiserror::Error)]
pub enum PrepareError {
    #[error("level {level} is not one of the allowed levels {allowed}")]
    NotAllowed { level: Level, allowed: String },
    #[error(
        "level {level} with {method} coefficients is unstable at dt = {dt:e} s (predicted limit {limit:e} s); \
         choose another level or method, or lower the instance's dt"
    )]
    Unstable {
        level: Level,
        method: Method,
        dt: f64,
        limit: f64,
    },
    #[error("preparing level {level} with {method}: {message}")]
    Failed {
        level: Level,
        method: Method,
        message: String,
    },
    #[error("recording the reference of {scene}: {message}")]
    Reference { scene: String, message: String },
}

/// A level ready to switch to.
#[derive(Debug)]
pub struct Prepared {
    pub level: Level,
    pub method: Method,
    pub material: Material,
    /// The level against the reference; its `dt` is the level's time step.
    pub problem: Arc<LodProblem>,
    /// Predicted stability limit of `material` at this level (s).
    pub dt_limit: f64,
    /// Mean relative error over the recorded reference.
    pub predicted_error: f64,
    /// Wall seconds the estimate took (0 on a cache hit).
    pub estimate_seconds: f64,
    pub cached: bool,
}

impl Prepared {
    /// A simulation of this level at rest.
    pub fn simulation(&self) -> Result<Simulation, PrepareError> {
        self.problem
            .simulation(self.material)
            .map_err(|e| PrepareError::Failed {
                level: self.level,
                method: self.method,
                message: e.to_string(),
            })
    }
}

/// Prepares the levels of one instance; remembers what it prepared.
#[derive(Debug)]
pub struct Preparer {
    config: Arc<InstanceConfig>,
    estimation: EstimationConfig,
    estimator: Estimator,
    reference: Mutex<Option<Arc<Reference>>>,
    prepared: Mutex<HashMap<(Level, Method), Arc<Prepared>>>,
    /// One preparation at a time per instance: a second request for the same
    /// level waits for the first and then finds it prepared.
    work: Mutex<()>,
}

impl Preparer {
    pub fn new(config: Arc<InstanceConfig>, estimation: EstimationConfig, cache: Option<CoefficientCache>) -> Preparer {
        let tag = format!(
            "daemon;ref={};ms={};es={}",
            estimation.spec.frames, estimation.spec.metric_stride, estimation.spec.estimate_stride
        );
        Preparer {
            config,
            estimation,
            estimator: Estimator { cache, tag },
            reference: Mutex::new(None),
            prepared: Mutex::new(HashMap::new()),
            work: Mutex::new(()),
        }
    }

    pub fn config(&self) -> &Arc<InstanceConfig> {
        &self.config
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

    /// The reference run, recorded on first use.
    pub fn reference(&self) -> Result<Arc<Reference>, PrepareError> {
        let mut slot = lock(&self.reference);
        if let Some(r) = slot.as_ref() {
            return Ok(r.clone());
        }
        let scene = self.scene();
        let name = self.config.name.clone();
        let (reference, _) = record_reference(&scene, self.estimation.spec, &mut |line| {
            tracing::info!(instance = %name, "{line}");
        })
        .map_err(|e| PrepareError::Reference {
            scene: scene.name.clone(),
            message: e.to_string(),
        })?;
        tracing::info!(
            instance = %self.config.name,
            frames = reference.frames.len(),
            o_max = reference.o_max,
            "reference recorded"
        );
        *slot = Some(reference.clone());
        Ok(reference)
    }

    /// The reference if it has been recorded.
    pub fn reference_if_ready(&self) -> Option<Arc<Reference>> {
        lock(&self.reference).clone()
    }

    fn scene(&self) -> crate::scene::Scene {
        let mut scene = self.config.scene.clone();
        scene.params.integrator = self.config.integrator;
        scene
    }

    /// Prepare `level` with `method` (blocking; cached after the first time).
    pub fn prepare(&self, level: Level, method: Method) -> Result<Arc<Prepared>, PrepareError> {
        if !self.config.levels.contains(&level) {
            return Err(PrepareError::NotAllowed {
                level,
                allowed: allowed(&self.config.levels),
            });
        }
        if let Some(p) = self.get(level, method) {
            return Ok(p);
        }
        let _guard = lock(&self.work);
        if let Some(p) = self.get(level, method) {
            return Ok(p);
        }
        let started = Instant::now();
        let reference = self.reference()?;
        let scene = self.scene();
        let failed = |e: ExperimentError| PrepareError::Failed {
            level,
            method,
            message: e.to_string(),
        };
        let mass = MassConvention::Lumped;
        let integrator = self.config.integrator;
        let dt = match self.config.dt {
            Some(dt) => dt,
            None => {
                level_dt(
                    &scene,
                    &reference,
                    level.nx,
                    level.ny,
                    mass,
                    integrator,
                    reference.material,
                    0.75,
                )
                .map_err(failed)?
                .0
            }
        };
        let problem = LodProblem::new(&scene, reference.clone(), level.nx, level.ny, mass, integrator, dt)
            .map_err(|e| failed(e.into()))?;
        let frames = problem.frames();
        let fit = FitOptions {
            train: Some(0..frames),
            max_frames: self.estimation.fit_frames.min(frames),
            max_iterations: self.estimation.fit_iterations as usize,
            ..FitOptions::default()
        };
        let estimated = self.estimator.estimate(&problem, method, &fit).map_err(failed)?;
        let material = estimated.material;
        let (problem, limit) = if self.config.dt.is_some() {
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
        let prepared = Arc::new(Prepared {
            level,
            method,
            material,
            problem: Arc::new(problem),
            dt_limit: limit,
            predicted_error: report.mean,
            estimate_seconds: estimated.seconds,
            cached: estimated.cached,
        });
        tracing::info!(
            instance = %self.config.name,
            %level,
            %method,
            dt = prepared.problem.dt,
            predicted_error = report.mean,
            cached = estimated.cached,
            seconds = started.elapsed().as_secs_f64(),
            "level prepared"
        );
        lock(&self.prepared).insert((level, method), prepared.clone());
        Ok(prepared)
    }

    /// The start level with the scene's own coefficients, without a
    /// reference: lumped masses, dt the largest step ≤ 0.75 × the predicted
    /// limit that divides the metric frame interval the reference will have
    /// (so the estimated model later lines up with it). Instant; lets an
    /// instance step at once while its estimate is prepared.
    pub fn quick_start(&self) -> Result<(Simulation, f64), PrepareError> {
        let level = self.config.start;
        let scene = self.scene();
        let failed = |message: String| PrepareError::Failed {
            level,
            method: Method::Same,
            message,
        };
        let topology = Arc::new(Topology::grid(scene.shape(level.nx, level.ny), scene.orientation));
        let masses: Vec<f64> = topology.node_areas.iter().map(|a| a * scene.areal_density).collect();
        let loads = scene.loads(&topology).map_err(|e| failed(e.to_string()))?;
        let interval = scene.params.dt * self.estimation.spec.metric_stride as f64;
        let params = scene.params;
        let build = |dt: f64, check| {
            Simulation::new(
                topology.clone(),
                masses.clone(),
                crate::sim::SimParams { dt, ..params },
                loads.clone(),
                State::at_rest(&topology),
                check,
            )
            .map_err(|e| failed(e.to_string()))
        };
        let dt = match self.config.dt {
            Some(dt) => dt,
            None => {
                let limit = build(interval, StabilityCheck::Force)?.dt_limit();
                interval / (interval / (0.75 * limit)).ceil().max(1.0)
            }
        };
        let sim = build(dt, StabilityCheck::Enforce)?;
        Ok((sim, dt))
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
