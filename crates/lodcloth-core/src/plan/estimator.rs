//! Planning a level: recording the reference, choosing a stable dt, and
//! estimating coefficients through the on-disk cache. Shared by the daemon's
//! [`Preparer`](super::Preparer) and the experiments, so both run a level
//! the same way.

use std::sync::Arc;
use std::time::Instant;

use crate::cache::{CacheEntry, CacheError, CacheKey, CoefficientCache, Provenance};
use crate::estimate::{
    no_progress, Details, EstimateError, FitOptions, LodProblem, Method, Progress, ProgressFn, RecordSpec, Reference,
    ReferenceError,
};
use crate::level::Level;
use crate::scene::{MassConvention, Scene, SceneError};
use crate::sim::{Integrator, Material, StabilityCheck};

/// Why a level could not be planned: its scene, reference, estimate or cache failed.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// The scene could not be built at a level.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The reference run of `scene` failed (diverged or could not start).
    #[error("{scene}: {source}")]
    Reference {
        /// The scene's name.
        scene: String,
        /// Why the recording failed.
        source: ReferenceError,
    },
    /// An estimator failed.
    #[error(transparent)]
    Estimate(#[from] EstimateError),
    /// The coefficient cache could not be read or written.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// The request itself is impossible (e.g. no held-out frames).
    #[error("{0}")]
    Invalid(String),
}

/// The estimators' behaviour, in the cache key: raise it with any change
/// that alters what an estimator returns for the same inputs (2: BCD/GKD
/// readings, the fit's guard against `same`, `same` bit for bit on square
/// cells; 3: a Broyden-updated Jacobian, withdrawn; 4: BCD among the fit's
/// starts, its tolerance 1 %; 5: the fit stops on a predicted gain below its
/// tolerance; 6: BCD, GKD and `lsq` hold a mesh level's stretch at the
/// material's), so no cache serves an estimate made by other code.
pub const ESTIMATORS_VERSION: u32 = 6;

/// Runs estimators, through the on-disk coefficient cache when there is one.
#[derive(Debug, Clone, Default)]
pub struct Estimator {
    /// Where estimates are kept between runs (`None`: always compute).
    pub cache: Option<CoefficientCache>,
    /// Everything besides the cache key's fields that changes an estimate
    /// (record spec, fit settings), folded into the key's method string.
    pub tag: String,
}

/// What [`Estimator::estimate`] returns.
#[derive(Debug, Clone)]
pub struct Estimated {
    /// The estimated coefficients (K, C per spring type).
    pub material: Material,
    /// One-line diagnostics of the estimate ([`notes`]), or where it came from.
    pub notes: String,
    /// Wall seconds spent estimating (0 on a cache hit).
    pub seconds: f64,
    /// Read from the cache rather than computed.
    pub cached: bool,
}

impl Estimator {
    /// Estimate with `method`, or read it from the cache.
    pub fn estimate(&self, problem: &LodProblem, method: Method, fit: &FitOptions) -> Result<Estimated, PlanError> {
        self.estimate_reporting(problem, method, fit, &mut no_progress)
    }

    /// [`estimate`](Self::estimate), telling `progress` how a computed
    /// estimate goes (nothing on a cache hit).
    pub fn estimate_reporting(
        &self,
        problem: &LodProblem,
        method: Method,
        fit: &FitOptions,
        progress: ProgressFn,
    ) -> Result<Estimated, PlanError> {
        let mut compute = || -> Result<Estimated, PlanError> {
            let t = Instant::now();
            let est = problem.estimate(method, fit, progress)?;
            Ok(Estimated {
                material: est.material,
                notes: notes(&est.details),
                seconds: t.elapsed().as_secs_f64(),
                cached: false,
            })
        };
        let Some(cache) = self.cache.as_ref().filter(|_| method != Method::Same) else {
            return compute();
        };
        let key = self.key(problem, method, fit);
        let mut fresh = None;
        let (entry, provenance) = cache.get_or_compute(&key, || -> Result<CacheEntry, PlanError> {
            let e = compute()?;
            let mut entry = CacheEntry::new(key.clone(), e.material);
            entry.notes.insert("estimate_seconds".into(), e.seconds);
            fresh = Some(e);
            Ok(entry)
        })?;
        Ok(match (provenance, fresh) {
            (Provenance::Hit, _) | (_, None) => hit(&entry),
            (_, Some(e)) => e,
        })
    }

    /// The estimate of `method` on `problem` when the cache holds it,
    /// without estimating (`None`: no cache, no entry, or `same`, which is
    /// never cached). A cache that cannot be read counts as no entry.
    pub fn cached(&self, problem: &LodProblem, method: Method, fit: &FitOptions) -> Option<Estimated> {
        let cache = self.cache.as_ref().filter(|_| method != Method::Same)?;
        let entry = cache.get(&self.key(problem, method, fit)).ok()??;
        Some(hit(&entry))
    }

    /// The cache key of `method` on `problem` with `fit`'s settings.
    fn key(&self, problem: &LodProblem, method: Method, fit: &FitOptions) -> CacheKey {
        let train = fit.train_range(problem.frames());
        // A level served with another integrator than its reference ran:
        // the key names both, so an estimate made against a reference of
        // another integrator is never taken for this one.
        let reference_integrator = if problem.reference.integrator == problem.integrator {
            String::new()
        } else {
            format!("[reference={}]", problem.reference.integrator.name())
        };
        CacheKey {
            scene: problem.scene.name.clone(),
            scene_hash: problem.scene.source_hash,
            reference: cache_pair(problem.scene.reference_level()),
            target: cache_pair(problem.level),
            method: format!(
                "{method}[v{ESTIMATORS_VERSION};{};train={}..{};frames={};iter={};tol={};reading={};guard={},{},{}]",
                self.tag,
                train.start,
                train.end,
                fit.max_frames,
                fit.max_iterations,
                fit.tolerance,
                fit.reading,
                fit.min_gain,
                fit.short_tolerance,
                fit.guard_window
            ) + &problem.settling().map_or(String::new(), |h| format!("[settle={h}]"))
                + &reference_integrator
                // Self-contact can be set by a daemon's instance, not only by
                // the scene file, whose text the key hashes.
                + &problem.scene.params.self_contact.map_or(String::new(), |c| {
                    format!("[self={},{}]", c.thickness, c.friction)
                }),
            mass: problem.mass.name().to_string(),
            integrator: problem.integrator.name().to_string(),
            dt: problem.dt,
        }
    }
}

/// `log` given an estimate's progress at most once per `seconds` (the
/// first report at once): what a long estimate (`drape`, minutes) shows
/// while it runs.
pub fn progress_every(seconds: f64, mut log: impl FnMut(Progress)) -> impl FnMut(Progress) {
    let mut last: Option<Instant> = None;
    move |p| {
        if last.is_none_or(|t| t.elapsed().as_secs_f64() >= seconds) {
            last = Some(Instant::now());
            log(p);
        }
    }
}

/// An estimate read from the cache.
fn hit(entry: &CacheEntry) -> Estimated {
    Estimated {
        material: entry.material,
        notes: format!(
            "cached ({:.1} s when computed)",
            entry.notes.get("estimate_seconds").copied().unwrap_or(f64::NAN)
        ),
        seconds: 0.0,
        cached: true,
    }
}

/// Record the reference run of `scene` at its own resolution.
pub fn record_reference(
    scene: &Scene,
    spec: RecordSpec,
    log: &mut dyn FnMut(String),
) -> Result<(Arc<Reference>, f64), PlanError> {
    record_reference_while(scene, spec, log, &|| true)
}

/// [`record_reference`], stopped when `keep_going` says no
/// ([`Reference::record_while`]).
pub fn record_reference_while(
    scene: &Scene,
    spec: RecordSpec,
    log: &mut dyn FnMut(String),
    keep_going: &dyn Fn() -> bool,
) -> Result<(Arc<Reference>, f64), PlanError> {
    let mut s = scene.clone();
    s.stability = StabilityCheck::Enforce;
    let sim = s.build()?;
    let start = Instant::now();
    let mut last = Instant::now();
    let name = scene.name.clone();
    let mut progress = |done, total| {
        if last.elapsed().as_secs_f64() > 5.0 {
            last = Instant::now();
            log(format!("{name}: reference {done}/{total} steps"));
        }
    };
    let reference =
        Reference::record_while(sim, spec, &mut progress, keep_going).map_err(|source| PlanError::Reference {
            scene: scene.name.clone(),
            source,
        })?;
    let wall = start.elapsed().as_secs_f64();
    let simulated = spec.frames as f64 * reference.dt;
    Ok((Arc::new(reference), wall / simulated))
}

/// A level as the cache's key writes it: a grid's `(nx, ny)`, a mesh's
/// `(vertices, 0)` (no grid has a side of 0).
fn cache_pair(level: Level) -> (usize, usize) {
    match level {
        Level::Grid { nx, ny } => (nx, ny),
        Level::Points(n) | Level::Vertices(n) => (n, 0),
    }
}

/// The largest dt ≤ `margin` × `limit` that divides `interval` (a metric
/// frame holds a whole number of steps), or `interval` when it is smaller.
pub fn frame_dt(interval: f64, limit: f64, margin: f64) -> f64 {
    interval / (interval / (margin * limit)).ceil().max(1.0)
}

/// The largest dt ≤ `margin` × the predicted stability limit of `material` at
/// `level` that divides the reference's metric frame interval.
pub fn level_dt(
    scene: &Scene,
    reference: &Arc<Reference>,
    level: impl Into<Level>,
    mass: MassConvention,
    integrator: Integrator,
    material: Material,
    margin: f64,
) -> Result<(f64, f64), PlanError> {
    let interval = reference.dt * reference.spec.metric_stride as f64;
    let probe = LodProblem::at(scene, reference.clone(), level.into(), mass, integrator, interval)?;
    let limit = probe.simulation(material)?.dt_limit();
    Ok((frame_dt(interval, limit, margin), limit))
}

/// `level` of `scene` (a grid `(nx, ny)` or any [`Level`]) as the daemon
/// and `lod-plan` run it: lumped masses, the scene's integrator, dt at ≤
/// 0.75 of the `same` model's stability limit.
pub fn default_problem(
    scene: &Scene,
    reference: &Arc<Reference>,
    level: impl Into<Level>,
) -> Result<LodProblem, PlanError> {
    let level = level.into();
    let integrator = scene.params.integrator;
    let mass = MassConvention::Lumped;
    let interval = reference.dt * reference.spec.metric_stride as f64;
    // One build of the level: probed at the frame interval with its `same`
    // material, then given the largest dt ≤ 0.75 of that limit dividing it.
    let probe = LodProblem::at(scene, reference.clone(), level, mass, integrator, interval)?;
    let limit = probe.simulation(probe.same_material())?.dt_limit();
    let dt = frame_dt(interval, limit, 0.75);
    Ok(probe.with_dt(dt)?)
}

/// `problem` itself when `material` runs within 0.8 of its predicted
/// stability limit at `problem.dt`, else the same level at the largest dt
/// that does; with the model's limit. Every scored model obeys this bound.
pub fn stable_problem(problem: &LodProblem, material: Material) -> Result<(LodProblem, f64), PlanError> {
    let limit = problem.simulation(material)?.dt_limit();
    if problem.dt <= 0.8 * limit {
        return Ok((problem.clone(), limit));
    }
    // The limit does not depend on dt: the same level at a dividing dt.
    let interval = problem.reference.dt * problem.reference.spec.metric_stride as f64;
    let dt = frame_dt(interval, limit, 0.8);
    Ok((problem.with_dt(dt)?, limit))
}

/// One-line diagnostics of an estimate.
pub fn notes(details: &Details) -> String {
    match details {
        Details::Same => String::new(),
        Details::Inverse(e) => {
            let r = &e.rejections;
            let considered: u64 = r.considered.iter().sum();
            let rejected: u64 = r.near_rest.iter().sum::<u64>() + r.negative_k.iter().sum::<u64>();
            let fallbacks = e.fallback_k.iter().chain(&e.fallback_c).filter(|&&f| f).count();
            let held = e.held.iter().filter(|&&h| h).count();
            format!(
                "rejected K samples {rejected}/{considered} (near rest {}, negative {}); C: no rel. velocity {}, negative {}; fallbacks {fallbacks}; classes held at the material {held}",
                r.near_rest.iter().sum::<u64>(),
                r.negative_k.iter().sum::<u64>(),
                r.no_relative_velocity.iter().sum::<u64>(),
                r.negative_c.iter().sum::<u64>()
            )
        }
        Details::Lsq(e) => format!(
            "condition {:.2e}, relative residual {:.3}, clamped {}, held at the material {}",
            e.condition,
            e.relative_residual,
            e.clamped.iter().filter(|&&c| c).count(),
            e.held.iter().filter(|&&h| h).count()
        ),
        Details::Fit(f) => format!(
            "start {} (train rms {:.3}%), train rms {:.3}% after {} iterations, {} runs, {}{}",
            f.start,
            100.0 * f.start_rms,
            100.0 * f.rms,
            f.iterations,
            f.evaluations,
            f.stop,
            f.kept_start.as_ref().map_or(String::new(), |k| format!("; {k}"))
        ),
        Details::Drape(d) => format!(
            "bending x{:.4} of the start; shadow {:.6} m² against the reference's {:.6} ({:+.2}%; the start's {:+.2}%), {} runs{}",
            d.factor,
            d.shadow,
            d.target,
            100.0 * (d.shadow / d.target - 1.0),
            100.0 * (d.start_shadow / d.target - 1.0),
            d.runs.len(),
            if d.converged { "" } else { ", not within the tolerance" }
        ),
    }
}
