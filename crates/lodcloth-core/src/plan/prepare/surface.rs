//! Preparing a level of a point-sampled surface: its all-points reference,
//! the simplified model and its coefficients (`same`, `fit` or the paper's
//! inverse fits on the surface's springs).

use std::sync::Arc;
use std::time::Instant;

use super::{once, reference_failed, Basis, Level, PrepareError, PrepareFailure, Prepared, Preparer};
use crate::cache::{CacheEntry, CacheError, CacheKey, Provenance};
use crate::estimate::inverse::{self, Distribution};
use crate::estimate::{no_progress, Method, RecordSpec, Reference};
use crate::lod::Correlation;
use crate::points::estimate::{self as surface_fit, SurfaceFitOptions, SurfaceReference};
use crate::points::model::PointModel;
use crate::points::scene::SurfaceScene;
use crate::sim::{Material, SimError};

impl Preparer {
    /// The surface reference: every point simulated over the scene,
    /// recorded on first use.
    pub(super) fn surface_reference(&self, scene: &SurfaceScene) -> Result<Arc<SurfaceReference>, PrepareError> {
        once(&self.surface_reference, || {
            let started = Instant::now();
            let mut model = self.all_points(scene)?;
            let reference = SurfaceReference::record(&mut model, scene.frames(), scene.interval())
                .map_err(|e| reference_failed(scene, e.into()))?;
            tracing::info!(
                instance = %self.plan.name,
                points = scene.points(),
                frames = reference.frames.len(),
                o_max = reference.o_max,
                seconds = started.elapsed().as_secs_f64(),
                "surface reference recorded"
            );
            Ok(reference)
        })
    }

    /// The model simulating every point of the cloud.
    pub(super) fn all_points(&self, scene: &SurfaceScene) -> Result<PointModel, PrepareError> {
        scene
            .model(scene.points(), self.plan.integrator, None, &mut |_, _| {})
            .map_err(|e| reference_failed(scene, e.into()))
    }

    /// A surface level: simplify to `points`, take the scene's coefficients
    /// (`same`) or fit the stretch and bend stiffness to the all-points
    /// reference (`fit`, cached on disk), then score it.
    pub(super) fn prepare_surface(
        &self,
        scene: &SurfaceScene,
        level: Level,
        points: usize,
        method: Method,
    ) -> Result<Prepared, PrepareError> {
        let started = Instant::now();
        let failed = |source: PrepareFailure| PrepareError::Failed {
            level,
            method,
            source: Box::new(source),
        };
        let reference = self.surface_reference(scene)?;
        let mut model = scene
            .model(points, self.plan.integrator, None, &mut |_, _| {})
            .map_err(|e| failed(e.into()))?;
        let frames = reference.frames.len();
        let (material, seconds, cached) = match method {
            // A surface has no grid directions: both "same"s are its springs.
            Method::Same | Method::SameSpring => (model.sim.params().material, 0.0, false),
            Method::Fit => self.surface_fit(scene, &mut model, &reference, points)?,
            Method::Shape | Method::Follow | Method::Drape => return Err(failed(PrepareFailure::ClothOnly(method))),
            Method::Bcd | Method::Gkd | Method::Lsq => {
                let estimated = self.surface_inverse(scene, &model, points, method)?;
                // The estimated springs may be stiffer than the scene's:
                // rebuild the level with its own stable dt.
                model = scene
                    .model(points, self.plan.integrator, Some(&estimated.0), &mut |_, _| {})
                    .map_err(|e| failed(e.into()))?;
                estimated
            }
        };
        let dt = model.sim.params().dt;
        surface_fit::apply_material(&mut model, material).map_err(|e| match e {
            SimError::UnstableTimeStep { dt, limit, .. } => PrepareError::Unstable {
                level,
                method,
                dt,
                limit,
            },
            e => failed(e.into()),
        })?;
        let limit = model.sim.dt_limit();
        let fresh = surface_fit::restart(&model).map_err(|e| failed(e.into()))?;
        let score = surface_fit::score(&mut model, fresh, &reference, 0..frames).map_err(|e| failed(e.into()))?;
        if !score.finite {
            return Err(PrepareError::Unstable {
                level,
                method,
                dt,
                limit,
            });
        }
        tracing::info!(
            instance = %self.plan.name,
            %level,
            %method,
            dt,
            predicted_error = score.mean,
            cached,
            seconds = started.elapsed().as_secs_f64(),
            "level prepared"
        );
        Ok(Prepared {
            level,
            method,
            material,
            dt,
            dt_limit: limit,
            predicted_error: score.mean,
            o_max: reference.o_max,
            estimate_seconds: seconds,
            cached,
            basis: Basis::Surface {
                model: Box::new(model),
                reference,
            },
        })
    }

    /// The fitted material of a surface level (cached on disk): returns it
    /// with the seconds the fit took and whether it came from the cache.
    fn surface_fit(
        &self,
        scene: &SurfaceScene,
        model: &mut PointModel,
        reference: &SurfaceReference,
        points: usize,
    ) -> Result<(Material, f64, bool), PrepareError> {
        let level = Level::Points(points);
        let failed = |source: PrepareFailure| PrepareError::Failed {
            level,
            method: Method::Fit,
            source: Box::new(source),
        };
        let options = SurfaceFitOptions {
            train: 0..reference.frames.len(),
            ..SurfaceFitOptions::default()
        };
        let integrator = model.sim.params().integrator.name().to_string();
        let dt = model.sim.params().dt;
        let mut fit = || -> Result<(Material, f64), PrepareError> {
            let t = Instant::now();
            let f = surface_fit::fit(model, reference, &options, &mut |_| {}).map_err(|e| failed(e.into()))?;
            tracing::info!(
                instance = %self.plan.name,
                %level,
                stretch_scale = f.stretch_scale,
                bend_scale = f.bend_scale,
                before = f.before.mean,
                after = f.after.mean,
                evaluations = f.evaluations,
                "surface stiffness fitted"
            );
            Ok((f.material, t.elapsed().as_secs_f64()))
        };
        let method = format!(
            "fit[surface;frames={};grid={};range={};iter={}]",
            options.train.end, options.grid, options.log_range, options.iterations
        );
        self.surface_cached(scene, points, method, integrator, dt, &mut fit)
    }

    /// The paper's BCD or GKD, or our `lsq`, on a surface level: the
    /// all-points run recorded with estimation samples, mapped onto the
    /// level's points through [`Correlation::subset`] (simulated points are
    /// cloud points), then the inverse Hooke fit of the cloth. Cached on disk.
    fn surface_inverse(
        &self,
        scene: &SurfaceScene,
        model: &PointModel,
        points: usize,
        method: Method,
    ) -> Result<(Material, f64, bool), PrepareError> {
        let level = Level::Points(points);
        let failed = |source: PrepareFailure| PrepareError::Failed {
            level,
            method,
            source: Box::new(source),
        };
        let integrator = model.sim.params().integrator.name().to_string();
        let dt = model.sim.params().dt;
        let mut estimate = || -> Result<(Material, f64), PrepareError> {
            let t = Instant::now();
            let reference = self.surface_samples(scene)?;
            let correlation = Correlation::subset(reference.topology.n_nodes, &model.kept);
            let mut coarse = model.sim.clone();
            let observations = inverse::observe(&reference, &correlation, &mut coarse, &mut no_progress);
            let material = match method {
                Method::Lsq => {
                    inverse::lsq_estimate(&reference.material, coarse.topology(), &observations, &mut no_progress)
                        .material
                }
                _ => {
                    let distribution = if method == Method::Bcd {
                        Distribution::Bcd
                    } else {
                        Distribution::Gkd
                    };
                    inverse::inverse_estimate(
                        &reference.material,
                        &reference,
                        &correlation,
                        coarse.topology(),
                        &observations,
                        distribution,
                        inverse::Reading::default(),
                        &mut no_progress,
                    )
                    .material
                }
            };
            if material
                .springs
                .iter()
                .any(|s| !(s.k.is_finite() && s.k >= 0.0 && s.c.is_finite()))
            {
                return Err(failed(PrepareFailure::Unusable(material)));
            }
            Ok((material, t.elapsed().as_secs_f64()))
        };
        let key_method = format!(
            "{method}[v{};surface;samples-per-frame=1;span=1;reading={}]",
            crate::plan::estimator::ESTIMATORS_VERSION,
            inverse::Reading::default()
        );
        self.surface_cached(scene, points, key_method, integrator, dt, &mut estimate)
    }

    /// The all-points surface run recorded as a cloth reference: one
    /// estimation sample (three consecutive steps) per frame interval.
    fn surface_samples(&self, scene: &SurfaceScene) -> Result<Arc<Reference>, PrepareError> {
        once(&self.surface_samples, || {
            let started = Instant::now();
            let model = self.all_points(scene)?;
            let per_frame = (scene.interval() / model.sim.params().dt).round() as u64;
            let spec = RecordSpec {
                frames: per_frame * scene.frames() as u64,
                metric_stride: per_frame,
                estimate_stride: per_frame.max(2),
                difference_span: 1,
            };
            let reference =
                Reference::record(model.sim, spec, &mut |_, _| {}).map_err(|e| reference_failed(scene, e.into()))?;
            tracing::info!(
                instance = %self.plan.name,
                samples = reference.samples.len(),
                seconds = started.elapsed().as_secs_f64(),
                "surface estimation samples recorded"
            );
            Ok(reference)
        })
    }

    /// `compute`'s material for a surface level through the on-disk cache:
    /// returns it with the seconds it took and whether it was a cache hit.
    fn surface_cached(
        &self,
        scene: &SurfaceScene,
        points: usize,
        method: String,
        integrator: String,
        dt: f64,
        compute: &mut dyn FnMut() -> Result<(Material, f64), PrepareError>,
    ) -> Result<(Material, f64, bool), PrepareError> {
        let level = Level::Points(points);
        let Some(cache) = self.estimator.cache.as_ref() else {
            return compute().map(|(m, s)| (m, s, false));
        };
        let key = CacheKey {
            scene: scene.name.clone(),
            scene_hash: scene.source_hash,
            reference: (scene.points(), 1),
            target: (points, 1),
            method,
            mass: "point-area".into(),
            integrator,
            dt,
        };
        // A cache that cannot be read or written costs a recomputation,
        // never the level.
        enum Failure {
            Fit(PrepareError),
            Cache(CacheError),
        }
        impl From<CacheError> for Failure {
            fn from(e: CacheError) -> Failure {
                Failure::Cache(e)
            }
        }
        let mut computed = None;
        let result = cache.get_or_compute(&key, || -> Result<CacheEntry, Failure> {
            let (material, s) = compute().map_err(Failure::Fit)?;
            computed = Some((material, s));
            let mut entry = CacheEntry::new(key.clone(), material);
            entry.notes.insert("estimate_seconds".into(), s);
            Ok(entry)
        });
        match result {
            Ok((entry, provenance)) => Ok((
                entry.material,
                computed.map_or(0.0, |(_, s)| s),
                provenance == Provenance::Hit,
            )),
            Err(Failure::Fit(e)) => Err(e),
            Err(Failure::Cache(e)) => {
                tracing::warn!(instance = %self.plan.name, %level, "coefficient cache: {e}; using the fit uncached");
                match computed {
                    Some((material, s)) => Ok((material, s, false)),
                    None => compute().map(|(m, s)| (m, s, false)),
                }
            }
        }
    }
}
