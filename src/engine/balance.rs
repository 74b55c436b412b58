//! Moving instances between stepping threads as their cost changes.
//!
//! [`super::Engine::start`] places instances by what a step costs on their
//! first state. What an instance costs changes while it runs: a cloth with
//! self-contact is certified flat at rest and costs many times more once it
//! folds (paper-2 at 24×24: 0.04 of a core at rest, bursts above one core
//! folded), a switch changes the level, an input drags a cloth into
//! contact. Placement that never changes then leaves an instance that grew
//! sharing a thread it now fills, and every instance there falls behind.
//!
//! So each instance keeps its [`Load`]: the cores of stepping it needed per
//! simulated second, in windows of [`REPORT_EVERY`], as a peak that decays
//! over [`HOLD`] (what matters is whether the thread keeps up in its bursts,
//! not on average). Every [`REPORT_EVERY`] each stepping thread reports the
//! sum of its instances' loads; the most loaded thread hands the least
//! loaded one the instance whose move lowers the larger of their two loads
//! most ([`plan`]), when it lowers it by more than [`MARGIN`]. Only the
//! thread an instance runs on gives it away, between two passes, so an
//! instance is never stepped by two threads; moves are [`COOLDOWN`] apart
//! across the engine, so each one is measured before the next is planned.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};
use std::thread::Thread;
use std::time::{Duration, Instant};

use super::lock;
use super::runner::Runner;

/// How often a stepping thread reports its load, and an instance's load
/// window.
pub(super) const REPORT_EVERY: Duration = Duration::from_millis(500);

/// Time constant (s) over which a load's peak decays: a cloth that folds
/// every episode of a looping scene (paper-2's is 6 s) keeps its peak
/// between folds.
const HOLD: f64 = 20.0;

/// Cores by which a move must lower the larger of the two threads' loads:
/// below it, the move would chase measurement noise.
pub(super) const MARGIN: f64 = 0.02;

/// Least time between two moves in the engine.
const COOLDOWN: Duration = Duration::from_secs(1);

/// One instance's load: cores of stepping per simulated second, the peak
/// of its windows decaying over [`HOLD`].
#[derive(Debug, Clone)]
pub(super) struct Load {
    window_start: Instant,
    busy: Duration,
    sim: f64,
    peak: f64,
}

impl Load {
    /// A load starting at `seed` (the cost measured at placement).
    pub(super) fn new(now: Instant, seed: f64) -> Load {
        Load {
            window_start: now,
            busy: Duration::ZERO,
            sim: 0.0,
            peak: seed,
        }
    }

    /// A pass stepped `sim` simulated seconds in `busy`.
    pub(super) fn count(&mut self, busy: Duration, sim: f64) {
        self.busy += busy;
        self.sim += sim;
    }

    /// The load at `now`, closing the window when it is [`REPORT_EVERY`]
    /// old. A window without steps (paused, held) lets the peak decay.
    pub(super) fn at(&mut self, now: Instant) -> f64 {
        let wall = now.saturating_duration_since(self.window_start);
        if wall >= REPORT_EVERY {
            let rate = if self.sim > 0.0 {
                self.busy.as_secs_f64() / self.sim
            } else {
                0.0
            };
            self.peak = rate.max(self.peak * (-wall.as_secs_f64() / HOLD).exp());
            self.window_start = now;
            self.busy = Duration::ZERO;
            self.sim = 0.0;
        }
        self.peak
    }
}

/// The move that balances: reported by thread `from`, with every thread's
/// load in `loads` and the loads of `from`'s instances in `instances`.
/// `Some((instance, to))` when `from` is the most loaded thread (the
/// lowest index among equals) and moving `instance` to the least loaded
/// thread lowers the larger of the two loads by more than [`MARGIN`]; of
/// such moves, the one that lowers it most.
pub(super) fn plan(loads: &[f64], from: usize, instances: &[f64]) -> Option<(usize, usize)> {
    let most = (0..loads.len()).rev().max_by(|&a, &b| loads[a].total_cmp(&loads[b]))?;
    let least = (0..loads.len()).min_by(|&a, &b| loads[a].total_cmp(&loads[b]))?;
    if most != from || least == from {
        return None;
    }
    let (hi, lo) = (loads[from], loads[least]);
    let (i, after) = instances
        .iter()
        .enumerate()
        .map(|(i, &c)| (i, (hi - c).max(lo + c)))
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    (after < hi - MARGIN).then_some((i, least))
}

/// What the stepping threads share to move instances between them.
pub(super) struct Balance {
    /// Every stepping thread's last reported load, and when the last move was.
    shared: Mutex<(Vec<f64>, Option<Instant>)>,
    /// Instances handed to each thread, not yet taken up.
    inboxes: Vec<Mutex<Vec<Runner>>>,
    arrived: Vec<AtomicBool>,
    /// The stepping threads, to wake one an instance was handed to (set once
    /// they are spawned; no move before).
    threads: OnceLock<Vec<Thread>>,
}

impl Balance {
    /// Between `n` stepping threads, each starting with load `loads[i]`.
    pub(super) fn new(loads: Vec<f64>) -> Balance {
        let n = loads.len();
        Balance {
            shared: Mutex::new((loads, None)),
            inboxes: (0..n).map(|_| Mutex::new(Vec::new())).collect(),
            arrived: (0..n).map(|_| AtomicBool::new(false)).collect(),
            threads: OnceLock::new(),
        }
    }

    pub(super) fn set_threads(&self, threads: Vec<Thread>) {
        // Set once, by the engine's start; a second call would be a bug there.
        let _ = self.threads.set(threads);
    }

    /// Instances handed to thread `i` since it last looked.
    pub(super) fn take(&self, i: usize, runners: &mut Vec<Runner>) {
        if self.arrived[i].swap(false, Ordering::AcqRel) {
            runners.append(&mut lock(&self.inboxes[i]));
        }
    }

    /// Thread `i` reports its instances' loads at `now`, and hands one of
    /// them to another thread when [`plan`] says so.
    pub(super) fn report(&self, i: usize, runners: &mut Vec<Runner>, now: Instant) {
        let Some(threads) = self.threads.get() else {
            return;
        };
        let own: Vec<f64> = runners.iter_mut().map(|r| r.load.at(now)).collect();
        let mut shared = lock(&self.shared);
        let (loads, last_move) = &mut *shared;
        loads[i] = own.iter().sum();
        if last_move.is_some_and(|t| now.saturating_duration_since(t) < COOLDOWN) {
            return;
        }
        let Some((k, to)) = plan(loads, i, &own) else {
            return;
        };
        let runner = runners.swap_remove(k);
        tracing::info!(
            instance = %runner.name,
            from = i,
            to,
            load = format!("{:.2}", own[k]),
            loads = format!("{:.2} -> {:.2}, {:.2} -> {:.2}", loads[i], loads[i] - own[k], loads[to], loads[to] + own[k]),
            "moved to a less loaded stepping thread (cores of stepping per second, measured)"
        );
        loads[i] -= own[k];
        loads[to] += own[k];
        *last_move = Some(now);
        drop(shared);
        runner.home.store(to, Ordering::Release);
        lock(&self.inboxes[to]).push(runner);
        self.arrived[to].store(true, Ordering::Release);
        threads[to].unpark();
    }
}

/// Which stepping thread an instance is on, shared by its runner and its
/// handle (which wakes that thread for a command).
pub(super) type Home = std::sync::Arc<AtomicUsize>;

#[cfg(test)]
mod tests {
    use super::*;

    /// The most loaded thread hands the least loaded one the instance that
    /// balances them best, and nothing moves when no move lowers the larger
    /// load by more than the margin, or when another thread reports.
    #[test]
    fn the_most_loaded_thread_moves_the_instance_that_balances_best() {
        // Thread 0: a folded cloth (1.0) and three light ones; thread 1: 0.43.
        let own = [0.05, 1.0, 0.08, 0.05];
        let loads = [own.iter().sum(), 0.43];
        // Moving 0.08 gives max(1.10, 0.51); the folded cloth max(0.18, 1.43).
        assert_eq!(plan(&loads, 0, &own), Some((2, 1)));
        assert_eq!(plan(&loads, 1, &[0.43]), None, "only the most loaded thread moves");
        // Alone and heavier than the rest together: nothing helps.
        assert_eq!(plan(&[1.0, 0.63], 0, &[1.0]), None);
        // A gain of 0.01 core is noise.
        assert_eq!(plan(&[0.40, 0.38], 0, &[0.39, 0.01]), None);
        assert_eq!(plan(&[0.5], 0, &[0.5]), None, "one thread");
        // Equal loads: the lowest index is the most loaded, another the least.
        assert_eq!(plan(&[0.6, 0.6, 0.1], 0, &[0.3, 0.3]), Some((0, 2)));
        assert_eq!(plan(&[0.6, 0.6, 0.1], 1, &[0.3, 0.3]), None);
    }

    /// A window's load is its busy time per simulated second; a peak decays
    /// over [`HOLD`] and a window without steps brings no new peak.
    #[test]
    fn a_load_keeps_its_peak_and_lets_it_decay() {
        let t0 = Instant::now();
        let mut load = Load::new(t0, 0.1);
        load.count(Duration::from_millis(300), 0.5);
        assert_eq!(
            load.at(t0 + Duration::from_millis(100)),
            0.1,
            "the window is still open"
        );
        let t1 = t0 + REPORT_EVERY;
        assert!((load.at(t1) - 0.6).abs() < 1e-12);
        let t2 = t1 + Duration::from_secs(20);
        let decayed = load.at(t2);
        assert!((decayed - 0.6 * (-1.0f64).exp()).abs() < 1e-12, "{decayed}");
    }
}
