//! What self-contact costs a step: the hanging cloth (config/scenes/
//! hanging.toml) with its bottom-left corner dragged up and across in
//! front of it and back through it (a grab, as a client's drag is), with
//! self-contact on, until it is folded over itself; then from that state
//! 400 steps timed with self-contact and without, best of 5. Prints µs per
//! step, the pairs in contact, the candidates, pairs checked and rebuilds
//! per step, the overhead and its ratio to the step, on one thread and
//! with a helper thread lent as the daemon lends one, for f64 and f32
//! springs (the daemon's).
//!
//! Then a folding scene (default the paper's scene 2, which the default
//! daemon serves) run whole from rest at the levels a daemon serves, each
//! at the daemon's dt (the largest dividing the 8 ms metric frame within
//! 0.75 of the level's stability limit), f32 springs, one thread: µs per
//! step with self-contact and without, the steps certified flat, rebuilds
//! per step, the most candidates, and the steps that ended crossing (exact
//! check, every 10th step).
//!
//! With `--timeline N`, only the scene at N×N with self-contact, per half
//! second of its run (mean and slowest step, flat steps, rebuilds, checks).
//!
//! `cargo bench -p lodcloth-core --bench self_contact_cost -- [--levels 32,64] [--thickness 0.003]
//!  [--scene config/scenes/paper-2-corner.toml] [--scene-levels 16,24,32] [--timeline 24]`
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use lodcloth_core::scene::Scene;
use std::sync::atomic::{AtomicBool, Ordering};

use lodcloth_core::sim::{
    crossings, Grab, Lender, Pair, SelfContact, Serial, Simulation, SpringPrecision, StabilityCheck, State, Topology,
};

fn arg<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(String::as_str)
}

/// Best µs per step over 5 runs of `steps`, each from `state`, and per
/// step of the last run: candidate pairs, pairs checked, rebuilds.
fn time(sim: &mut Simulation, state: &State, steps: usize, pair: &dyn Pair) -> (f64, [f64; 3]) {
    let mut best = f64::INFINITY;
    let mut work = [0.0; 3];
    for _ in 0..5 {
        sim.set_state(state.clone()).expect("state fits");
        work = [0.0; 3];
        let t = Instant::now();
        for _ in 0..steps {
            let s = sim.step_on_lean(pair).self_contact;
            work[0] += f64::from(s.candidates);
            work[1] += f64::from(s.checks);
            work[2] += f64::from(s.rebuilds);
        }
        best = best.min(t.elapsed().as_secs_f64() / steps as f64);
    }
    (best * 1e6, work.map(|w| w / steps as f64))
}

fn rebuilt(sim: &Simulation, contact: Option<SelfContact>, precision: SpringPrecision) -> Simulation {
    let mut params = *sim.params();
    params.self_contact = contact;
    let mut out = Simulation::new(
        Arc::clone(sim.topology()),
        sim.masses().to_vec(),
        params,
        sim.loads().clone(),
        sim.state().clone(),
        StabilityCheck::Force,
    )
    .expect("builds");
    out.set_grabs(sim.grabs().to_vec()).expect("grabs fit");
    out.set_spring_precision(precision);
    out
}

/// The corner's grab `t` seconds into the drag (1.6 s in all).
fn drag(topology: &Topology, corner: u32, t: f64) -> Grab {
    let start = topology.rest_positions[corner as usize];
    let up = (t / 0.8).min(1.0);
    let back = ((t - 0.8) / 0.8).clamp(0.0, 1.0);
    Grab {
        nodes: vec![corner],
        weights: vec![1.0],
        // Up and across, 5 cm in front, then 13 cm back.
        target: [start[0] + 0.6 * up, start[1] + 0.6 * up, start[2] + 0.1 - 0.26 * back],
        stiffness: 40.0,
        damping: 0.4,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let levels: Vec<usize> = arg(&args, "--levels")
        .unwrap_or("32,64")
        .split(',')
        .map(|s| s.parse().expect("--levels: node counts per side"))
        .collect();
    let thickness: f64 = arg(&args, "--thickness").map_or(0.003, |s| s.parse().expect("--thickness: metres"));
    let contact = SelfContact {
        thickness,
        friction: 0.3,
    };
    let scene_path = arg(&args, "--scene").unwrap_or(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/scenes/paper-2-corner.toml"
    ));
    if let Some(n) = arg(&args, "--timeline") {
        let n = n.parse().expect("--timeline: nodes per side");
        timeline(Path::new(scene_path), n, contact);
        return;
    }
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/scenes/hanging.toml"));
    let mut scene = Scene::load(path).expect("scene");
    scene.params.self_contact = Some(contact);
    println!(
        "scene {} ({}, dt {:e} s), thickness {thickness} m: the hanging cloth rests 0.5 s, its bottom-left corner is dragged \
         up, across and back through it for 1.6 s; then 400 steps timed, best of 5",
        scene.name,
        scene.params.integrator.name(),
        scene.params.dt
    );
    // A helper thread that does nothing else, as the daemon's partner
    // thread lends itself to a stepping thread.
    let lender = Arc::new(Lender::new());
    let stop = Arc::new(AtomicBool::new(false));
    let helper = {
        let (lender, stop) = (lender.clone(), stop.clone());
        std::thread::spawn(move || lender.serve_until(&stop))
    };
    println!(
        "| level | springs | pairs in contact | crossings | candidates | checks / step | rebuilds / step | without µs | with µs | overhead µs | overhead / step | with, two threads µs | overhead / step, two threads |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for n in levels {
        let mut sim = scene.build_at(n, n).expect("builds");
        let dt = scene.params.dt;
        let corner = ((n - 1) * n) as u32;
        let (mut pairs, mut unresolved, mut first_crossing) = (0, 0, None);
        for s in 0..((0.5 + 1.6) / dt).round() as usize {
            let t = s as f64 * dt - 0.5;
            if t >= 0.0 {
                let grab = drag(sim.topology(), corner, t);
                sim.set_grabs(vec![grab]).expect("a valid grab");
            }
            let report = sim.step().self_contact;
            pairs = report.proximities;
            unresolved += usize::from(report.unresolved > 0);
            if first_crossing.is_none() && s % 10 == 9 && !crossings(sim.topology(), &sim.state().pos).is_empty() {
                first_crossing = Some(s as f64 * dt);
            }
        }
        println!(
            "{n}×{n} drag: {unresolved} steps left pairs colliding; {}",
            first_crossing.map_or("no crossing (exact check, every 10th step)".into(), |t| format!(
                "first crossing at {t:.4} s"
            ))
        );
        let crossed = crossings(sim.topology(), &sim.state().pos).len();
        let state = sim.state().clone();
        for precision in [SpringPrecision::F64, SpringPrecision::F32] {
            let mut with = rebuilt(&sim, Some(contact), precision);
            let mut without = rebuilt(&sim, None, precision);
            let (w, work) = time(&mut with, &state, 400, &Serial);
            let (wo, _) = time(&mut without, &state, 400, &Serial);
            let (w2, _) = time(&mut with, &state, 400, &*lender);
            println!(
                "| {n}×{n} | {precision:?} | {pairs} | {crossed} | {:.0} | {:.0} | {:.2} | {wo:.1} | {w:.1} | {:.1} | {:.2} | {w2:.1} | {:.2} |",
                work[0],
                work[1],
                work[2],
                w - wo,
                (w - wo) / wo,
                (w2 - wo) / wo
            );
        }
    }
    stop.store(true, Ordering::Relaxed);
    helper.join().expect("the helper thread ends");
    let levels: Vec<usize> = arg(&args, "--scene-levels")
        .unwrap_or("16,24,32")
        .split(',')
        .map(|s| s.parse().expect("--scene-levels: node counts per side"))
        .collect();
    whole_scene(Path::new(scene_path), &levels, contact);
}

/// The daemon's dt at level `n`: the largest dividing the metric frame
/// (the reference's dt × 40, `metric_stride`) within 0.75 of the level's
/// stability limit.
fn daemon_dt(scene: &Scene, n: usize) -> f64 {
    let limit = scene.build_at(n, n).expect("builds").dt_limit();
    lodcloth_core::plan::frame_dt(scene.params.dt * 40.0, limit, 0.75)
}

/// The scene at one level with self-contact, whole from rest, f32 springs,
/// one thread: per half second, the mean and slowest step, the share of
/// steps certified flat, rebuilds and checks per step, the most candidates
/// and pairs in contact: where in the run self-contact costs what.
fn timeline(path: &Path, n: usize, contact: SelfContact) {
    let mut scene = Scene::load(path).expect("scene");
    scene.params.dt = daemon_dt(&scene, n);
    scene.params.self_contact = Some(contact);
    let dt = scene.params.dt;
    let mut sim = scene.build_at(n, n).expect("builds");
    sim.set_spring_precision(SpringPrecision::F32);
    println!(
        "scene {} at {n}×{n}, dt {dt:.3e} s, self-contact (thickness {} m), f32 springs, one thread; per 0.5 s:",
        scene.name, contact.thickness
    );
    println!("| from s | mean µs | slowest µs | flat | rebuilds / step | checks / step | most candidates | most in contact | impacts |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let window = (0.5 / dt).round() as usize;
    let steps = (scene.duration / dt).round() as usize;
    for w in 0..steps.div_ceil(window) {
        let (mut spent, mut slowest, mut flat, mut rebuilds, mut checks) = (0.0, 0.0f64, 0, 0u64, 0u64);
        let (mut candidates, mut contact_pairs, mut impacts) = (0, 0, 0u64);
        let count = window.min(steps - w * window);
        for _ in 0..count {
            let t = Instant::now();
            let c = sim.step_on_lean(&Serial).self_contact;
            let took = t.elapsed().as_secs_f64();
            spent += took;
            slowest = slowest.max(took);
            flat += usize::from(c.flat);
            rebuilds += u64::from(c.rebuilds);
            checks += u64::from(c.checks);
            candidates = candidates.max(c.candidates);
            contact_pairs = contact_pairs.max(c.proximities);
            impacts += u64::from(c.impacts);
        }
        println!(
            "| {:.1} | {:.1} | {:.0} | {:.0} % | {:.3} | {:.0} | {candidates} | {contact_pairs} | {impacts} |",
            w as f64 * 0.5,
            spent / count as f64 * 1e6,
            slowest * 1e6,
            100.0 * flat as f64 / count as f64,
            rebuilds as f64 / count as f64,
            checks as f64 / count as f64
        );
    }
    // The same run gives the same bits: a change meant to leave the
    // trajectory alone shows here whether it did.
    let sum = sim.state().pos.iter().fold(0.0, |s, x| s + x);
    println!(
        "final positions' sum {sum:e}, {} crossings",
        crossings(sim.topology(), &sim.state().pos).len()
    );
}

/// The scene run whole from rest at each level, with self-contact and
/// without (module docs).
fn whole_scene(path: &Path, levels: &[usize], contact: SelfContact) {
    let scene = Scene::load(path).expect("scene");
    println!(
        "\nscene {} ({}, {:.1} s), run whole from rest, f32 springs, one thread, thickness {} m",
        scene.name,
        scene.params.integrator.name(),
        scene.duration,
        contact.thickness
    );
    println!(
        "| level | dt | steps | without µs | with µs | overhead / step | slowest step with, ms | most zone rounds | flat steps | rebuilds / step | most candidates | most pairs in contact | steps crossing (of checked) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for &n in levels {
        let dt = daemon_dt(&scene, n);
        let mut at = scene.clone();
        at.params.dt = dt;
        let steps = (at.duration / dt).round() as usize;
        let mut cost = [0.0; 2];
        let (mut rebuilds, mut candidates, mut pairs, mut crossing, mut checked, mut flat) =
            (0u64, 0u32, 0u32, 0, 0, 0);
        // A pass of the daemon's thread is as slow as its slowest step: one
        // over `max_catch_up` (0.1 s) is an overrun for every instance there.
        let (mut slowest, mut rounds) = (0.0f64, 0u32);
        for (i, on) in [false, true].into_iter().enumerate() {
            at.params.self_contact = on.then_some(contact);
            let mut sim = at.build_at(n, n).expect("builds");
            sim.set_spring_precision(SpringPrecision::F32);
            let mut spent = 0.0;
            for s in 0..steps {
                let t = Instant::now();
                let report = sim.step_on_lean(&Serial);
                let took = t.elapsed().as_secs_f64();
                spent += took;
                if on {
                    slowest = slowest.max(took);
                    let c = report.self_contact;
                    rounds = rounds.max(c.zone_rounds);
                    rebuilds += u64::from(c.rebuilds);
                    flat += usize::from(c.flat);
                    candidates = candidates.max(c.candidates);
                    pairs = pairs.max(c.proximities);
                    if s % 10 == 9 {
                        checked += 1;
                        crossing += usize::from(!crossings(sim.topology(), &sim.state().pos).is_empty());
                    }
                }
            }
            cost[i] = spent / steps as f64 * 1e6;
        }
        println!(
            "| {n}×{n} | {dt:.3e} | {steps} | {:.1} | {:.1} | {:.2} | {:.1} | {rounds} | {:.0} % | {:.3} | {candidates} | {pairs} | {crossing} of {checked} |",
            cost[0],
            cost[1],
            (cost[1] - cost[0]) / cost[0],
            slowest * 1e3,
            100.0 * flat as f64 / steps as f64,
            rebuilds as f64 / steps as f64
        );
    }
}
