//! Whose turn it is: how long work (a reference recording, an estimate's
//! runs) gives way to other work. The core only says where it may give
//! way; the caller decides whether it does. The daemon holds its
//! background preparations there while a preparation a client waits for
//! runs (`src/service/turns.rs`), so the client's work gets the cores the
//! stepping threads leave instead of sharing them with the background.
//!
//! Nothing here blocks by itself: with [`Turns::none`] (the default) a
//! checkpoint is one branch on a `None`.

use std::sync::Arc;

/// What a caller does at long work's checkpoints and around its waits for
/// other threads' work.
pub trait Courtesy: Send + Sync {
    /// A point in long work (a metric frame of a run, 1 % of a recording)
    /// where the calling thread may be held. It may hold a preparation's
    /// lock here: a thread that waits for such a lock does so inside
    /// [`Courtesy::waiting`].
    fn checkpoint(&self);

    /// Run `wait`, in which the calling thread waits for another thread's
    /// work (a preparation's lock, a reference being recorded). Work held
    /// at its checkpoints because of the caller's must be let go on
    /// meanwhile, or the two would wait for each other.
    fn waiting(&self, wait: &mut dyn FnMut());
}

/// A shared [`Courtesy`], or none (every checkpoint a no-op).
#[derive(Clone, Default)]
pub struct Turns(Option<Arc<dyn Courtesy>>);

impl std::fmt::Debug for Turns {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "Turns(given)"
        } else {
            "Turns(none)"
        })
    }
}

impl Turns {
    /// Checkpoints that never hold (the default).
    pub fn none() -> Turns {
        Turns(None)
    }

    /// Checkpoints that do what `courtesy` says.
    pub fn new(courtesy: Arc<dyn Courtesy>) -> Turns {
        Turns(Some(courtesy))
    }

    /// See [`Courtesy::checkpoint`].
    #[inline]
    pub fn checkpoint(&self) {
        if let Some(c) = &self.0 {
            c.checkpoint();
        }
    }

    /// `wait()` inside [`Courtesy::waiting`]: its result.
    pub fn waiting<R>(&self, wait: impl FnOnce() -> R) -> R {
        let Some(c) = &self.0 else {
            return wait();
        };
        let mut wait = Some(wait);
        let mut out = None;
        c.waiting(&mut || {
            if let Some(w) = wait.take() {
                out = Some(w());
            }
        });
        match out {
            Some(r) => r,
            // A courtesy that did not run the wait: run it here rather
            // than fail (the trait says it must; this keeps the result).
            None => (wait.take().expect("the wait has not run"))(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[derive(Default)]
    struct Count {
        checkpoints: AtomicUsize,
        waits: AtomicUsize,
    }

    impl Courtesy for Count {
        fn checkpoint(&self) {
            self.checkpoints.fetch_add(1, Ordering::Relaxed);
        }
        fn waiting(&self, wait: &mut dyn FnMut()) {
            self.waits.fetch_add(1, Ordering::Relaxed);
            wait();
        }
    }

    #[test]
    fn a_given_courtesy_sees_every_checkpoint_and_wait_and_the_wait_returns_its_value() {
        let count = Arc::new(Count::default());
        let turns = Turns::new(count.clone());
        turns.checkpoint();
        turns.checkpoint();
        assert_eq!(turns.waiting(|| 7), 7);
        assert_eq!(count.checkpoints.load(Ordering::Relaxed), 2);
        assert_eq!(count.waits.load(Ordering::Relaxed), 1);
        assert_eq!(Turns::none().waiting(|| 3), 3);
    }
}
