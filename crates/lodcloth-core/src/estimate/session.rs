//! A recorded session scored afterwards: a level's states while clients
//! touched it, against the reference replaying the same inputs from rest.
//! The daemon withholds its live error while a cloth is touched (the
//! reference it replays has not seen the inputs); this is that error,
//! computed from a recording.

use crate::lod::{Correlation, LodError};
use crate::scene::{Scene, SceneError};
use crate::touch::{Script, Touch, TouchError};

use super::{ErrorAccumulator, ErrorReport};

/// Why a session could not be scored.
#[derive(Debug, thiserror::Error)]
pub enum SessionScoreError {
    /// No recorded state at or after the first input.
    #[error("no recorded state at or after the first input")]
    NoState,
    /// The scene would not build at the reference's resolution.
    #[error("building the reference: {0}")]
    Scene(#[from] SceneError),
    /// The reference and the level do not correlate.
    #[error("mapping the reference onto the level: {0}")]
    Lod(#[from] LodError),
    /// A recorded state is not of the level's size.
    #[error("the state at t = {time:.4} s has {nodes} nodes, not the {} of {}x{}", .level.0 * .level.1, .level.0, .level.1)]
    Nodes {
        /// Its time (s).
        time: f64,
        /// Its node count.
        nodes: usize,
        /// The level (nx, ny).
        level: (usize, usize),
    },
    /// The reference refused one of the session's inputs.
    #[error("the reference refused an input at t = {time:.4} s: {source}")]
    Refused {
        /// When (s).
        time: f64,
        /// Why.
        source: TouchError,
    },
    /// The reference came out non-finite under the inputs.
    #[error("the touched reference diverged at t = {time:.4} s")]
    Diverged {
        /// When (s).
        time: f64,
    },
    /// The reference did not move, so there is no displacement to normalise by.
    #[error("the touched reference did not move")]
    Still,
}

/// A recorded session (a level's states while clients touched it) scored
/// against the reference replaying the same inputs: the live error the
/// daemon withholds while a cloth is touched, computed afterwards.
#[derive(Debug, Clone)]
pub struct SessionScore {
    /// (simulated time, mean eq. 9 error of the frame) per recorded frame
    /// scored.
    pub frames: Vec<(f64, f64)>,
    /// Over every scored frame and node.
    pub report: ErrorReport,
    /// The touched reference's largest displacement from rest (m).
    pub o_max: f64,
}

/// Score `recorded` states of a `level` (time, SoA positions, in time
/// order, from the episode's start) against the scene at `reference`
/// replaying `script` from rest, from the first input on. `progress` sees
/// the fraction done.
pub fn score_session(
    scene: &Scene,
    reference: (usize, usize),
    level: (usize, usize),
    recorded: &[(f64, Vec<f64>)],
    script: &Script,
    progress: &mut dyn FnMut(f64),
) -> Result<SessionScore, SessionScoreError> {
    let first = script.events().first().map_or(0.0, |e| e.0);
    let scored: Vec<&(f64, Vec<f64>)> = recorded.iter().filter(|(t, _)| *t >= first).collect();
    let last = scored.last().ok_or(SessionScoreError::NoState)?.0;
    let mut sim = scene.build_at(reference.0, reference.1)?;
    let coarse = scene.shape(level.0, level.1);
    let correlation = Correlation::grids(&scene.shape(reference.0, reference.1), &coarse)?;
    let n = level.0 * level.1;
    if let Some((t, p)) = scored.iter().find(|(_, p)| p.len() != 3 * n) {
        return Err(SessionScoreError::Nodes {
            time: *t,
            nodes: p.len() / 3,
            level,
        });
    }
    // The reference under the inputs, mapped onto the level's nodes at
    // each recorded time (nearest step), and its largest displacement.
    let mut touch = Touch::new(scene);
    let mut next = 0;
    let rest = sim.state().pos.clone();
    let nr = sim.topology().n_nodes;
    let dt = sim.params().dt;
    let mut o_max2: f64 = 0.0;
    let mut mapped = Vec::with_capacity(scored.len());
    for (t, _) in &scored {
        while sim.state().time < t - 0.5 * dt {
            script
                .apply_due(&mut next, &mut touch, &mut sim)
                .map_err(|source| SessionScoreError::Refused {
                    time: sim.state().time,
                    source,
                })?;
            if !sim.step().finite {
                return Err(SessionScoreError::Diverged { time: sim.state().time });
            }
            let pos = &sim.state().pos;
            for k in 0..nr {
                o_max2 = o_max2.max(
                    (0..3)
                        .map(|c| (pos[c * nr + k] - rest[c * nr + k]).powi(2))
                        .sum::<f64>(),
                );
            }
        }
        let mut m = vec![0.0; 3 * n];
        correlation.map(&sim.state().pos, &mut m);
        mapped.push(m);
        progress(sim.state().time / last);
    }
    let o_max = o_max2.sqrt();
    if !(o_max > 0.0) {
        return Err(SessionScoreError::Still);
    }
    let mut acc = ErrorAccumulator::new(o_max, n, scored.len());
    let mut frames = Vec::with_capacity(scored.len());
    for ((t, pos), r) in scored.iter().zip(&mapped) {
        let mean = (0..n)
            .map(|k| {
                (0..3)
                    .map(|c| (pos[c * n + k] - r[c * n + k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum::<f64>()
            / n as f64
            / o_max;
        frames.push((*t, mean));
        acc.push(*t, r, pos);
    }
    Ok(SessionScore {
        frames,
        report: acc.report(),
        o_max,
    })
}
