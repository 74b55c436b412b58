//! Recording the fine reference run (MSS_ref) once, for every level and
//! method that is estimated or scored against it.
//!
//! A "frame" is one reference step, as in the paper (20,000 frames of RK4).
//! Storing every frame of a 64×64 cloth would take ~1 GB, so two sparse
//! samplings are kept:
//!
//! - **metric frames** every `metric_stride` steps: fine positions as `f32`
//!   (1e-7 m resolution on a 1 m cloth, far below any error we report), used to
//!   score coarse runs;
//! - **estimation samples** every `estimate_stride` steps: the fine positions
//!   at steps n−s, n, n+s in `f64` (s = `difference_span`, 1 by default), from which velocities and accelerations
//!   follow by finite differences (the paper's inverse procedure uses
//!   consecutive positions). f64 matters here: the second difference at
//!   dt = 2e-4 s cancels ~7 digits.
//!
//! Averages over evenly spaced samples estimate the all-frames averages of the
//! paper without bias. `O_max` is measured at every step.
//!
//! Whole states (positions and velocities, f64) are kept every
//! [`CHECKPOINT_SECONDS`] of simulated time, so a replay of the reference
//! under a touched episode's inputs ([`super::ReplayedReference`]) starts
//! from the last one before the first input instead of from rest: the same
//! steps, so the same bits, without re-running the untouched part.

use std::sync::{Arc, OnceLock};

use crate::sim::{Integrator, Material, Simulation, State, Topology};

/// Simulated seconds between two whole states kept by
/// [`Reference::record`]: a replay starts at most this far before its
/// first input. A 64×64 reference keeps 197 KB per checkpoint, 2 MB per
/// simulated second, against 6 MB of metric frames and 37 MB of estimation
/// samples at the daemon's default strides (40 and 40 steps at 2×10⁻⁴ s).
pub const CHECKPOINT_SECONDS: f64 = 0.1;

/// How to record a reference run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordSpec {
    /// Reference steps to run ("frames").
    pub frames: u64,
    /// Keep positions every this many steps for scoring.
    pub metric_stride: u64,
    /// Keep an estimation sample every this many steps.
    pub estimate_stride: u64,
    /// Steps between the three positions of a sample (1: consecutive steps,
    /// as in the paper). Larger spans difference over a longer time and so
    /// filter out vibrations faster than the coarse cloth can represent.
    pub difference_span: u64,
}

impl RecordSpec {
    /// The paper's 20,000 frames, 2,000 metric frames, 500 estimation samples.
    pub const PAPER: RecordSpec = RecordSpec {
        frames: 20_000,
        metric_stride: 10,
        estimate_stride: 40,
        difference_span: 1,
    };
}

/// Positions of three consecutive reference steps around a sample.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Time of the middle step (s).
    pub time: f64,
    /// Positions at steps n−s, n, n+s (SoA, f64), s = the difference span.
    pub prev: Vec<f64>,
    /// Positions at step n.
    pub cur: Vec<f64>,
    /// Positions at step n+s.
    pub next: Vec<f64>,
}

/// A recorded reference run. See the module docs.
#[derive(Debug, Clone)]
pub struct Reference {
    /// The reference cloth.
    pub topology: Arc<Topology>,
    /// Node masses of the reference (kg).
    pub masses: Vec<f64>,
    /// Coefficients the reference ran with.
    pub material: Material,
    /// Reference integrator and step.
    pub integrator: Integrator,
    /// The reference's time step (s).
    pub dt: f64,
    /// What was recorded and how often.
    pub spec: RecordSpec,
    /// Metric frames: `frame_times[f]` and positions `frames[f]` (SoA, f32).
    pub frame_times: Vec<f64>,
    /// The step count of each metric frame.
    pub frame_steps: Vec<u64>,
    /// Positions of each metric frame.
    pub frames: Vec<Vec<f32>>,
    /// Estimation samples.
    pub samples: Vec<Sample>,
    /// Largest distance of any node from its rest position over the run (m).
    pub o_max: f64,
    /// Rest positions (SoA).
    pub rest: Vec<f64>,
    /// Whole states every [`CHECKPOINT_SECONDS`] (in time order), to
    /// resume the run from.
    pub checkpoints: Vec<State>,
    /// The `drape` fit's reading of this recording, `(end, pixel, shadow)`:
    /// its mean shadow at a scene's end over its twins (`super::shadow`),
    /// minutes of runs that every level of the reference would repeat.
    pub(crate) drape_shadow: OnceLock<(f64, f64, f64)>,
}

/// Why a reference could not be recorded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReferenceError {
    /// A position or velocity became non-finite.
    #[error("the reference diverged at step {step} (t = {time:.4} s); lower its dt or check its coefficients")]
    Diverged {
        /// The step.
        step: u64,
        /// Its time (s).
        time: f64,
    },
    /// Stopped by its caller before the end.
    #[error("the reference was stopped at step {step}")]
    Stopped {
        /// The last step taken.
        step: u64,
    },
    /// No node moved from rest.
    #[error("the reference never moved from its rest shape (O_max = {o_max}); the relative error is undefined")]
    NoMotion {
        /// The largest displacement (m).
        o_max: f64,
    },
    /// The record spec is inconsistent (says which field).
    #[error("invalid record spec: {0}")]
    Spec(&'static str),
}

impl Reference {
    /// `scene` as this reference ran it: with its integrator and step. A
    /// level may be served with another integrator than the scene's (the
    /// daemon's `integrator`), one that need not be stable at the scene's
    /// step; every run of the reference (resumed, replayed, jittered,
    /// touched) is built from this, not from the level's scene.
    pub fn scene_as_run(&self, scene: &crate::scene::Scene) -> crate::scene::Scene {
        let mut scene = scene.clone();
        scene.params.integrator = self.integrator;
        scene.params.dt = self.dt;
        scene
    }

    /// Run `sim` (at rest, t = 0) for `spec.frames` steps and record it.
    /// `progress(done, total)` is called every 1 % of the run.
    pub fn record(
        sim: Simulation,
        spec: RecordSpec,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<Reference, ReferenceError> {
        Self::record_while(sim, spec, progress, &|| true)
    }

    /// [`Reference::record`], asking `keep_going` every 1 % of the run and
    /// stopping ([`ReferenceError::Stopped`]) when it says no: a recording
    /// that someone else's copy has made useless.
    pub fn record_while(
        mut sim: Simulation,
        spec: RecordSpec,
        progress: &mut dyn FnMut(u64, u64),
        keep_going: &dyn Fn() -> bool,
    ) -> Result<Reference, ReferenceError> {
        if spec.frames < 3 {
            return Err(ReferenceError::Spec("frames must be at least 3"));
        }
        if spec.metric_stride == 0 || spec.difference_span == 0 || spec.estimate_stride < 2 * spec.difference_span {
            return Err(ReferenceError::Spec(
                "metric_stride and difference_span must be ≥ 1 and estimate_stride ≥ 2 × difference_span",
            ));
        }
        let topology = sim.topology().clone();
        let n = topology.n_nodes;
        let rest = sim.state().pos.clone();
        let mut frames = Vec::with_capacity((spec.frames / spec.metric_stride) as usize);
        let mut frame_times = Vec::with_capacity(frames.capacity());
        let mut frame_steps = Vec::with_capacity(frames.capacity());
        let mut samples = Vec::with_capacity((spec.frames / spec.estimate_stride) as usize);
        // Positions at the step before the next sample centre.
        let mut prev: Vec<f64> = Vec::new();
        let mut pending: Option<Sample> = None;
        let mut o_max2: f64 = 0.0;
        let tick = (spec.frames / 100).max(1);
        let checkpoint_stride = ((CHECKPOINT_SECONDS / sim.params().dt).round() as u64).max(1);
        let mut checkpoints = Vec::with_capacity((spec.frames / checkpoint_stride) as usize);
        for step in 1..=spec.frames {
            let report = sim.step();
            if !report.finite {
                return Err(ReferenceError::Diverged {
                    step,
                    time: sim.state().time,
                });
            }
            let pos = &sim.state().pos;
            for k in 0..n {
                let d2 = (0..3).map(|c| (pos[c * n + k] - rest[c * n + k]).powi(2)).sum::<f64>();
                o_max2 = o_max2.max(d2);
            }
            // Sample centres are the multiples of `estimate_stride` ≥ 2·span,
            // so a sample is completed before the next one needs its `prev`.
            let span = spec.difference_span;
            if step >= span && (step - span).is_multiple_of(spec.estimate_stride) {
                if let Some(mut s) = pending.take() {
                    s.next = pos.clone();
                    samples.push(s);
                }
            }
            if step % spec.estimate_stride == 0 && step + span <= spec.frames {
                pending = Some(Sample {
                    time: sim.state().time,
                    prev: std::mem::take(&mut prev),
                    cur: pos.clone(),
                    next: Vec::new(),
                });
            }
            if (step + span).is_multiple_of(spec.estimate_stride) {
                prev = pos.clone();
            }
            if step % spec.metric_stride == 0 {
                frames.push(pos.iter().map(|&x| x as f32).collect());
                frame_times.push(sim.state().time);
                frame_steps.push(step);
            }
            if step % checkpoint_stride == 0 {
                checkpoints.push(sim.state().clone());
            }
            if step % tick == 0 {
                progress(step, spec.frames);
                if !keep_going() {
                    return Err(ReferenceError::Stopped { step });
                }
            }
        }
        let o_max = o_max2.sqrt();
        if !(o_max > 1e-12) {
            return Err(ReferenceError::NoMotion { o_max });
        }
        let params = *sim.params();
        Ok(Reference {
            masses: sim.masses().to_vec(),
            topology,
            material: params.material,
            integrator: params.integrator,
            dt: params.dt,
            spec,
            frame_times,
            frame_steps,
            frames,
            samples,
            o_max,
            rest,
            checkpoints,
            drape_shadow: OnceLock::new(),
        })
    }

    /// The latest checkpoint a run may resume from to reach simulated time
    /// `t` exactly as from rest (its time at most half a step past `t`).
    pub fn checkpoint_before(&self, t: f64) -> Option<&State> {
        let last = self.checkpoints.partition_point(|s| s.time < t + 0.5 * self.dt);
        last.checked_sub(1).map(|k| &self.checkpoints[k])
    }

    /// Bytes held by the recorded frames, samples and checkpoints.
    pub fn memory_bytes(&self) -> usize {
        self.frames.iter().map(|f| 4 * f.len()).sum::<usize>()
            + self
                .checkpoints
                .iter()
                .map(|s| 8 * (s.pos.len() + s.vel.len()))
                .sum::<usize>()
            + self
                .samples
                .iter()
                .map(|s| 8 * (s.prev.len() + s.cur.len() + s.next.len()))
                .sum::<usize>()
    }
}
