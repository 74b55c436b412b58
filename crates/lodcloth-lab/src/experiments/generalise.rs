//! Generalisation over a suite of scenes (issue 19): every estimator is
//! trained on the first part of each scene's run and scored on the rest
//! (held-out time), and its corrections are carried to scenes it never saw
//! (held-out scenes); both in the long-horizon measure (Sung eq. 9 over a
//! whole run from rest) and the short-horizon one (the level restarted from
//! the reference every window, [`LodProblem::score_windows`]).
//!
//! What carries from one scene to another is not a set of coefficients —
//! the suite's fabrics differ (cotton, canvas, knit) — but the *correction*
//! an estimator applies to the reference's coefficients at a level: the
//! ratio K_level / K_reference and C_level / C_reference per spring type.
//! A held-out scene gets the median of the other scenes' ratios (per
//! coefficient, in log space) applied to its own reference coefficients.
//! The median, not the mean: a fit's correction is sometimes particular to
//! its scene's motion (the shaken curtain's fit cuts shear K five-fold so
//! the coarse cloth folds, the cantilevered canvas cuts its cross-direction
//! K 16-fold), and one such scene would move a mean for every other scene.
//! The median carries what most scenes agree on.
//!
//! The chaos floor ([`twin_floor`]): the reference itself re-run with its
//! coefficients changed by one part in a million, scored like any model.
//! On a scene whose motion is chaotic (a cloth turning about one pin, a
//! flag in gusts) these twins drift from the reference as far as a coarse
//! level does, so a level's long-horizon error near the floor says nothing
//! about its material; the short horizon is the measure there. It is not a
//! strict bound: a model fitted to the first half of a run can stay in
//! phase with the reference for a while longer than an unfitted twin.

use std::ops::Range;
use std::sync::Arc;

use rayon::prelude::*;

use crate::modal::{self, ClampedModes};
use lodcloth_core::estimate::{no_progress, ErrorReport, FitOptions, LodProblem, Method, Reference};
use lodcloth_core::plan::{default_problem, progress_every, stable_problem, Estimator, GridLevel, Level, PlanError};
use lodcloth_core::scene::{MassConvention, Scene};
use lodcloth_core::sim::{Material, SpringCoeffs, SpringKind};

/// The offset of reference draw `draw` in units of the draws'
/// perturbation: 0, +1, −1, +2, −2, … (draw 0 is the scene as written).
pub fn draw_offset(draw: usize) -> f64 {
    let m = draw.div_ceil(2) as f64;
    if draw % 2 == 1 {
        m
    } else {
        -m
    }
}

/// Draw `draw` of `scene`'s reference: every stiffness of its material —
/// a grid's springs, a mesh's membrane moduli and bending rigidity — times
/// `1 + draw_offset(draw) · perturbation`, nothing else changed, and a
/// source hash of its own, so no cache takes one draw's estimates for
/// another's. On a chaotic scene each draw is another outcome of the same
/// fabric (the reference's twins of [`twin_floor`], recorded as references
/// themselves), and a level's short horizon is one sample of it: one
/// recording can land 0.3–1.5 points from another a millionth apart
/// (NOTEBOOK.md, "One recording is one draw of the short horizon").
/// Draw 0 is `scene` itself, hash included.
pub fn reference_draw(scene: &Scene, draw: usize, perturbation: f64) -> Scene {
    let mut s = scene.clone();
    if draw == 0 {
        return s;
    }
    let f = 1.0 + draw_offset(draw) * perturbation;
    for spring in &mut s.params.material.springs {
        spring.k *= f;
    }
    if let Some(mesh) = s.mesh.as_mut() {
        let mesh = Arc::make_mut(mesh);
        let m = &mut mesh.membrane.stiffness;
        for v in [
            &mut m.stretch_u,
            &mut m.stretch_v,
            &mut m.shear,
            &mut m.bend_u,
            &mut m.bend_v,
        ] {
            *v *= f;
        }
        if let Some(b) = mesh.bending.as_mut() {
            b.k *= f;
        }
    }
    s.source_hash = lodcloth_core::hash::fnv1a64(
        &[
            &scene.source_hash.to_le_bytes()[..],
            &(draw as u64).to_le_bytes(),
            &perturbation.to_bits().to_le_bytes(),
        ]
        .concat(),
    );
    s
}

/// A measure over reference draws: mean, sample standard deviation (0 for
/// one draw) and range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// The mean over the draws.
    pub mean: f64,
    /// The sample standard deviation (n − 1), 0 for a single draw.
    pub sd: f64,
    /// The smallest draw.
    pub min: f64,
    /// The largest draw.
    pub max: f64,
    /// How many draws.
    pub n: usize,
}

impl Spread {
    /// The spread of `values`; `None` when there are none.
    pub fn of(values: &[f64]) -> Option<Spread> {
        let n = values.len();
        if n == 0 {
            return None;
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let sd = if n > 1 {
            (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        } else {
            0.0
        };
        Some(Spread {
            mean,
            sd,
            min: values.iter().copied().fold(f64::INFINITY, f64::min),
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            n,
        })
    }
}

/// Options of [`suite`].
#[derive(Debug, Clone)]
pub struct SuiteOptions {
    /// The level, named once for every scene (resolved against each
    /// scene's aspect ratio).
    pub level: GridLevel,
    /// Estimators compared.
    pub methods: Vec<Method>,
    /// The fit's settings; its training window is set per scene to the
    /// first `train_fraction` of the run.
    pub fit: FitOptions,
    /// Fraction of each run estimators train on; the rest is held out.
    pub train_fraction: f64,
    /// Window of the short-horizon measure (s).
    pub short_window: f64,
    /// Relative change of the chaos floor's twins' coefficients
    /// ([`TWIN_PERTURBATION`] by default).
    pub floor_perturbation: f64,
    /// Factors on every estimate's bend class, (stiffness K, damping C),
    /// applied before it is scored: what a bending factor costs held out
    /// ((1, 1): the estimates as they are).
    pub bend_scale: (f64, f64),
    /// Stiffen every level's bending modes in this band (its end cut to
    /// the modes both have) to the reference's
    /// ([`crate::modal::stiffening`], paired by order) before
    /// estimating and scoring; estimates are then never cached (the cache
    /// does not know the level's stencils).
    pub modal: Option<Range<usize>>,
    /// Settle every restart of the short horizon by one backward-Euler
    /// step of this length (s) before it runs
    /// ([`lodcloth_core::lod::settle`]); estimates are unchanged by it but
    /// `follow`'s, which fits the restarts as they are scored.
    pub settle: Option<f64>,
}

/// Held-out statistics of one model on one scene (fractions of O_max).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldOut {
    /// Mean over nodes and held-out frames (long horizon: one run from rest).
    pub mean: f64,
    /// 95th percentile over nodes and held-out frames.
    pub p95: f64,
    /// Mean over the last quarter of the held-out frames.
    pub last_quarter: f64,
    /// Mean over the held-out frames, restarted from the reference every
    /// short window (short horizon).
    pub short_mean: f64,
    /// 95th percentile of the short-horizon errors.
    pub short_p95: f64,
}

/// The chaos floor of one scene ([`twin_floor`]), fractions of O_max over
/// the held-out frames, long horizon, averaged over the twins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Floor {
    /// Mean over nodes and held-out frames.
    pub mean: f64,
    /// 95th percentile over nodes and held-out frames.
    pub p95: f64,
    /// Mean over the last quarter of the held-out frames.
    pub last_quarter: f64,
    /// The smallest of the twins' means.
    pub min: f64,
    /// The largest of the twins' means.
    pub max: f64,
}

/// The default relative change of the chaos floor's twins' coefficients:
/// far below any estimate's change and any level's discretisation error.
pub const TWIN_PERTURBATION: f64 = 1e-6;

/// One scene × estimator of the suite.
#[derive(Debug, Clone)]
pub struct SuiteRow {
    /// The scene's name.
    pub scene: String,
    /// The level on this scene (a grid, or a mesh's vertex count).
    pub level: Level,
    /// 1 − level nodes / reference nodes.
    pub reduction: f64,
    /// The estimator.
    pub method: Method,
    /// Coefficients estimated on this scene's training window.
    pub material: Material,
    /// Wall seconds of that estimate (0 when cached).
    pub estimate_seconds: f64,
    /// One line on the estimate (`plan::notes`): for `fit` and `shape`
    /// where it started and whether its guard kept the start (and why);
    /// "cached (…)" when it was read from the cache.
    pub notes: String,
    /// Its score on this scene's held-out frames.
    pub own: HeldOut,
    /// The other scenes' corrections applied to this scene's reference
    /// coefficients, scored on the same frames; `None` for a lone scene.
    pub transferred: Option<HeldOut>,
    /// The scene's chaos floor on the same frames (the same for every
    /// method of the scene).
    pub floor: Floor,
}

/// Run the suite: `scenes` with their recorded references.
pub fn suite(
    scenes: &[(Scene, Arc<Reference>)],
    options: &SuiteOptions,
    estimator: &Estimator,
    log: &mut dyn FnMut(String),
) -> Result<Vec<SuiteRow>, PlanError> {
    if !(options.floor_perturbation >= 0.0 && options.floor_perturbation < 0.5) {
        return Err(PlanError::Invalid(format!(
            "the chaos floor's perturbation must be in [0, 0.5), got {}",
            options.floor_perturbation
        )));
    }
    if let Some(h) = options.settle.filter(|h| !(h.is_finite() && *h > 0.0)) {
        return Err(PlanError::Invalid(format!(
            "the settling step must be a positive, finite time (s), got {h}"
        )));
    }
    if !(options.train_fraction > 0.0 && options.train_fraction < 1.0) {
        return Err(PlanError::Invalid(format!(
            "the training fraction must be in (0, 1), got {}",
            options.train_fraction
        )));
    }
    let (bend_k, bend_c) = options.bend_scale;
    if !(bend_k.is_finite() && bend_k > 0.0 && bend_c.is_finite() && bend_c > 0.0) {
        return Err(PlanError::Invalid(format!(
            "the bend class's scales must be finite and positive, got K ×{bend_k}, C ×{bend_c}"
        )));
    }
    let mut problems = Vec::with_capacity(scenes.len());
    for (scene, reference) in scenes {
        let level = options
            .level
            .on(
                scene.width,
                scene.height,
                scene.mesh.as_ref().map(|m| m.reference.vertices()),
            )
            .map_err(|e| PlanError::Invalid(format!("{}: {e}", scene.name)))?;
        let problem = default_problem(scene, reference, level)?;
        problems.push(match &options.modal {
            Some(band) => stiffened(&problem, band.clone())?,
            None => problem,
        });
    }
    let uncached;
    let estimator = if options.modal.is_some() {
        uncached = Estimator {
            cache: None,
            tag: estimator.tag.clone(),
        };
        &uncached
    } else {
        estimator
    };
    // The problems the estimates are scored on: the same, their
    // restarts settled when asked.
    let scoring: Vec<LodProblem> = problems
        .iter()
        .map(|p| match options.settle {
            Some(h) => p.clone().with_settling(h),
            None => p.clone(),
        })
        .collect();
    // Every scene's own estimate, per method.
    let mut rows = Vec::new();
    for (p, scored) in problems.iter().zip(&scoring) {
        let frames = p.frames();
        let train_end = train_end(frames, options.train_fraction);
        let eps = options.floor_perturbation;
        let floor = twin_floor(&p.scene, &p.reference, train_end..frames, eps)?;
        log(format!(
            "{} chaos floor (three twins of the reference, coefficients × (1 ± {eps:e})): held-out mean {:.2}% ({:.2}–{:.2}%)  p95 {:.2}%  last quarter {:.2}%",
            p.scene.name,
            100.0 * floor.mean,
            100.0 * floor.min,
            100.0 * floor.max,
            100.0 * floor.p95,
            100.0 * floor.last_quarter
        ));
        let fit = FitOptions {
            train: Some(0..train_end),
            ..options.fit.clone()
        };
        for &method in &options.methods {
            // `follow` fits the restarts as they are scored: settled when
            // they are.
            let estimating = if method == Method::Follow { scored } else { p };
            let mut est = {
                let name = &p.scene.name;
                let mut progress = progress_every(10.0, |q| {
                    log(format!("{name} {method}: {} {}/{}", q.stage, q.done, q.total))
                });
                estimator.estimate_reporting(estimating, method, &fit, &mut progress)?
            };
            if let Some(band) = &options.modal {
                let end = if band.end == usize::MAX {
                    String::new()
                } else {
                    band.end.to_string()
                };
                let stiffened = format!("bending modes {}..{end} stiffened to the reference's", band.start);
                est.notes = if est.notes.is_empty() {
                    stiffened
                } else {
                    format!("{}; {stiffened}", est.notes)
                };
            }
            if options.bend_scale != (1.0, 1.0) {
                est.material = est
                    .material
                    .kind_scaled(SpringKind::Bend, options.bend_scale.0, options.bend_scale.1);
                let scaled = format!("bend class K ×{bend_k}, C ×{bend_c}");
                est.notes = if est.notes.is_empty() {
                    scaled
                } else {
                    format!("{}; {scaled}", est.notes)
                };
            }
            if let Some(h) = options.settle {
                let settled = format!("restarts settled by a backward-Euler step of {h} s");
                est.notes = if est.notes.is_empty() {
                    settled
                } else {
                    format!("{}; {settled}", est.notes)
                };
            }
            let own = held_out(scored, est.material, train_end, options.short_window)?;
            log(format!(
                "{} {} {:<4} held-out mean {:.2}%  p95 {:.2}%  last quarter {:.2}%  short horizon {:.2}%  est {:.0} s{}",
                p.scene.name,
                p.level,
                method,
                100.0 * own.mean,
                100.0 * own.p95,
                100.0 * own.last_quarter,
                100.0 * own.short_mean,
                est.seconds,
                if est.notes.is_empty() {
                    String::new()
                } else {
                    format!("  ({})", est.notes)
                }
            ));
            rows.push(SuiteRow {
                scene: p.scene.name.clone(),
                level: p.level,
                reduction: 1.0 - p.topology().n_nodes as f64 / p.reference.topology.n_nodes as f64,
                method,
                material: est.material,
                estimate_seconds: est.seconds,
                notes: est.notes,
                own,
                transferred: None,
                floor,
            });
        }
    }
    // Held-out scenes: each scene with the others' corrections.
    if problems.len() > 1 {
        for (b, p) in problems.iter().enumerate() {
            let frames = p.frames();
            let train_end = train_end(frames, options.train_fraction);
            for &method in &options.methods {
                // Rows are in scene-major order: row i is scene i / m.
                let m = options.methods.len();
                let others: Vec<(Material, Material)> = rows
                    .iter()
                    .enumerate()
                    .filter(|(i, r)| r.method == method && i / m != b)
                    .map(|(i, r)| (r.material, problems[i / m].same_material()))
                    .collect();
                let material = corrected(p.same_material(), &others);
                let score = held_out(&scoring[b], material, train_end, options.short_window)?;
                log(format!(
                    "{} {:<4} from the other scenes: held-out mean {:.2}%, short horizon {:.2}%",
                    p.scene.name,
                    method,
                    100.0 * score.mean,
                    100.0 * score.short_mean
                ));
                if let Some(row) = rows[b * m..(b + 1) * m].iter_mut().find(|r| r.method == method) {
                    row.transferred = Some(score);
                }
            }
        }
    }
    Ok(rows)
}

/// The first held-out frame when the first `fraction` of `frames` trains
/// (at least one frame on each side).
fn train_end(frames: usize, fraction: f64) -> usize {
    ((frames as f64 * fraction).round() as usize).clamp(1, frames - 1)
}

/// `base` scaled per spring type and coefficient by the median of
/// `estimated / reference` over `pairs` (`base` itself when there are none;
/// the geometric mean of the middle two for an even count). A zero
/// coefficient on either side carries no ratio.
fn corrected(base: Material, pairs: &[(Material, Material)]) -> Material {
    let ratio = |f: &dyn Fn(&Material, usize) -> f64, t: usize| -> f64 {
        let mut logs: Vec<f64> = pairs
            .iter()
            .map(|(e, r)| (f(e, t), f(r, t)))
            .filter(|&(e, r)| e > 0.0 && r > 0.0)
            .map(|(e, r)| (e / r).ln())
            .collect();
        logs.sort_by(f64::total_cmp);
        match logs.len() {
            0 => 1.0,
            n if n % 2 == 1 => logs[n / 2].exp(),
            n => (0.5 * (logs[n / 2 - 1] + logs[n / 2])).exp(),
        }
    };
    let k = |m: &Material, t: usize| m.springs[t].k;
    let c = |m: &Material, t: usize| m.springs[t].c;
    Material {
        springs: std::array::from_fn(|t| SpringCoeffs {
            k: base.springs[t].k * ratio(&k, t),
            c: base.springs[t].c * ratio(&c, t),
        }),
    }
}

/// The chaos floor: `reference` re-run at its own resolution, integrator,
/// dt and masses as three twins — every stiffness × (1 ± `perturbation`),
/// every damping × (1 + `perturbation`) — each scored against the
/// recording on `frames` (long horizon); their average, and the spread of
/// their means. One twin is one draw of a chaotic outcome (on paper scene
/// 2 two draws can land seconds apart in phase), hence three. With no
/// perturbation every twin reproduces the recording to its f32 storage.
pub fn twin_floor(
    scene: &Scene,
    reference: &Arc<Reference>,
    frames: Range<usize>,
    perturbation: f64,
) -> Result<Floor, PlanError> {
    // The reference itself (a grid's own resolution, or every vertex).
    let twin = LodProblem::at(
        scene,
        reference.clone(),
        scene.reference_level(),
        MassConvention::Lumped,
        reference.integrator,
        reference.dt,
    )?;
    let twins: [(f64, f64); 3] = [(perturbation, 0.0), (-perturbation, 0.0), (0.0, perturbation)];
    let reports: Vec<ErrorReport> = twins
        .par_iter()
        .map(|&(dk, dc)| {
            let mut material = reference.material;
            for s in &mut material.springs {
                s.k *= 1.0 + dk;
                s.c *= 1.0 + dc;
            }
            twin.score(material, frames.clone(), &mut no_progress)
        })
        .collect::<Result<_, _>>()?;
    let avg = |f: fn(&ErrorReport) -> f64| reports.iter().map(f).sum::<f64>() / reports.len() as f64;
    let means = reports.iter().map(|r| r.mean);
    Ok(Floor {
        mean: avg(|r| r.mean),
        p95: avg(|r| r.p95),
        last_quarter: avg(|r| r.last_quarter),
        min: means.clone().fold(f64::INFINITY, f64::min),
        max: means.fold(0.0, f64::max),
    })
}

/// `material` on `problem`'s held-out frames (from `train_end`), long and
/// short horizon, at a dt the model is stable at.
fn held_out(
    problem: &LodProblem,
    material: Material,
    train_end: usize,
    short_window: f64,
) -> Result<HeldOut, PlanError> {
    let (p, _) = stable_problem(problem, material)?;
    let frames = p.frames();
    let interval = p.reference.dt * p.reference.spec.metric_stride as f64;
    let window = ((short_window / interval).round() as usize).max(1);
    let long: ErrorReport = p.score(material, train_end..frames, &mut no_progress)?;
    let short = p.score_windows(material, train_end..frames, window, &mut no_progress)?;
    Ok(HeldOut {
        mean: long.mean,
        p95: long.p95,
        last_quarter: long.last_quarter,
        short_mean: short.mean,
        short_p95: short.p95,
    })
}

/// A band of modes as the command line writes it: `FIRST..END`, or
/// `FIRST..` for every mode from FIRST on (END `usize::MAX`, cut to the
/// modes there are where it is used).
pub fn parse_band(s: &str) -> Result<Range<usize>, String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("{s:?} is not a band FIRST..END or FIRST.."))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|e| format!("{v:?} in {s:?} is not a mode number: {e}"))
    };
    let (a, b) = (parse(a)?, if b.is_empty() { usize::MAX } else { parse(b)? });
    if a >= b {
        return Err(format!("the band {s:?} is empty: FIRST must be below END"));
    }
    Ok(a..b)
}

/// `problem` with its bending modes in `band` stiffened to its
/// reference's ([`modal::stiffening`]: both clamped spectra, dense).
fn stiffened(problem: &LodProblem, band: Range<usize>) -> Result<LodProblem, PlanError> {
    let invalid =
        |e: &dyn std::fmt::Display| PlanError::Invalid(format!("{} {}: {e}", problem.scene.name, problem.level));
    let reference = &problem.reference.topology;
    let topology = problem.topology();
    let held = problem.scene.loads(reference).map_err(|e| invalid(&e))?;
    let reference_pinned = modal::pinned_flags(reference.n_nodes, held.pins.iter().map(|p| p.node));
    let pinned = modal::pinned_flags(topology.n_nodes, problem.loads().pins.iter().map(|p| p.node));
    let modes = ClampedModes::of(topology, &pinned, "level").map_err(|e| invalid(&e))?;
    let target = ClampedModes::of(reference, &reference_pinned, "reference").map_err(|e| invalid(&e))?;
    let rows = modal::stiffening(topology, &pinned, &modes, &target, band).map_err(|e| invalid(&e))?;
    Ok(problem.with_bending(&rows))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material(k: [f64; 3], c: [f64; 3]) -> Material {
        Material::isotropic([0, 1, 2].map(|t| SpringCoeffs { k: k[t], c: c[t] }))
    }

    #[test]
    fn a_spread_is_the_mean_sample_sd_and_range() {
        let s = Spread::of(&[1.0, 2.0, 3.0, 4.0]).expect("four values");
        assert_eq!((s.mean, s.min, s.max, s.n), (2.5, 1.0, 4.0, 4));
        assert!((s.sd - (5.0f64 / 3.0).sqrt()).abs() < 1e-15, "{}", s.sd);
        let one = Spread::of(&[0.03]).expect("one value");
        assert_eq!((one.mean, one.sd, one.min, one.max), (0.03, 0.0, 0.03, 0.03));
        assert_eq!(Spread::of(&[]), None);
    }

    #[test]
    fn a_band_reads_as_written_and_an_empty_one_is_refused() {
        assert_eq!(parse_band("12..50"), Ok(12..50));
        assert_eq!(parse_band("12.."), Ok(12..usize::MAX));
        for bad in ["50..12", "7..7", "12", "..5", "a..b", "1..-2"] {
            let e = parse_band(bad).expect_err(bad);
            assert!(e.contains(bad), "{bad}: {e}");
        }
    }

    #[test]
    fn corrections_carry_as_median_ratios() {
        let reference_a = material([400.0, 60.0, 8.0], [0.04, 0.006, 0.0008]);
        let reference_b = material([2000.0, 600.0, 200.0], [0.2, 0.06, 0.02]);
        // Scene a's estimator doubled every K and halved every C; scene b's
        // multiplied K by 8 and C by 2: the geometric means are 4 and 1.
        let est_a = material([800.0, 120.0, 16.0], [0.02, 0.003, 0.0004]);
        let est_b = material([16000.0, 4800.0, 1600.0], [0.4, 0.12, 0.04]);
        let base = material([40.0, 6.0, 0.8], [0.004, 0.0006, 0.00008]);
        let m = corrected(base, &[(est_a, reference_a), (est_b, reference_b)]);
        for t in 0..5 {
            assert!((m.springs[t].k / base.springs[t].k - 4.0).abs() < 1e-12);
            assert!((m.springs[t].c / base.springs[t].c - 1.0).abs() < 1e-12);
        }
        assert_eq!(corrected(base, &[]), base);
        // A third scene that multiplied every K by 1000 is an outlier: the
        // median of (2, 8, 1000) is 8, where the mean would be 20.
        let est_c = material([400_000.0, 60_000.0, 8000.0], [0.04, 0.006, 0.0008]);
        let m = corrected(
            base,
            &[(est_a, reference_a), (est_b, reference_b), (est_c, reference_a)],
        );
        for t in 0..5 {
            assert!((m.springs[t].k / base.springs[t].k - 8.0).abs() < 1e-9);
            assert!((m.springs[t].c / base.springs[t].c - 1.0).abs() < 1e-12);
        }
    }
}
