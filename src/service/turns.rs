//! Whose turn it is in the daemon: background preparations (start-up's,
//! refinements, resumes) hold at their checkpoints while a preparation a
//! client waits for runs.
//!
//! Scheduling classes alone did not give a client's work the spare core.
//! Linux balances cores by weight, and the nice-19 client thread weighs
//! almost nothing, so on a 2-core Zen 3 it stayed on the busiest stepping
//! thread's core while the `SCHED_IDLE` background had the other one: a
//! switch's reference was recorded at 420–660 steps/s beside the
//! background's 1,000 (docs/results.md, "Real time during a cold start"). Held here, the
//! background leaves its core idle, and an idle core takes the waiting
//! client thread.
//!
//! The core says where work may be held ([`Courtesy::checkpoint`]: every
//! metric frame of a level's runs, 1 % of a reference recording) and wraps
//! its waits for other threads' work ([`Courtesy::waiting`]): a client
//! waiting there for a level the held background prepares lets it go on
//! meanwhile, so neither waits for the other.

use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

use crate::turns::{Courtesy, Turns};

/// The kind of work a thread does, as [`super::lower_priority`] and
/// [`super::client_priority`] set it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    /// Stepping threads, the runtime's, tests': never held.
    Other,
    /// Held at checkpoints while client work runs.
    Background,
    /// A client waits for it.
    Client,
}

thread_local! {
    static CLASS: Cell<Class> = const { Cell::new(Class::Other) };
}

pub(super) fn mark_background() {
    CLASS.with(|c| c.set(Class::Background));
}

pub(super) fn mark_client() {
    CLASS.with(|c| c.set(Class::Client));
}

fn class() -> Class {
    CLASS.with(Cell::get)
}

/// Client work running now, and a wake-up for held background work.
struct Claims {
    running: Mutex<usize>,
    /// `running`, read without the lock on every checkpoint (written under it).
    fast: AtomicUsize,
    none_left: Condvar,
}

static CLAIMS: Claims = Claims {
    running: Mutex::new(0),
    fast: AtomicUsize::new(0),
    none_left: Condvar::new(),
};

impl Claims {
    fn lock(&self) -> MutexGuard<'_, usize> {
        self.running.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn add(&self) {
        let mut n = self.lock();
        *n += 1;
        self.fast.store(*n, Ordering::Release);
    }

    /// One less, if any; true when one was taken.
    fn take(&self) -> bool {
        let mut n = self.lock();
        if *n == 0 {
            return false;
        }
        *n -= 1;
        self.fast.store(*n, Ordering::Release);
        if *n == 0 {
            self.none_left.notify_all();
        }
        true
    }
}

/// Held while work a client waits for runs: background work holds at its
/// next checkpoint until no such work is left.
pub(super) struct ClientWork(());

/// Count the calling work in until the returned value is dropped.
pub(super) fn client_work() -> ClientWork {
    CLAIMS.add();
    ClientWork(())
}

impl Drop for ClientWork {
    fn drop(&mut self) {
        CLAIMS.take();
    }
}

/// Client work running now (for `/metrics` and tests).
pub(super) fn client_work_running() -> usize {
    CLAIMS.fast.load(Ordering::Acquire)
}

struct Daemon;

impl Courtesy for Daemon {
    fn checkpoint(&self) {
        if CLAIMS.fast.load(Ordering::Acquire) == 0 || class() != Class::Background {
            return;
        }
        let mut n = CLAIMS.lock();
        while *n > 0 {
            n = CLAIMS.none_left.wait(n).unwrap_or_else(|e| e.into_inner());
        }
    }

    fn waiting(&self, wait: &mut dyn FnMut()) {
        if class() != Class::Client {
            return wait();
        }
        // While it waits, this client work is not running: what it waits
        // for may be background work held on its account.
        let released = CLAIMS.take();
        wait();
        if released {
            CLAIMS.add();
        }
    }
}

/// The daemon's checkpoints, for every instance's preparer.
pub(super) fn turns() -> Turns {
    Turns::new(Arc::new(Daemon))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;
    use std::time::{Duration, Instant};

    /// Background work counting its checkpoints until `stop`.
    fn background(turns: Turns, passed: Arc<AtomicUsize>, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
        std::thread::spawn(move || {
            mark_background();
            while !stop.load(Ordering::Relaxed) {
                turns.checkpoint();
                passed.fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(Duration::from_micros(200));
            }
        })
    }

    fn wait_until(what: &str, ok: impl Fn() -> bool) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !ok() {
            assert!(Instant::now() < deadline, "{what}: not within 10 s");
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Background work stops at its checkpoints while a client's runs and
    /// goes on after; a client that waits for the held work inside
    /// `waiting` lets it go on, so the two never wait for each other; work
    /// of no class is never held.
    #[test]
    fn background_holds_while_client_work_runs_and_goes_on_for_a_client_waiting_for_it() {
        let turns = super::turns();
        let passed = Arc::new(AtomicUsize::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let worker = background(turns.clone(), passed.clone(), stop.clone());
        wait_until("background work runs", || passed.load(Ordering::Relaxed) > 10);

        let client = std::thread::spawn({
            let (turns, passed) = (turns.clone(), passed.clone());
            move || {
                mark_client();
                let claim = client_work();
                // Held: at most the pass it was in finishes.
                std::thread::sleep(Duration::from_millis(20));
                let at = passed.load(Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(100));
                let held = passed.load(Ordering::Relaxed) - at;
                // Waiting for the held work lets it go on.
                let before = passed.load(Ordering::Relaxed);
                turns.waiting(|| {
                    wait_until("held work goes on for a waiting client", || {
                        passed.load(Ordering::Relaxed) > before + 10
                    })
                });
                // And after the wait it is held again.
                std::thread::sleep(Duration::from_millis(20));
                let again = passed.load(Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(100));
                let held_again = passed.load(Ordering::Relaxed) - again;
                drop(claim);
                (held, held_again)
            }
        });
        let (held, held_again) = client.join().expect("client thread");
        // At most the one pass it was in when the claim came (were the
        // thread descheduled for the 20 ms between its check and its count).
        assert!(held <= 1, "background passed {held} checkpoints while client work ran");
        assert!(
            held_again <= 1,
            "background passed {held_again} checkpoints after the client's wait"
        );
        let after = passed.load(Ordering::Relaxed);
        wait_until("background goes on once no client work is left", || {
            passed.load(Ordering::Relaxed) > after + 10
        });
        // Threads of no class pass their checkpoints whatever runs.
        let _claim = client_work();
        let mut n = 0;
        for _ in 0..100 {
            turns.checkpoint();
            n += 1;
        }
        assert_eq!(n, 100);
        drop(_claim);
        stop.store(true, Ordering::Relaxed);
        worker.join().expect("background thread");
        assert_eq!(client_work_running(), 0);
    }
}
