//! Figures of the browser view for the README: frames per second the page
//! renders in headless Chromium (SwiftShader, no GPU) for 64×64 and 128×128
//! cloths, and the latency from the daemon's publish to the browser's
//! receipt through `lodcloth view`, next to a plain zenoh subscriber's on
//! the same states (the difference is what the relay adds).
//!
//! Daemon, viewer and browser share the machine, as on a laptop.
//!
//! `cargo bench --bench view_bench -- [--seconds S]`
//! Writes `out/view-bench/view_bench.csv`.

#[path = "../tests/browser/mod.rs"]
mod browser;
#[path = "../tests/daemon/mod.rs"]
mod daemon;

use std::io::Write;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use prost::Message;
use serde_json::Value;

use browser::Browser;
use daemon::*;
use lodcloth::proto::v1;
use lodcloth::service::client::ClientOptions;
use lodcloth::view::ViewOptions;

/// p-quantile of sorted values.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

struct Row {
    n: usize,
    fps: f64,
    states_per_s: f64,
    publish_hz: f64,
    rtf: f64,
    page: (f64, f64),
    direct: (f64, f64),
    samples: usize,
}

/// One n×n instance (paper scene 1, symplectic Euler at the level's stable
/// dt, method `same`: steps stay short, so states go out at the publish
/// rate even where the cloth runs behind real time), the viewer and a
/// browser; measure `seconds`.
async fn measure(n: usize, seconds: f64) -> Row {
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let publish_hz = 60.0;
    let text = config_header(port, dir.path()).replace("publish_hz = 50.0", &format!("publish_hz = {publish_hz}"))
        + &format!(
            r#"
[estimation]
reference_steps = 120
metric_stride = 20
estimate_stride = 20
[[instances]]
name = "g{n}"
scene = "{scene}"
integrator = "symplectic_euler"
reference = "{n}x{n}"
levels = ["{n}x{n}"]
start = "{n}x{n}"
method = "same"
"#,
            scene = scene_path("paper-1-top-edge.toml").display(),
        );
    let d = Daemon::run(port, &text, dir);
    let c = client(&[d.endpoint()]).await;
    let name = format!("g{n}");
    wait_info(&c, &name).await;

    let (addr_tx, addr_rx) = tokio::sync::oneshot::channel();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let options = ViewOptions {
        listen: "127.0.0.1:0".parse().expect("address"),
        zenoh: ClientOptions::new(&[d.endpoint()]),
        prefix: PREFIX.into(),
    };
    let view = tokio::spawn(lodcloth::view::run(
        options,
        move |a| {
            let _ = addr_tx.send(a);
        },
        async {
            let _ = stop_rx.await;
        },
    ));
    let addr = addr_rx.await.expect("viewer address");
    let mut b = Browser::open(&format!("http://{addr}/?instance={name}")).await;
    b.wait_for(60, "states drawn", "(window.lodclothStats?.statesDrawn ?? 0) > 20")
        .await;

    // A plain subscriber beside the browser: the bus's own latency.
    let sub = c
        .session
        .declare_subscriber(lodcloth::service::keys::state(PREFIX, &name))
        .await
        .expect("subscriber");
    let metrics = c
        .session
        .declare_subscriber(lodcloth::service::keys::metrics(PREFIX, &name))
        .await
        .expect("subscriber");
    b.eval("(() => { window.lodclothStats.latenciesMs.length = 0; return true; })()")
        .await;
    let drawn0 = b.eval("window.lodclothStats.statesDrawn").await.as_f64().unwrap_or(0.0);
    let mut fps = Vec::new();
    let mut direct = Vec::new();
    let mut rtf = Vec::new();
    let start = Instant::now();
    let mut next_sample = start + Duration::from_secs(1);
    while start.elapsed().as_secs_f64() < seconds {
        tokio::select! {
            s = sub.recv_async() => {
                let s = s.expect("a state");
                let now = SystemTime::now().duration_since(UNIX_EPOCH).expect("clock").as_nanos() as f64;
                let st = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
                direct.push((now - st.stepped_unix_nanos as f64) / 1e6);
            }
            m = metrics.recv_async() => {
                let m = v1::Metrics::decode(m.expect("metrics").payload().to_bytes().as_ref()).expect("Metrics");
                rtf.push(m.real_time_factor);
            }
            () = tokio::time::sleep_until(next_sample.into()) => {
                next_sample += Duration::from_secs(1);
                fps.push(b.eval("window.lodclothStats.fps").await.as_f64().unwrap_or(0.0));
            }
        }
    }
    let elapsed = start.elapsed().as_secs_f64();
    let drawn = b.eval("window.lodclothStats.statesDrawn").await.as_f64().unwrap_or(0.0) - drawn0;
    let mut page: Vec<f64> = match b.eval("window.lodclothStats.latenciesMs").await {
        Value::Array(v) => v.iter().filter_map(Value::as_f64).collect(),
        _ => Vec::new(),
    };
    b.screenshot(&std::path::PathBuf::from(format!("out/view-bench/view_{n}.png")))
        .await;
    drop(b);
    let _ = stop_tx.send(());
    let _ = view.await;
    drop((sub, metrics));
    drop(c);
    d.shutdown().await.expect("daemon shutdown");

    page.sort_by(f64::total_cmp);
    direct.sort_by(f64::total_cmp);
    rtf.sort_by(f64::total_cmp);
    Row {
        n,
        fps: fps.iter().sum::<f64>() / fps.len().max(1) as f64,
        states_per_s: drawn / elapsed,
        publish_hz,
        rtf: quantile(&rtf, 0.5),
        page: (quantile(&page, 0.5), quantile(&page, 0.99)),
        direct: (quantile(&direct, 0.5), quantile(&direct, 0.99)),
        samples: page.len(),
    }
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seconds = args
        .iter()
        .position(|a| a == "--seconds")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(15.0);
    std::fs::create_dir_all("out/view-bench").expect("out dir");
    let mut rows = Vec::new();
    for n in [64, 128] {
        eprintln!("measuring {n}x{n} for {seconds} s …");
        rows.push(measure(n, seconds).await);
    }
    let mut csv = std::fs::File::create("out/view-bench/view_bench.csv").expect("csv");
    writeln!(
        csv,
        "level,page_fps,states_drawn_per_s,publish_hz,real_time_factor,page_latency_p50_ms,page_latency_p99_ms,bus_latency_p50_ms,bus_latency_p99_ms,samples"
    )
    .expect("csv");
    println!("| level | page fps | states drawn/s (published {}/s) | real-time factor | publish → browser p50 / p99 (ms) | publish → zenoh subscriber p50 / p99 (ms) | relay adds p50 / p99 (ms) |", rows[0].publish_hz);
    println!("|---|---|---|---|---|---|---|");
    for r in &rows {
        writeln!(
            csv,
            "{n}x{n},{:.1},{:.1},{},{:.3},{:.2},{:.2},{:.2},{:.2},{}",
            r.fps,
            r.states_per_s,
            r.publish_hz,
            r.rtf,
            r.page.0,
            r.page.1,
            r.direct.0,
            r.direct.1,
            r.samples,
            n = r.n
        )
        .expect("csv");
        println!(
            "| {n}×{n} | {:.1} | {:.1} | {:.2} | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} / {:.2} |",
            r.fps,
            r.states_per_s,
            r.rtf,
            r.page.0,
            r.page.1,
            r.direct.0,
            r.direct.1,
            r.page.0 - r.direct.0,
            r.page.1 - r.direct.1,
            n = r.n
        );
    }
    eprintln!("wrote out/view-bench/view_bench.csv and view_64.png, view_128.png");
}
