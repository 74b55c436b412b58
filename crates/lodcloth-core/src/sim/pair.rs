//! A second thread for one step, lent by the caller.
//!
//! The core starts no thread. A large cloth's step splits its work into two
//! halves of a fixed shape (see [`Simulation::step_on`](super::Simulation::step_on))
//! and hands them to a [`Pair`], which runs them one after the other
//! ([`Serial`]) or at the same time ([`Lender`], served by a thread the
//! caller owns). The halves are the same whichever runs them, so results are
//! bit-identical with one thread or two.
//!
//! [`Lender`] is the hand-over: the stepping thread posts the second half,
//! runs the first itself, then takes the second back if no helper started
//! it. A busy or descheduled helper therefore never makes a step slower
//! than doing both halves alone; it only helps when it is idle.

use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Mutex;
use std::thread::Thread;
use std::time::{Duration, Instant};

/// Runs two pieces of work, possibly at the same time.
pub trait Pair: Sync {
    /// Run `a` and `b` and return when both have finished. A panic in either
    /// propagates to the caller.
    fn join(&self, a: &mut (dyn FnMut() + Send), b: &mut (dyn FnMut() + Send));
}

/// Both halves on the calling thread, `a` first.
#[derive(Debug, Clone, Copy, Default)]
pub struct Serial;

impl Pair for Serial {
    fn join(&self, a: &mut (dyn FnMut() + Send), b: &mut (dyn FnMut() + Send)) {
        a();
        b();
    }
}

const IDLE: u8 = 0;
const POSTED: u8 = 1;
const RUNNING: u8 = 2;
const DONE: u8 = 3;
const PANICKED: u8 = 4;

/// A [`Pair`] whose second half a helper thread may take: the helper calls
/// [`Lender::help`] whenever it is idle (and is unparked when work is
/// posted, see [`Lender::set_helper`]). One stepping thread joins through a
/// `Lender` at a time; joins through one `Lender` from two threads at once
/// are serialised by a lock.
pub struct Lender {
    state: AtomicU8,
    /// The posted half while `state` is POSTED or RUNNING; a raw pointer
    /// because it borrows from the joining thread's stack, which waits in
    /// [`Pair::join`] until the helper is done with it.
    job: UnsafeCell<Option<*mut (dyn FnMut() + Send)>>,
    helper: Mutex<Option<Thread>>,
    joining: Mutex<()>,
}

// SAFETY: `job` is written only by the joining thread while `state` is IDLE
// (no helper reads it), and read only by the helper that moved `state` from
// POSTED to RUNNING; the joiner does not return from `join`, and so keeps the
// closure alive, until `state` is IDLE again or DONE/PANICKED. The closure is
// `Send`, so running it on the helper is sound.
unsafe impl Sync for Lender {}
unsafe impl Send for Lender {}

impl Default for Lender {
    fn default() -> Lender {
        Lender::new()
    }
}

impl std::fmt::Debug for Lender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Lender")
            .field("state", &self.state.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

impl Lender {
    /// A lender with no helper yet: joins run serially until one is set.
    pub fn new() -> Lender {
        Lender {
            state: AtomicU8::new(IDLE),
            job: UnsafeCell::new(None),
            helper: Mutex::new(None),
            joining: Mutex::new(()),
        }
    }

    /// The thread to unpark when work is posted (the one calling
    /// [`Lender::help`]).
    pub fn set_helper(&self, thread: Thread) {
        *self.helper.lock().unwrap_or_else(|e| e.into_inner()) = Some(thread);
    }

    /// Whether work is waiting for a helper.
    pub fn posted(&self) -> bool {
        self.state.load(Ordering::Acquire) == POSTED
    }

    /// Run the posted half, if any and no one took it yet. Returns whether
    /// this call ran one. Called by the helper thread only.
    pub fn help(&self) -> bool {
        if self
            .state
            .compare_exchange(POSTED, RUNNING, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            return false;
        }
        // SAFETY: see the `Sync` impl: RUNNING gives this thread the job,
        // and the joiner keeps it alive until it sees DONE or PANICKED.
        let job = unsafe { (*self.job.get()).expect("a posted job") };
        let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| unsafe { (*job)() }));
        self.state
            .store(if ran.is_ok() { DONE } else { PANICKED }, Ordering::Release);
        true
    }
}

impl Lender {
    /// [`Lender::help`], then keep watching for the next half for up to
    /// `linger` after each one (never past `deadline`); returns how many
    /// halves ran. The halves of one step follow each other within
    /// microseconds, or after the joiner's longer half, and waking a parked
    /// thread costs tens of microseconds, so a helper lingers a little
    /// rather than parking between halves. (The only clock the core reads:
    /// a bound on a spin-wait, never a pace.)
    pub fn help_lingering(&self, linger: Duration, deadline: Instant) -> usize {
        let mut ran = 0;
        while self.help() {
            ran += 1;
            let end = (Instant::now() + linger).min(deadline);
            while !self.posted() && Instant::now() < end {
                for _ in 0..64 {
                    std::hint::spin_loop();
                }
            }
        }
        ran
    }
}

impl Lender {
    /// Makes the calling thread this lender's helper and runs posted halves
    /// until `stop` is set; returns how many it ran. Between halves it
    /// parks (a join unparks it), so an idle helper costs nothing.
    pub fn serve_until(&self, stop: &std::sync::atomic::AtomicBool) -> usize {
        self.set_helper(std::thread::current());
        let mut ran = 0;
        while !stop.load(Ordering::Acquire) {
            if self.help() {
                ran += 1;
            } else {
                std::thread::park_timeout(Duration::from_millis(1));
            }
        }
        ran
    }
}

impl Pair for Lender {
    fn join(&self, a: &mut (dyn FnMut() + Send), b: &mut (dyn FnMut() + Send)) {
        let helper = self.helper.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let Some(helper) = helper else {
            a();
            b();
            return;
        };
        let _one_joiner = self.joining.lock().unwrap_or_else(|e| e.into_inner());
        // SAFETY: `state` is IDLE (the previous join left it so), so no
        // helper looks at `job`. The lifetime is erased; `join` does not
        // return while a helper may still use the pointer (below).
        let erased: *mut (dyn FnMut() + Send + '_) = b;
        let erased: *mut (dyn FnMut() + Send + 'static) = unsafe { std::mem::transmute(erased) };
        unsafe { *self.job.get() = Some(erased) };
        self.state.store(POSTED, Ordering::Release);
        helper.unpark();
        // If `a` panics, `b` may be running on the helper with borrows from
        // this frame: wait for it before unwinding.
        let ran_a = std::panic::catch_unwind(std::panic::AssertUnwindSafe(&mut *a));
        let helped = match self
            .state
            .compare_exchange(POSTED, IDLE, Ordering::Acquire, Ordering::Acquire)
        {
            Ok(_) => {
                // Not taken: run it here.
                unsafe { *self.job.get() = None };
                if ran_a.is_ok() {
                    b();
                }
                None
            }
            Err(_) => {
                let mut spins = 0u32;
                let end = loop {
                    match self.state.load(Ordering::Acquire) {
                        s @ (DONE | PANICKED) => break s,
                        _ => {
                            spins += 1;
                            if spins < 1 << 12 {
                                std::hint::spin_loop();
                            } else {
                                std::thread::yield_now();
                            }
                        }
                    }
                };
                unsafe { *self.job.get() = None };
                self.state.store(IDLE, Ordering::Release);
                Some(end)
            }
        };
        if let Err(p) = ran_a {
            std::panic::resume_unwind(p);
        }
        if helped == Some(PANICKED) {
            panic!("the helper thread's half of a step panicked");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicBool, AtomicUsize};
    use std::sync::Arc;

    /// A helper thread serving `lender` until `stop`; counts the halves it ran.
    fn serve(lender: Arc<Lender>, stop: Arc<AtomicBool>, ran: Arc<AtomicUsize>) -> std::thread::JoinHandle<()> {
        let ready = Arc::new(AtomicBool::new(false));
        let r = ready.clone();
        let h = std::thread::spawn(move || {
            lender.set_helper(std::thread::current());
            r.store(true, Ordering::Release);
            while !stop.load(Ordering::Acquire) {
                if lender.help() {
                    ran.fetch_add(1, Ordering::Relaxed);
                } else {
                    std::thread::park_timeout(std::time::Duration::from_millis(1));
                }
            }
        });
        while !ready.load(Ordering::Acquire) {
            std::thread::yield_now();
        }
        h
    }

    #[test]
    fn both_halves_run_exactly_once_with_or_without_a_helper() {
        let lender = Arc::new(Lender::new());
        // No helper yet: serial.
        let (mut x, mut y) = (0, 0);
        lender.join(&mut || x += 1, &mut || y += 1);
        assert_eq!((x, y), (1, 1));

        let stop = Arc::new(AtomicBool::new(false));
        let ran = Arc::new(AtomicUsize::new(0));
        let h = serve(lender.clone(), stop.clone(), ran.clone());
        let rounds = 2000;
        let (mut a_count, mut b_count) = (0usize, 0usize);
        let mut data = vec![0u64; 1 << 12];
        for r in 0..rounds {
            let (lo, hi) = data.split_at_mut(1 << 11);
            lender.join(
                &mut || {
                    a_count += 1;
                    lo.iter_mut().for_each(|v| *v += r);
                },
                &mut || {
                    b_count += 1;
                    // Enough work that the helper often takes it.
                    hi.iter_mut().for_each(|v| *v += r);
                    std::hint::black_box(&hi);
                },
            );
        }
        stop.store(true, Ordering::Release);
        h.thread().unpark();
        h.join().expect("helper");
        assert_eq!((a_count, b_count), (rounds as usize, rounds as usize));
        let expected: u64 = (0..rounds).sum();
        assert!(data.iter().all(|&v| v == expected));
        eprintln!("helper ran {} of {rounds} second halves", ran.load(Ordering::Relaxed));
    }

    #[test]
    fn a_panicking_half_on_the_helper_reaches_the_joiner() {
        let lender = Arc::new(Lender::new());
        let stop = Arc::new(AtomicBool::new(false));
        let ran = Arc::new(AtomicUsize::new(0));
        let h = serve(lender.clone(), stop.clone(), ran.clone());
        let mut caught = false;
        // Until the helper is the one that ran (and panicked in) the half.
        for _ in 0..10_000 {
            let before = ran.load(Ordering::Relaxed);
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                lender.join(
                    &mut || std::thread::sleep(std::time::Duration::from_micros(200)),
                    &mut || panic!("half b"),
                )
            }));
            assert!(r.is_err(), "a panicking half must reach the caller");
            if ran.load(Ordering::Relaxed) > before {
                caught = true;
                break;
            }
        }
        stop.store(true, Ordering::Release);
        h.thread().unpark();
        h.join().expect("the helper survives a panicking half");
        assert!(caught, "the helper never took the half");
        // The lender is usable again.
        let (mut x, mut y) = (0, 0);
        lender.join(&mut || x += 1, &mut || y += 1);
        assert_eq!((x, y), (1, 1));
    }
}
