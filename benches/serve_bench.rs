//! Daemon figures for the README: capacity of the stepping engine (how many
//! instances per size and integrator hold real time at 1 kHz physics and
//! 60 Hz publishing), state latency from the end of a step to a subscriber
//! on loopback, bytes per state message, and switch latency (prepared and
//! not yet prepared).
//!
//! Cloths of `sim::SPLIT_MIN_NODES` nodes or more (128×128 here)
//! step on both threads when the other is idle (see `engine`), so a single
//! such instance may hold real time where one core could not.
//!
//! Capacity counts grow by one to 8, then by a quarter until one fails,
//! and are then bisected to within 5 % of the largest count held.
//!
//! `cargo bench --bench serve_bench -- [--quick] [--bus-only | --capacity-only] [--sizes 24,40,64,128] [--precision f32]`
//! (`--precision f32`: the capacity instances evaluate their springs in f32,
//! as an instance with `spring_precision = "f32"`).

use std::time::{Duration, Instant};

use prost::Message;

use lodcloth::engine::{Engine, EngineSettings, InstanceSetup, StateFrame};
use lodcloth::plan::Level;
use lodcloth::proto::state_message;
use lodcloth::proto::{v1, WireLevel};
use lodcloth::scene::Scene;
use lodcloth::service::client::Client;
use lodcloth::service::config::ServiceConfig;
use lodcloth::service::keys;
use lodcloth::sim::{Integrator, Simulation, SpringPrecision};

const DT: f64 = 1e-3;

/// The paper's first scene at n×n stepping at 1 kHz: its springs softened
/// just enough that dt = 1 ms is within 0.8 of the predicted limit (the cost
/// of a step does not depend on the stiffness). Not beyond 128×128: so
/// softened, a 256×256 cloth stretches past 10× its length within a second
/// and halts as diverged (and its two-thread step, ~1 ms, would not hold
/// 1 kHz anyway).
fn instance(n: usize, integrator: Integrator, precision: SpringPrecision) -> Simulation {
    let mut scene = Scene::load(std::path::Path::new("config/scenes/paper-1-top-edge.toml")).expect("scene");
    scene.params.integrator = integrator;
    scene.params.dt = DT;
    scene.stability = lodcloth::sim::StabilityCheck::Force;
    let probe = scene.build_at(n, n).expect("build");
    let limit = probe.dt_limit();
    if limit < DT / 0.8 {
        let scale = (limit * 0.8 / DT).powi(2);
        for s in &mut scene.params.material.springs {
            s.k *= scale;
            s.c *= scale.sqrt();
        }
    }
    scene.stability = lodcloth::sim::StabilityCheck::Enforce;
    let mut sim = scene.build_at(n, n).expect("stable at 1 kHz");
    sim.set_spring_precision(precision);
    sim
}

/// Run `count` instances for `seconds`; worst real-time factor and total overruns.
fn trial(n: usize, integrator: Integrator, precision: SpringPrecision, count: usize, seconds: f64) -> (f64, u64, f64) {
    let setups = (0..count)
        .map(|i| InstanceSetup {
            publish_hz: 60.0,
            ..InstanceSetup::new(format!("i{i}"), instance(n, integrator, precision), Level::new(n, n))
        })
        .collect();
    let engine = Engine::start(
        setups,
        EngineSettings {
            threads: 2,
            max_catch_up: 0.1,
            max_lag: 0.25,
            slice: lodcloth::engine::PASS_SLICE,
            // The frame count read below is refreshed with the metrics: at
            // 100 Hz it is at most 10 ms stale, 0.3 % of a trial.
            metrics_hz: 100.0,
            replay_class: || {},
        },
    )
    .expect("engine");
    // Warm up, then measure the simulated time each instance advanced.
    std::thread::sleep(Duration::from_millis(500));
    let frames0: Vec<u64> = engine.handles().iter().map(|h| h.status().frame).collect();
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(seconds));
    let wall = t0.elapsed().as_secs_f64();
    let mut worst = f64::INFINITY;
    let mut overruns = 0;
    let mut cost = 0.0;
    for (h, f0) in engine.handles().iter().zip(frames0) {
        let f1 = h.status().frame;
        worst = worst.min((f1 - f0) as f64 * DT / wall);
        if let Some(m) = h.metrics.borrow().as_ref() {
            overruns += m.overruns + m.lag_resets;
            cost += m.step_cost_us;
        }
    }
    engine.stop();
    (worst, overruns, cost / count as f64)
}

fn capacity(quick: bool, sizes: &[usize], precision: SpringPrecision) {
    println!(
        "## Capacity: instances in real time at 1 kHz physics, 60 Hz snapshots, 2 stepping threads, springs in {precision}\n"
    );
    println!("| size | integrator | step µs, alone | instances held | core-µs per step at capacity | first count failed: instances, worst RTF, overruns |");
    println!("|---|---|---|---|---|---|");
    let seconds = if quick { 1.0 } else { 4.0 };
    for &n in sizes {
        for integrator in [Integrator::SymplecticEuler, Integrator::Rk4] {
            // Grow until an instance falls behind (status frames are refreshed
            // at the metrics rate, so allow 1 % slack on the factor).
            let mut held = 0;
            let mut count = 1;
            let mut step_us = f64::NAN;
            let mut fail = (0.0, 0);
            let mut failed = None;
            loop {
                let (rtf, overruns, cost) = trial(n, integrator, precision, count, seconds);
                if count == 1 {
                    step_us = cost;
                }
                if rtf >= 0.99 && overruns == 0 {
                    held = count;
                    count = if count < 8 { count + 1 } else { count + count / 4 };
                } else {
                    fail = (rtf, overruns);
                    failed = Some(count);
                    break;
                }
                if count > 400 {
                    break;
                }
            }
            // Past 8 the counts grow by a quarter: bisect between the last
            // count held and the first that failed, to within 5 %, so a
            // row reads its capacity rather than the grid's step.
            while let Some(bad) = failed.filter(|&bad| bad - held > (held / 20).max(1)) {
                let mid = held + (bad - held) / 2;
                let (rtf, overruns, _) = trial(n, integrator, precision, mid, seconds);
                if rtf >= 0.99 && overruns == 0 {
                    held = mid;
                } else {
                    fail = (rtf, overruns);
                    failed = Some(mid);
                }
            }
            // Two threads' worth of wall time shared by `held` instances at 1 kHz.
            let budget = if held > 0 {
                2.0 * 1e6 * DT / held as f64
            } else {
                f64::NAN
            };
            println!(
                "| {n}×{n} | {integrator} | {step_us:.1} | {held} | ≤ {budget:.1} | {}, {:.2}, {} |",
                failed.map_or_else(|| "none up to 400".to_string(), |c| c.to_string()),
                fail.0,
                fail.1
            );
        }
    }
    println!();
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

async fn bus(quick: bool) {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let cache = tempfile::tempdir().unwrap();
    let text = format!(
        r#"
prefix = "bench"
cache = "{}"
[zenoh]
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false
[estimation]
reference_steps = 15000
precompute = false
[[instances]]
name = "p1"
scene = "config/scenes/paper-1-top-edge.toml"
levels = ["16x16", "24x24", "32x32", "40x40"]
start = "24x24"
method = "gkd"
"#,
        cache.path().display()
    );
    let config = ServiceConfig::from_toml(&text, "bench").unwrap();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let daemon = tokio::spawn(lodcloth::service::run(config, async {
        let _ = rx.await;
    }));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let client = Client::connect(&[format!("tcp/127.0.0.1:{port}")], "bench")
        .await
        .unwrap();
    let sub = client
        .session
        .declare_subscriber(keys::state("bench", "p1"))
        .await
        .unwrap();
    // Latency: the end of the step a state was taken after → receipt here.
    let mut lat = Vec::new();
    let mut bytes = 0usize;
    let end = Instant::now() + Duration::from_secs(if quick { 3 } else { 10 });
    while Instant::now() < end {
        let Ok(Ok(s)) = tokio::time::timeout(Duration::from_secs(2), sub.recv_async()).await else {
            break;
        };
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as f64;
        let payload = s.payload().to_bytes();
        bytes = payload.len();
        let st = v1::State::decode(payload.as_ref()).unwrap();
        lat.push((now - st.stepped_unix_nanos as f64) / 1e3);
    }
    // An undrained subscriber fills its FIFO and then blocks this session's
    // receive path (zenoh's default handler), replies included: drop it.
    drop(sub);
    println!("## State latency, end of step → subscriber (loopback, one subscriber, 24×24 at 60 Hz)\n");
    println!(
        "{} states: p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs; {} bytes per message\n",
        lat.len(),
        percentile(&mut lat, 0.5),
        percentile(&mut lat, 0.99),
        percentile(&mut lat, 1.0),
        bytes
    );
    println!("## Bytes per state message\n");
    println!("| level | nodes | bytes |");
    println!("|---|---|---|");
    for n in [24usize, 40, 64, 128] {
        let f = StateFrame {
            frame: 123_456,
            time: 1.234,
            episode: 0,
            level: Level::new(n, n),
            coefficient_version: 2,
            positions: vec![0.5; 3 * n * n],
            simulation_positions: Vec::new(),
            normals: Vec::new(),
            reference_positions: Vec::new(),
            collider_positions: Vec::new(),
            stepped: std::time::SystemTime::now(),
            transition: false,
        };
        println!(
            "| {n}×{n} | {} | {} |",
            n * n,
            state_message("paper-1", &f).encode_to_vec().len()
        );
    }
    println!();
    println!("## Switch latency (request → new level stepping → reply)\n");
    println!("| switch | prepared before? | seconds |");
    println!("|---|---|---|");
    let req = |n| v1::SwitchRequest {
        target: Some(v1::switch_request::Target::Level(Level::new(n, n).to_wire())),
        method: String::new(),
        at_once: false,
    };
    let t = Duration::from_secs(600);
    // Let the start level's estimate go live first (records the reference).
    let _ = client.switch("p1", &req(24), t).await;
    for (n, label) in [
        (40, "24→40, uncached: estimate + calibrate"),
        (24, "40→24, prepared"),
        (40, "24→40, prepared"),
    ] {
        let t0 = Instant::now();
        let r = match client.switch("p1", &req(n), t).await {
            Ok(r) => r,
            Err(e) => {
                println!("| {label} | — | failed: {e} |");
                continue;
            }
        };
        println!(
            "| {label} | {} | {:.3} (daemon: {:.3}) |",
            r.cached,
            t0.elapsed().as_secs_f64(),
            r.seconds
        );
    }
    println!();
    let _ = tx.send(());
    let _ = daemon.await;
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap();
    if !std::env::args().any(|a| a == "--bus-only") {
        let args: Vec<String> = std::env::args().collect();
        let sizes: Vec<usize> = args
            .iter()
            .position(|a| a == "--sizes")
            .and_then(|i| args.get(i + 1))
            .map(|s| {
                s.split(',')
                    .map(|x| x.trim().parse().expect("--sizes: a list of sizes"))
                    .collect()
            })
            .unwrap_or_else(|| vec![24, 40, 64, 128]);
        let precision = args
            .iter()
            .position(|a| a == "--precision")
            .and_then(|i| args.get(i + 1))
            .map_or(SpringPrecision::F64, |s| {
                SpringPrecision::from_name(s).expect("--precision: f64 or f32")
            });
        capacity(quick, &sizes, precision);
    }
    if !std::env::args().any(|a| a == "--capacity-only") {
        rt.block_on(bus(quick));
    }
}
