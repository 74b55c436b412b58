//! `drape`: a level's bending fitted so that it drapes as the reference
//! does (the settled shape's shadow, the Cusick tester's measure).
//!
//! A coarse level of a folding cloth hangs limper than its reference: its
//! bending modes past the softest dozen are softer, so the drape coefficient
//! of the Cusick disc's 40 % level is 15 % below the reference's with
//! `same` (the lab's NOTEBOOK.md, "Stiffening a level mode by mode"). The drape is a
//! static measure: where the cloth comes to rest, not how it gets there, so
//! the estimators that read motion (eq. 9 residuals, forces at samples) do
//! not aim at it. This one does, with one number for one coefficient: the
//! bend class (K and C together, a mesh's bending rigidity and its damping)
//! of the start is scaled by the factor `s` at which the level, draped from
//! rest over the scene's duration, casts the reference's shadow at the end.
//!
//! The shadow is [`crate::drape::shadow_area`] (the union of the
//! triangles' projections along y, gravity's axis in every shipped drape),
//! to pixels of 1/1000 of the reference's rest extent. The reference's is
//! read once per recording, whichever level asks first: its run resumed
//! from the recording's last checkpoint to the scene's end. The level's is
//! a monotone function of `s` in the mean (a stiffer cloth spreads wider)
//! with steps where the folds' count changes, so the factor is found by
//! bracketing in log `s` (×1.5 a run) and then the Illinois variant of
//! regula falsi, which keeps a bracket whatever the steps do. A run that diverges counts as too stiff.
//!
//! One run is one draw of a drape whose folds form where rounding decides
//! (on the Cusick disc the drape coefficient of one mesh spreads by 1–3 %,
//! sd, between runs whose heights differ by a micrometre). A factor fitted
//! to one draw of each matched those draws and left the 40 % level's mean
//! 4.9 % low (results.md, "Fitting the drape"). So every shadow here is the
//! mean over [`DRAPE_TWINS`] runs: the reference's recorded run and its
//! twins from rest, the level's runs from rest, every twin but the first
//! with each height jittered by [`DRAPE_JITTER`] (seeded 1, 2, …, as
//! `drape_scan run --twins` makes them). The twins run in parallel and
//! meet every half second of simulated time to report progress. The
//! factor makes the level's mean shadow the reference's within
//! [`DRAPE_TOLERANCE`]. Pure: no I/O.

use rayon::prelude::*;

use super::{EstimateError, LodProblem, Progress, ProgressFn};
use crate::drape::{jitter_heights, shadow_area};
use crate::sim::{Material, Simulation, SpringKind};

/// The shadow a fit stops at: within this share of the reference's. On the
/// Cusick disc 0.25 % of the shadow is 0.5 % of the drape coefficient.
pub const DRAPE_TOLERANCE: f64 = 2.5e-3;

/// Runs of the level at most (a bracket and its refinement).
pub const DRAPE_RUNS: usize = 12;

/// Factors on the start's bending tried at most (and at least its inverse).
pub const DRAPE_RANGE: f64 = 16.0;

/// Runs per shadow: the first as the scene starts, the others its twins.
pub const DRAPE_TWINS: u64 = 4;

/// A twin's jitter of every height (m): far below anything a tester
/// could set, enough for rounding to pick other folds.
pub const DRAPE_JITTER: f64 = 1e-6;

/// Shadow pixels per the reference's largest rest extent.
const PIXELS_ACROSS: f64 = 1000.0;

/// What a `drape` fit did.
#[derive(Debug, Clone, PartialEq)]
pub struct DrapeReport {
    /// The factor on the start's bend class (K and C).
    pub factor: f64,
    /// The reference's shadow at the scene's end (m²; every shadow here is
    /// a mean over [`DRAPE_TWINS`] runs).
    pub target: f64,
    /// The level's shadow with the factor (m²).
    pub shadow: f64,
    /// The start's shadow (m²).
    pub start_shadow: f64,
    /// Every run: factor and shadow (m²; NaN where it diverged), in order.
    pub runs: Vec<(f64, f64)>,
    /// Whether the shadow came within [`DRAPE_TOLERANCE`] (else the
    /// closest run found within [`DRAPE_RUNS`] and [`DRAPE_RANGE`]).
    pub converged: bool,
}

/// The side of a shadow pixel for `problem`'s cloth (m).
fn pixel(problem: &LodProblem) -> f64 {
    let rest = &problem.reference.rest;
    let n = rest.len() / 3;
    let extent = |d: usize| {
        let c = &rest[d * n..(d + 1) * n];
        c.iter().copied().fold(f64::NEG_INFINITY, f64::max) - c.iter().copied().fold(f64::INFINITY, f64::min)
    };
    extent(0).max(extent(2)).max(extent(1)) / PIXELS_ACROSS
}

/// Simulated seconds between two progress reports of a batch of twins.
const REPORT_EVERY: f64 = 0.5;

/// Progress reports of one batch of twins run to `end`.
fn reports(end: f64) -> u64 {
    (end / REPORT_EVERY).ceil().max(1.0) as u64
}

/// Step `sim` until its clock reaches `until` (within half a step); false
/// when it diverged.
fn step_until(sim: &mut Simulation, until: f64, turns: &crate::turns::Turns) -> bool {
    let dt = sim.params().dt;
    let mut k = 0u64;
    while sim.state().time < until - 0.5 * dt {
        sim.step();
        k += 1;
        if k.is_multiple_of(1000) {
            if sim.diverged() {
                return false;
            }
            turns.checkpoint();
        }
    }
    !sim.diverged()
}

/// Step every twin (None: refused) to `end` in parallel, meeting every
/// [`REPORT_EVERY`] s of simulated time to `report(k)` the k-th of
/// [`reports`]`(end)` (the steps are the same as in one go, and so are
/// the bits); each twin's shadow then, NaN where it diverged or was refused.
fn shadows_at_end(
    sims: &mut [Option<Simulation>],
    end: f64,
    pixel: f64,
    turns: &crate::turns::Turns,
    report: &mut dyn FnMut(u64),
) -> Vec<f64> {
    let n = reports(end);
    for k in 1..=n {
        let until = if k == n { end } else { k as f64 * REPORT_EVERY };
        sims.par_iter_mut().for_each(|twin| {
            if let Some(sim) = twin {
                if !step_until(sim, until, turns) {
                    *twin = None;
                }
            }
        });
        report(k);
    }
    sims.iter()
        .map(|twin| match twin {
            Some(sim) => shadow_area(&sim.topology().triangles, &sim.state().pos, pixel),
            None => f64::NAN,
        })
        .collect()
}

/// The reference's mean shadow at the scene's end: its recording resumed
/// from the last checkpoint (or from rest) and stepped on, and its twins
/// from rest. Read once per recording (and end and pixel): the other
/// levels of the reference take it from there, with one report.
fn reference_shadow(
    problem: &LodProblem,
    end: f64,
    pixel: f64,
    report: &mut dyn FnMut(u64),
) -> Result<f64, EstimateError> {
    if let Some(&(e, p, shadow)) = problem.reference.drape_shadow.get() {
        if e == end && p == pixel {
            report(reports(end));
            return Ok(shadow);
        }
    }
    let sim_error = |source| EstimateError::Sim {
        level: problem.level,
        source,
    };
    let mut sims = (0..DRAPE_TWINS)
        .map(|twin| {
            let mut sim = problem.reference.scene_as_run(&problem.scene).build()?;
            if twin == 0 {
                if let Some(state) = problem.reference.checkpoints.iter().rev().find(|s| s.time <= end) {
                    sim.set_state(state.clone()).map_err(sim_error)?;
                }
            } else {
                jitter_heights(&mut sim, twin, DRAPE_JITTER);
            }
            Ok(Some(sim))
        })
        .collect::<Result<Vec<_>, EstimateError>>()?;
    let shadows = shadows_at_end(&mut sims, end, pixel, problem.turns(), report);
    let shadow = shadows.iter().sum::<f64>() / shadows.len() as f64;
    if !shadow.is_finite() {
        return Err(EstimateError::Drape(format!(
            "the reference diverged before the scene's end ({end} s)"
        )));
    }
    // Another level may have set it meanwhile: the same bits.
    let _ = problem.reference.drape_shadow.set((end, pixel, shadow));
    Ok(shadow)
}

/// The level's mean shadow with `material` at the scene's end over its
/// twins from rest; NaN when a twin diverged or the level is refused.
fn level_shadow(problem: &LodProblem, material: Material, end: f64, pixel: f64, report: &mut dyn FnMut(u64)) -> f64 {
    let mut sims: Vec<Option<Simulation>> = (0..DRAPE_TWINS)
        .map(|twin| {
            problem.simulation(material).ok().map(|mut sim| {
                if twin > 0 {
                    jitter_heights(&mut sim, twin, DRAPE_JITTER);
                }
                sim
            })
        })
        .collect();
    let shadows = shadows_at_end(&mut sims, end, pixel, problem.turns(), report);
    shadows.iter().sum::<f64>() / shadows.len() as f64
}

/// Fit the bend class of `start` so the level drapes to the reference's
/// shadow at the scene's end (module docs).
pub fn drape_fit(
    problem: &LodProblem,
    start: &Material,
    progress: ProgressFn<'_>,
) -> Result<DrapeReport, EstimateError> {
    let end = problem.scene.duration;
    if !(end > 0.0) {
        return Err(EstimateError::Drape("the scene has no duration to drape over".into()));
    }
    if problem.scene.params.gravity[1] >= 0.0
        || problem.scene.params.gravity[0] != 0.0
        || problem.scene.params.gravity[2] != 0.0
    {
        return Err(EstimateError::Drape(
            "the shadow is read along y: the scene's gravity must point down y".into(),
        ));
    }
    let pixel = pixel(problem);
    // Progress in batches' reports: the reference's, then the level runs'.
    let per_run = reports(end);
    let total = (DRAPE_RUNS as u64 + 1) * per_run;
    progress(Progress {
        stage: "drape: reference",
        done: 0,
        total,
    });
    let target = reference_shadow(problem, end, pixel, &mut |k| {
        progress(Progress {
            stage: "drape: reference",
            done: k,
            total,
        })
    })?;
    let mut runs: Vec<(f64, f64)> = Vec::new();
    // The level's shadow against the target, in log: f(s) > 0 is too stiff.
    let run = |s: f64, runs: &mut Vec<(f64, f64)>, progress: &mut dyn FnMut(Progress)| {
        let before = (runs.len() as u64 + 1) * per_run;
        let material = start.kind_scaled(SpringKind::Bend, s, s);
        let shadow = level_shadow(problem, material, end, pixel, &mut |k| {
            progress(Progress {
                stage: "drape: level runs",
                done: before + k,
                total,
            })
        });
        runs.push((s, shadow));
        if shadow.is_finite() && shadow > 0.0 {
            (shadow / target).ln()
        } else {
            f64::INFINITY
        }
    };
    let f0 = run(1.0, &mut runs, progress);
    let start_shadow = runs[0].1;
    if !f0.is_finite() {
        return Err(EstimateError::Drape(
            "the level diverged with the start's coefficients".into(),
        ));
    }
    let tol = (1.0 + DRAPE_TOLERANCE).ln();
    let (mut lo, mut hi) = ((0.0f64, f0), (0.0f64, f0)); // (ln s, f)
    let mut converged = f0.abs() <= tol;
    // Bracket: step ln s by ln 1.5 towards the target until f changes sign.
    if !converged {
        let step = 1.5f64.ln() * if f0 < 0.0 { 1.0 } else { -1.0 };
        let mut x = 0.0;
        loop {
            x += step;
            if x.abs() > DRAPE_RANGE.ln() + 1e-12 || runs.len() >= DRAPE_RUNS {
                break;
            }
            let f = run(x.exp(), &mut runs, progress);
            if f.abs() <= tol {
                converged = true;
                break;
            }
            if (f > 0.0) == (f0 > 0.0) {
                (lo, hi) = ((x, f), (x, f));
                continue;
            }
            (lo, hi) = if f0 < 0.0 {
                ((x - step, lo.1), (x, f))
            } else {
                ((x, f), (x - step, hi.1))
            };
            break;
        }
    }
    // Refine: Illinois on (lo: f < 0, hi: f > 0), a diverged end as +∞.
    if !converged && lo.1 < 0.0 && hi.1 > 0.0 {
        let mut side = 0i8;
        while runs.len() < DRAPE_RUNS {
            let x = if hi.1.is_finite() {
                (lo.0 * hi.1 - hi.0 * lo.1) / (hi.1 - lo.1)
            } else {
                0.5 * (lo.0 + hi.0)
            };
            let f = run(x.exp(), &mut runs, progress);
            if f.abs() <= tol {
                converged = true;
                break;
            }
            if f < 0.0 {
                lo = (x, f);
                if side == -1 {
                    hi.1 *= 0.5;
                }
                side = -1;
            } else {
                hi = (x, f);
                if side == 1 {
                    lo.1 *= 0.5;
                }
                side = 1;
            }
        }
    }
    // The run closest to the target (the last within the tolerance when
    // converged, which is the closest or as close).
    let best = runs
        .iter()
        .copied()
        .filter(|(_, a)| a.is_finite())
        .min_by(|a, b| ((a.1 / target).ln().abs()).total_cmp(&(b.1 / target).ln().abs()))
        .expect("the start's run is finite");
    Ok(DrapeReport {
        factor: best.0,
        target,
        shadow: best.1,
        start_shadow,
        runs,
        converged,
    })
}
