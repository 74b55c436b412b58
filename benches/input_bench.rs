//! Live input figures (issue 22): input-to-visible latency on loopback
//! (an input sent → the first state stepped after it took effect arrives)
//! at p50/p99, and the stepping real-time factor while 1,000 inputs a
//! second drag the cloth.
//!
//! An in-process daemon (paper-1 at 24×24, 60 states/s, the default input
//! limits) and a client on loopback. With `--shadow`, the instance runs its
//! shadow reference (the scene's 64×64 RK4): from the grab on, the
//! reference replays the inputs on a background thread, and the bench
//! prints how far its live error lags and whether stepping lost real time.
//!
//! `cargo bench --bench input_bench -- [--seconds 10] [--rate 1000] [--shadow]`

use std::time::{Duration, Instant};

use prost::Message;

use lodcloth::proto::v1;
use lodcloth::service::client::{Client, ClientError};
use lodcloth::service::config::ServiceConfig;
use lodcloth::service::keys;

use v1::input_request::Action;

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((p * (sorted.len() - 1) as f64).round() as usize).min(sorted.len() - 1)]
}

fn mv(target: [f64; 3]) -> v1::InputRequest {
    v1::InputRequest {
        action: Some(Action::Move(v1::input_request::Move {
            id: 1,
            target: Some(v1::Vec3 {
                x: target[0],
                y: target[1],
                z: target[2],
            }),
        })),
    }
}

/// A hand circling below the pinned edge (m).
fn circle(t: f64) -> [f64; 3] {
    let w = std::f64::consts::TAU * 0.5 * t;
    [0.5 + 0.2 * w.cos(), -0.8, 0.3 + 0.2 * w.sin()]
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let seconds: f64 = arg("--seconds").and_then(|s| s.parse().ok()).unwrap_or(10.0);
    let rate: f64 = arg("--rate").and_then(|s| s.parse().ok()).unwrap_or(1000.0);
    let shadow = std::env::args().any(|a| a == "--shadow");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .expect("a free port")
        .local_addr()
        .expect("address")
        .port();
    let cache = tempfile::tempdir().expect("temp dir");
    let text = format!(
        r#"
prefix = "bench"
cache = "{}"
[zenoh]
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false
[engine]
publish_hz = 60.0
[estimation]
reference_steps = 15000
precompute = false
[[instances]]
name = "p1"
scene = "config/scenes/paper-1-top-edge.toml"
levels = ["24x24"]
start = "24x24"
method = "same"
shadow_reference = {shadow}
"#,
        cache.path().display()
    );
    let config = ServiceConfig::from_toml(&text, "bench").expect("valid config");
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let daemon = tokio::spawn(lodcloth::service::run(config, async {
        let _ = stopped.await;
    }));
    tokio::time::sleep(Duration::from_millis(500)).await;
    // Shared by the tasks that send the flood.
    let client = std::sync::Arc::new(
        Client::connect(&[format!("tcp/127.0.0.1:{port}")], "bench")
            .await
            .expect("client"),
    );
    while client.info("p1").await.is_err() {
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    if shadow {
        // The level's estimate (with its recorded reference) is in.
        let metrics = client
            .session
            .declare_subscriber(keys::metrics("bench", "p1"))
            .await
            .expect("subscriber");
        let waited = Instant::now();
        loop {
            let m = metrics.recv_async().await.expect("metrics");
            let m = v1::Metrics::decode(m.payload().to_bytes().as_ref()).expect("Metrics");
            if m.live_error.is_some() {
                println!(
                    "shadow reference live after {:.1} s (live error {:.3} %)",
                    waited.elapsed().as_secs_f64(),
                    100.0 * m.live_error.unwrap_or(f64::NAN)
                );
                break;
            }
        }
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    let grab = v1::InputRequest {
        action: Some(Action::Grab(v1::input_request::Grab {
            id: 1,
            at: Some(v1::Patch {
                u: 0.5,
                v: 1.0,
                radius: 0.05,
            }),
            target: None,
            stiffness: 20.0,
            damping: 0.2,
        })),
    };
    client.input("p1", &grab).await.expect("grab");

    // 1. Input to visible, one input at a time, 20 ms apart.
    let states = client
        .session
        .declare_subscriber(keys::state("bench", "p1"))
        .await
        .expect("subscriber");
    let mut latencies = Vec::new();
    let t0 = Instant::now();
    for _ in 0..300 {
        while states.try_recv().ok().flatten().is_some() {}
        let sent = Instant::now();
        let reply = client
            .input("p1", &mv(circle(t0.elapsed().as_secs_f64())))
            .await
            .expect("move");
        loop {
            let s = states.recv_async().await.expect("state");
            let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
            if s.frame > reply.frame {
                break;
            }
        }
        latencies.push(sent.elapsed().as_secs_f64() * 1e3);
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    latencies.sort_by(f64::total_cmp);
    println!(
        "input to visible (loopback, 60 states/s, {} inputs): p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
        latencies.len(),
        percentile(&latencies, 0.5),
        percentile(&latencies, 0.99),
        latencies.last().copied().unwrap_or(f64::NAN)
    );
    drop(states);

    // 2. Stepping under `rate` inputs a second for `seconds`.
    let metrics = client
        .session
        .declare_subscriber(keys::metrics("bench", "p1"))
        .await
        .expect("subscriber");
    let before = v1::Metrics::decode(
        metrics
            .recv_async()
            .await
            .expect("metrics")
            .payload()
            .to_bytes()
            .as_ref(),
    )
    .expect("Metrics");
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
    let start = Instant::now();
    let sender = {
        let client = client.clone();
        tokio::spawn(async move {
            let period = Duration::from_secs_f64(1.0 / rate);
            let mut next = Instant::now();
            let mut sent = 0u64;
            while start.elapsed().as_secs_f64() < seconds {
                let client = client.clone();
                let tx = tx.clone();
                let target = circle(start.elapsed().as_secs_f64());
                tokio::spawn(async move {
                    let r = client.input("p1", &mv(target)).await;
                    let _ = tx.send(r);
                });
                sent += 1;
                next += period;
                tokio::time::sleep_until(next.into()).await;
            }
            sent
        })
    };
    let mut rtf = Vec::new();
    let mut lags = Vec::new();
    while start.elapsed().as_secs_f64() < seconds {
        if let Ok(Ok(m)) = tokio::time::timeout(Duration::from_secs(1), metrics.recv_async()).await {
            if let Ok(m) = v1::Metrics::decode(m.payload().to_bytes().as_ref()) {
                rtf.push(m.real_time_factor);
                lags.push(m.live_error_time.map(|t| m.time - t));
            }
        }
    }
    let sent = sender.await.expect("sender");
    tokio::time::sleep(Duration::from_secs(1)).await;
    let (mut ok, mut busy, mut other) = (0u64, 0u64, 0u64);
    while let Ok(r) = rx.try_recv() {
        match r {
            Ok(_) => ok += 1,
            Err(ClientError::Refused { code, .. }) if code == "CODE_BUSY" => busy += 1,
            Err(_) => other += 1,
        }
    }
    let after = v1::Metrics::decode(
        metrics
            .recv_async()
            .await
            .expect("metrics")
            .payload()
            .to_bytes()
            .as_ref(),
    )
    .expect("Metrics");
    rtf.sort_by(f64::total_cmp);
    println!(
        "{sent} inputs in {seconds} s ({:.0}/s asked): {ok} applied, {busy} BUSY, {other} other; \
         real-time factor per 0.1 s window: min {:.3}, median {:.3}; overruns {} → {}; \
         step {:.1} µs (before the flood {:.1} µs)",
        sent as f64 / seconds,
        rtf.first().copied().unwrap_or(f64::NAN),
        percentile(&rtf, 0.5),
        before.overruns,
        after.overruns,
        after.step_cost_us,
        before.step_cost_us
    );
    if shadow {
        let with: Vec<f64> = lags.iter().flatten().copied().collect();
        let mut sorted = with.clone();
        sorted.sort_by(f64::total_cmp);
        println!(
            "touched live error (the reference replaying the inputs): in {} of {} metrics; \
             lag first {:.3} s, last {:.3} s, p50 {:.3} s, max {:.3} s (simulated)",
            with.len(),
            lags.len(),
            with.first().copied().unwrap_or(f64::NAN),
            with.last().copied().unwrap_or(f64::NAN),
            percentile(&sorted, 0.5),
            sorted.last().copied().unwrap_or(f64::NAN)
        );
    }
    let _ = client.session.close().await;
    let _ = stop.send(());
    let _ = daemon.await;
}
