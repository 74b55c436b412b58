//! Issue 21: a client's preparation never waits for background work. The
//! daemon runs its background preparation as `SCHED_IDLE`, on cycles
//! nothing else wants, and an unprivileged thread cannot be raised out of
//! that class; so whatever a client needs that a background thread is
//! making must not be waited for. Here the cloth reference
//! (`Preparer::reference_now`).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use lodcloth::estimate::Method;
use lodcloth::plan::{Level, Preparer};
use lodcloth::service::config::ServiceConfig;
use lodcloth::turns::{Courtesy, Turns};

/// Paper scene 1 (top edge pinned, pulled down 1.0–2.5 s) with a 24×24
/// reference over its first 3 s, as the daemon tests run it.
fn preparer() -> Preparer {
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenes/paper-1-top-edge.toml");
    let text = format!(
        r#"
[estimation]
reference_steps = 15000
metric_stride = 25
estimate_stride = 25
precompute = false
[[instances]]
name = "prepare"
scene = "{}"
reference = "24x24"
levels = ["8x8", "12x12", "16x16"]
start = "8x8"
method = "same"
"#,
        scene.display()
    );
    let config = ServiceConfig::from_toml(&text, "prepare test").expect("valid config");
    Preparer::new(Arc::new(config.instances[0].clone()), config.estimation, None)
}

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

/// Held at its checkpoints while `hold` is set; a wait inside `waiting`
/// clears it (what the daemon does for a client that waits for held work).
#[derive(Default)]
struct Gate {
    hold: AtomicBool,
    checkpoints: AtomicUsize,
    held: AtomicUsize,
    waits: AtomicUsize,
}

impl Courtesy for Gate {
    fn checkpoint(&self) {
        self.checkpoints.fetch_add(1, Ordering::Relaxed);
        if self.hold.load(Ordering::Acquire) {
            self.held.fetch_add(1, Ordering::Relaxed);
        }
        while self.hold.load(Ordering::Acquire) {
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    fn waiting(&self, wait: &mut dyn FnMut()) {
        self.waits.fetch_add(1, Ordering::Relaxed);
        self.hold.store(false, Ordering::Release);
        wait();
    }
}

/// Issue 21: a preparer gives way where the daemon may hold background work
/// for a client's: every 1 % of its reference recording and every metric
/// frame of a level's runs. A second preparation of the same level waits
/// for the first inside `waiting`, so work held at a checkpoint while it
/// holds the level's lock is let go on, and neither waits for the other.
/// With the wait for the level's lock outside `waiting` both wait forever
/// (the first held, the second for its lock): the timeout below fails.
#[test]
fn a_preparer_gives_way_at_its_checkpoints_and_lets_held_work_go_on_when_it_waits_for_it() {
    let gate = Arc::new(Gate::default());
    gate.hold.store(true, Ordering::Release);
    let preparer = Arc::new(preparer().with_turns(Turns::new(gate.clone())));
    let level = Level::new(8, 8);
    let first = {
        let preparer = preparer.clone();
        std::thread::spawn(move || preparer.prepare(level, Method::Same))
    };
    // The first is held at its first checkpoint, the level's lock held.
    let deadline = Instant::now() + Duration::from_secs(30);
    while gate.held.load(Ordering::Relaxed) == 0 {
        assert!(Instant::now() < deadline, "the first preparation reached no checkpoint");
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(preparer.get(level, Method::Same).is_none());
    let (tx, rx) = mpsc::channel();
    let second = {
        let preparer = preparer.clone();
        std::thread::spawn(move || {
            let r = preparer.prepare(level, Method::Same);
            let _ = tx.send(());
            r
        })
    };
    let answered = rx.recv_timeout(Duration::from_secs(60));
    gate.hold.store(false, Ordering::Release);
    answered.expect("the second preparation waited for the held first one for 60 s");
    let a = first.join().expect("first").expect("prepared");
    let b = second.join().expect("second").expect("prepared");
    assert!(Arc::ptr_eq(&a, &b), "the second found the first's level");
    assert_eq!(gate.waits.load(Ordering::Relaxed), 1);
    // 1 % ticks of the reference (100) and a frame of every scored run.
    let frames = 15000 / 25;
    let checkpoints = gate.checkpoints.load(Ordering::Relaxed);
    assert!(checkpoints >= 100 + frames, "{checkpoints} checkpoints");
}

/// An instance may serve its levels with another integrator than its
/// scene's, one that is not stable at the scene's dt: the Cusick scene runs
/// RK4 at 1e-4 s, beyond symplectic Euler's limit (6.2e-5 s at its 1,261
/// vertices), and symplectic Euler is what serves its 504-vertex level in
/// real time. The reference is the scene as written (RK4 at 1e-4 s); the
/// level steps symplectic Euler at a dt under its own limit. Until
/// 2026-12-05 the reference ran the instance's integrator at the scene's
/// dt, and every preparation of such an instance failed with the stability
/// error ("dt = 1e-4 s is beyond the predicted stability limit of
/// symplectic_euler").
#[test]
fn an_instance_serves_another_integrator_than_its_reference_runs() {
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenes/cusick-drape.toml");
    let text = format!(
        r#"
[estimation]
reference_steps = 800
metric_stride = 40
estimate_stride = 40
precompute = false
[[instances]]
name = "cusick"
scene = "{}"
levels = ["504v"]
start = "504v"
method = "same"
integrator = "symplectic_euler"
"#,
        scene.display()
    );
    let config = lodcloth::service::config::ServiceConfig::from_toml(&text, "integrator test").expect("valid config");
    let preparer = lodcloth::plan::Preparer::new(Arc::new(config.instances[0].clone()), config.estimation, None);
    let prepared = preparer
        .prepare(Level::Vertices(504), Method::Same)
        .expect("prepared with symplectic Euler");
    let lodcloth::plan::Basis::Cloth(problem) = &prepared.basis else {
        panic!("a cloth level")
    };
    let reference = &problem.reference;
    assert_eq!(
        reference.integrator.name(),
        "rk4",
        "the reference runs the scene's integrator"
    );
    assert_eq!(reference.dt, 1e-4, "at the scene's dt");
    assert_eq!(
        problem.integrator.name(),
        "symplectic_euler",
        "the level the instance's"
    );
    assert!(
        prepared.dt <= prepared.dt_limit && prepared.dt < reference.dt,
        "the level steps under its own limit: dt {} limit {}",
        prepared.dt,
        prepared.dt_limit
    );
    assert!(prepared.predicted_error.is_finite(), "scored against the reference");
    let live = preparer.live_simulation(&prepared).expect("live simulation");
    assert_eq!(live.params().integrator.name(), "symplectic_euler");
}
