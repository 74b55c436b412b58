//! Issue 21: a client's preparation never waits for background work. The
//! daemon runs its background preparation as `SCHED_IDLE`, on cycles
//! nothing else wants, and an unprivileged thread cannot be raised out of
//! that class; so whatever a client needs that a background thread is
//! making must not be waited for. Here the cloth reference
//! (`Preparer::reference_now`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use lodcloth::estimate::Method;
use lodcloth::plan::Level;

use crate::drag::preparer;

/// A background thread (`SCHED_IDLE`) starts recording the reference while
/// every core is busy at normal priority (as the daemon's cores are with
/// stepping and a client's work), so it hardly runs. A client's
/// `reference_now` must record its own copy and return, instead of waiting
/// for it; the background's preparation then ends on the client's copy.
/// With `reference_now` waiting like `Preparer::prepare` does, the client
/// waited here until the timeout (the background recording needed minutes).
#[test]
fn a_client_records_the_reference_instead_of_waiting_for_a_starved_background_recording() {
    let preparer = Arc::new(preparer());
    // How long the reference takes alone, on a fresh preparer.
    let t = Instant::now();
    preparer_alone_reference();
    let alone = t.elapsed();

    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let stop = Arc::new(AtomicBool::new(false));
    let spinners: Vec<_> = (0..cores)
        .map(|_| {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut x = 0u64;
                while !stop.load(Ordering::Relaxed) {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
            })
        })
        .collect();
    let (started_tx, started_rx) = mpsc::channel();
    let background = {
        let preparer = preparer.clone();
        std::thread::spawn(move || {
            let param = libc::sched_param { sched_priority: 0 };
            // SAFETY: sched_setscheduler reads `param` only during the call;
            // pid 0 is the calling thread.
            let idle = unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } == 0;
            started_tx.send(idle).expect("the test waits");
            preparer.prepare(Level::new(8, 8), Method::Same)
        })
    };
    assert!(started_rx.recv().expect("started"), "SCHED_IDLE refused");
    // Let the background take the reference's slot first.
    std::thread::sleep(Duration::from_millis(200));
    let (done_tx, done_rx) = mpsc::channel();
    let client = {
        let preparer = preparer.clone();
        std::thread::spawn(move || {
            let t = Instant::now();
            let r = preparer.reference_now();
            let _ = done_tx.send(t.elapsed());
            r
        })
    };
    let limit = Duration::from_secs(60).max(alone * 20);
    let waited = done_rx.recv_timeout(limit);
    stop.store(true, Ordering::Relaxed);
    for s in spinners {
        s.join().expect("spinner");
    }
    let waited = waited.unwrap_or_else(|_| {
        panic!("the client waited over {limit:?} for the starved background recording (alone it takes {alone:?})")
    });
    client.join().expect("client").expect("the client's reference");
    eprintln!("reference alone {alone:?}; the client's copy beside a starved background recording {waited:?}");
    // The background's preparation ends (its recording stops at its next
    // 1 % once the client's copy is kept) on the client's reference.
    // One reference for every level: the background kept no copy of its own.
    let prepared = background.join().expect("background").expect("the background's level");
    let other = preparer.prepare(Level::new(12, 12), Method::Same).expect("prepared");
    let reference = |p: &lodcloth::plan::Prepared| match &p.basis {
        lodcloth::plan::Basis::Cloth(problem) => problem.reference.clone(),
        _ => panic!("a cloth"),
    };
    assert_eq!(reference(&prepared).frames.len(), 15000 / 25);
    assert!(Arc::ptr_eq(&reference(&prepared), &reference(&other)));
}

/// The reference of a fresh preparer, recorded on this thread.
fn preparer_alone_reference() {
    preparer().reference_now().expect("records");
}
