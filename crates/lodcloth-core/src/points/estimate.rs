//! Coefficients for a simplified surface, estimated from the all-points
//! simulation so the simplified one moves like it — the cloth's `fit`
//! idea ([`crate::estimate::fit`]) on point surfaces.
//!
//! The reference is the full cloud simulated with every point (or any
//! finer model), recorded at fixed frame times. A candidate pair of
//! stiffness scales (stretch K, bend K) is scored by simulating the
//! simplified surface, moving the full cloud with the transfer at every
//! frame, and taking the mean displacement error over the training frames
//! normalised by the reference's largest displacement (the cloth metric,
//! Sung eq. 9, on every original point). The scales are searched in log
//! space: a grid scan over both, then Nelder–Mead from the best cell;
//! candidates whose dt
//! would exceed `max_dt_fraction` of the stability limit are rejected, so a
//! fit never produces an unstable model. Pure: no I/O, no threads.

use std::sync::Arc;

use super::model::PointModel;
use crate::sim::vec3::{dist, V3};
use crate::sim::{Material, SimError, Simulation, SpringClass, SpringKind, StabilityCheck, State};

/// The full cloud's motion, recorded at fixed frame times.
#[derive(Debug, Clone)]
pub struct SurfaceReference {
    /// Positions of every original point at frame f (time `(f + 1) · interval`).
    pub frames: Vec<Vec<V3>>,
    /// Rest positions of the original points.
    pub rest: Vec<V3>,
    /// Time between frames (s).
    pub interval: f64,
    /// Largest displacement of any point in any frame (m).
    pub o_max: f64,
}

/// Why a reference or a fit failed.
#[derive(Debug, thiserror::Error)]
pub enum SurfaceEstimateError {
    /// The model's dt does not divide the frame interval.
    #[error("the model's dt {dt} s does not divide the frame interval {interval} s")]
    FrameMismatch {
        /// The model's time step (s).
        dt: f64,
        /// The reference's frame interval (s).
        interval: f64,
    },
    /// The reference became non-finite at this frame.
    #[error("the reference diverged at frame {0}")]
    Diverged(usize),
    /// The reference never moved.
    #[error("the reference never moved: there is nothing to fit")]
    NoMotion,
    /// The model and the reference have different clouds.
    #[error("the model has {model} points, the reference {reference}")]
    Points {
        /// Points the model moves.
        model: usize,
        /// Points in the reference.
        reference: usize,
    },
    /// The simulation refused the rescaled coefficients.
    #[error("{0}")]
    Sim(#[from] SimError),
}

/// Steps of `model` per frame of `interval`.
fn steps_per_frame(model: &PointModel, interval: f64) -> Result<u64, SurfaceEstimateError> {
    let dt = model.sim.params().dt;
    let ratio = interval / dt;
    if !(ratio >= 1.0 - 1e-9) || (ratio - ratio.round()).abs() > 1e-6 {
        return Err(SurfaceEstimateError::FrameMismatch { dt, interval });
    }
    Ok(ratio.round() as u64)
}

impl SurfaceReference {
    /// Record `frames` frames of `model` (usually every point simulated),
    /// whose dt must divide `interval`.
    pub fn record(
        model: &mut PointModel,
        frames: usize,
        interval: f64,
    ) -> Result<SurfaceReference, SurfaceEstimateError> {
        let per = steps_per_frame(model, interval)?;
        let rest = model.rest.positions.clone();
        let mut out = Vec::with_capacity(frames);
        let mut o_max: f64 = 0.0;
        for f in 0..frames {
            for _ in 0..per {
                if !model.step().finite {
                    return Err(SurfaceEstimateError::Diverged(f));
                }
            }
            model.update_cloud();
            for (p, q) in model.positions.iter().zip(&rest) {
                o_max = o_max.max(dist(*p, *q));
            }
            out.push(model.positions.clone());
        }
        if !(o_max > 0.0) {
            return Err(SurfaceEstimateError::NoMotion);
        }
        Ok(SurfaceReference {
            frames: out,
            rest,
            interval,
            o_max,
        })
    }
}

/// The error of a simulated surface against a reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceScore {
    /// Mean over points and the scored frames, relative to `o_max`.
    pub mean: f64,
    /// Largest single-point error, relative to `o_max`.
    pub max: f64,
    /// False when the simulation diverged (then both are infinite).
    pub finite: bool,
}

/// Simulate `sim` (a fresh copy of the model's simulation) against the
/// reference and score frames `range` (all frames are simulated up to its end).
pub fn score(
    model: &mut PointModel,
    sim: Simulation,
    reference: &SurfaceReference,
    range: std::ops::Range<usize>,
) -> Result<SurfaceScore, SurfaceEstimateError> {
    if model.rest.len() != reference.rest.len() {
        return Err(SurfaceEstimateError::Points {
            model: model.rest.len(),
            reference: reference.rest.len(),
        });
    }
    let saved = std::mem::replace(&mut model.sim, sim);
    let per = steps_per_frame(model, reference.interval);
    let result = per.map(|per| {
        let (mut sum, mut max, mut count) = (0.0, 0.0f64, 0usize);
        for f in 0..range.end.min(reference.frames.len()) {
            for _ in 0..per {
                if !model.step().finite {
                    return SurfaceScore {
                        mean: f64::INFINITY,
                        max: f64::INFINITY,
                        finite: false,
                    };
                }
            }
            if f < range.start {
                continue;
            }
            model.update_cloud();
            for (p, q) in model.positions.iter().zip(&reference.frames[f]) {
                let e = dist(*p, *q) / reference.o_max;
                sum += e;
                max = max.max(e);
                count += 1;
            }
        }
        SurfaceScore {
            mean: sum / count.max(1) as f64,
            max,
            finite: true,
        }
    });
    model.sim = saved;
    result
}

/// Fit settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceFitOptions {
    /// Frames the error is measured on (the rest are held out).
    pub train: std::ops::Range<usize>,
    /// Search range of each log-scale: factors in [e^−r, e^r].
    pub log_range: f64,
    /// Grid points per log-scale of the initial scan.
    pub grid: usize,
    /// Nelder–Mead iterations after the scan.
    pub iterations: usize,
    /// A candidate is rejected when the model's dt exceeds this fraction of
    /// its predicted stability limit.
    pub max_dt_fraction: f64,
}

impl Default for SurfaceFitOptions {
    fn default() -> Self {
        SurfaceFitOptions {
            train: 0..usize::MAX,
            log_range: 1.6,
            grid: 11,
            iterations: 60,
            max_dt_fraction: 0.95,
        }
    }
}

/// A fitted material.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceFit {
    /// The fitted stretch and bend coefficients.
    pub material: Material,
    /// Factors applied to the starting stretch and bend stiffness.
    pub stretch_scale: f64,
    /// See `stretch_scale`.
    pub bend_scale: f64,
    /// Training error before and after.
    pub before: SurfaceScore,
    /// See `before`.
    pub after: SurfaceScore,
    /// Simulations run.
    pub evaluations: usize,
}

/// A copy of the model's simulation with the stiffness scaled, at rest at
/// t = 0; `None` when its dt would exceed `max_fraction` of the limit.
pub fn rescaled(
    model: &PointModel,
    stretch: f64,
    bend: f64,
    max_fraction: f64,
) -> Result<Option<Simulation>, SimError> {
    let s = &model.sim;
    let mut params = *s.params();
    for class in SpringClass::ALL {
        match class.kind() {
            SpringKind::Structural => params.material.springs[class.index()].k *= stretch,
            SpringKind::Bend => params.material.springs[class.index()].k *= bend,
            SpringKind::Shear => {}
        }
    }
    let topology: Arc<_> = s.topology().clone();
    let sim = Simulation::new(
        topology.clone(),
        s.masses().to_vec(),
        params,
        s.loads().clone(),
        State::at_rest(&topology),
        StabilityCheck::Force,
    )?;
    let ok = !max_fraction.is_finite() || params.dt <= max_fraction * sim.dt_limit();
    Ok(ok.then_some(sim))
}

/// Fit the stretch and bend stiffness of `model` (at rest, t = 0) to the reference.
pub fn fit(
    model: &mut PointModel,
    reference: &SurfaceReference,
    options: &SurfaceFitOptions,
    progress: &mut dyn FnMut(usize),
) -> Result<SurfaceFit, SurfaceEstimateError> {
    let train = options.train.start..options.train.end.min(reference.frames.len());
    let mut evaluations = 0;
    let mut eval = |model: &mut PointModel, ls: f64, lb: f64| -> Result<f64, SurfaceEstimateError> {
        evaluations += 1;
        progress(evaluations);
        match rescaled(model, ls.exp(), lb.exp(), options.max_dt_fraction)? {
            Some(sim) => Ok(score(model, sim, reference, train.clone())?.mean),
            None => Ok(f64::INFINITY),
        }
    };
    let start = rescaled(model, 1.0, 1.0, f64::INFINITY)?.expect("no bound on dt");
    let before = score(model, start, reference, train.clone())?;
    // The error is not unimodal in a stiffness (oscillation phases wrap)
    // and the two scales trade off (bend springs also resist stretching),
    // so: a grid over both log-scales, then Nelder–Mead from the best cell.
    let n = options.grid.max(3);
    let h = 2.0 * options.log_range / (n - 1) as f64;
    let mut start = ([0.0, 0.0], before.mean);
    for i in 0..n {
        for j in 0..n {
            let x = [-options.log_range + h * i as f64, -options.log_range + h * j as f64];
            let f = eval(model, x[0], x[1])?;
            if f < start.1 {
                start = (x, f);
            }
        }
    }
    let mut simplex = [
        start,
        ([start.0[0] + 0.5 * h, start.0[1]], 0.0),
        ([start.0[0], start.0[1] + 0.5 * h], 0.0),
    ];
    for v in simplex.iter_mut().skip(1) {
        v.1 = eval(model, v.0[0], v.0[1])?;
    }
    for _ in 0..options.iterations {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let [best, mid, worst] = simplex;
        let centroid = [(best.0[0] + mid.0[0]) / 2.0, (best.0[1] + mid.0[1]) / 2.0];
        let toward = |t: f64| {
            [
                centroid[0] + t * (worst.0[0] - centroid[0]),
                centroid[1] + t * (worst.0[1] - centroid[1]),
            ]
        };
        let r = toward(-1.0);
        let fr = eval(model, r[0], r[1])?;
        if fr < best.1 {
            let e = toward(-2.0);
            let fe = eval(model, e[0], e[1])?;
            simplex[2] = if fe < fr { (e, fe) } else { (r, fr) };
        } else if fr < mid.1 {
            simplex[2] = (r, fr);
        } else {
            let k = toward(if fr < worst.1 { -0.5 } else { 0.5 });
            let fk = eval(model, k[0], k[1])?;
            if fk < worst.1.min(fr) {
                simplex[2] = (k, fk);
            } else {
                // Shrink towards the best vertex.
                for v in simplex.iter_mut().skip(1) {
                    v.0 = [(v.0[0] + best.0[0]) / 2.0, (v.0[1] + best.0[1]) / 2.0];
                    v.1 = eval(model, v.0[0], v.0[1])?;
                }
            }
        }
        let size = (simplex[1].0[0] - simplex[0].0[0])
            .abs()
            .max((simplex[2].0[1] - simplex[0].0[1]).abs());
        if size < 1e-4 {
            break;
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (ls, lb) = if simplex[0].1 < before.mean {
        (simplex[0].0[0], simplex[0].0[1])
    } else {
        (0.0, 0.0)
    };
    let sim = rescaled(model, ls.exp(), lb.exp(), f64::INFINITY)?.expect("no bound on dt");
    let material = sim.params().material;
    let after = score(model, sim, reference, train)?;
    Ok(SurfaceFit {
        material,
        stretch_scale: ls.exp(),
        bend_scale: lb.exp(),
        before,
        after,
        evaluations,
    })
}

/// A copy of the model's simulation, unchanged, at rest at t = 0.
pub fn restart(model: &PointModel) -> Result<Simulation, SimError> {
    Ok(rescaled(model, 1.0, 1.0, f64::INFINITY)?.expect("no bound on dt"))
}

/// Replace the model's simulation by one with `material`, at rest at t = 0.
pub fn apply_material(model: &mut PointModel, material: Material) -> Result<(), SimError> {
    let s = &model.sim;
    let mut params = *s.params();
    params.material = material;
    let topology = s.topology().clone();
    model.sim = Simulation::new(
        topology.clone(),
        s.masses().to_vec(),
        params,
        s.loads().clone(),
        State::at_rest(&topology),
        StabilityCheck::Enforce,
    )?;
    Ok(())
}
