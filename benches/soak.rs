//! Load and soak figures for the README (issue 7): a daemon (`lodcloth
//! serve`, its own process) on loopback, then
//! 1. **baseline**: one subscriber; publish latency p50/p99 (end of step →
//!    subscriber) and the real-time factor;
//! 2. **load**: `--subscribers` sessions, a tenth of them slow (in a child
//!    process: 100 ms per state, default FIFO handler, so their links back
//!    up); the fast ones' latency p50/p99, what the slow ones received, the
//!    real-time factor;
//! 3. **soak**: `--minutes` of stepping with ten subscribers, a switch every
//!    second and a bad request every second; the daemon's resident memory
//!    sampled every 5 s, written to `out/soak/memory.csv` and `.svg`.
//!
//! `cargo bench --bench soak -- [--subscribers 100] [--minutes 10]
//! [--fast-processes P]` (P > 0: the fast subscribers in P child processes
//! instead of this one).

#[path = "../tests/daemon/mod.rs"]
mod daemon;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use prost::Message;

use daemon::{wait_info, PREFIX};
use lodcloth::output::{line_chart_svg, Series};
use lodcloth::plan::Level;
use lodcloth::proto::{v1, WireLevel};
use lodcloth::service::client::{client_config, Client, ClientOptions};
use lodcloth::service::keys;

fn arg(name: &str, default: f64) -> f64 {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Resident set size of process `pid` (MiB), from /proc.
fn rss_mib(pid: u32) -> f64 {
    let statm = std::fs::read_to_string(format!("/proc/{pid}/statm")).unwrap_or_default();
    let pages: f64 = statm
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    pages * 4096.0 / (1024.0 * 1024.0)
}

fn now_nanos() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// One subscriber session's tally: states received and their latencies (ms).
#[derive(Default)]
struct Tally {
    received: AtomicU64,
    latencies: Mutex<Vec<f64>>,
}

/// A subscriber on its own session; `delay` per state makes it slow. A fast
/// one is a callback, so its arrival time is taken in zenoh's receiving
/// task, not after a hop through a channel and this process's runtime
/// (with 90 of them on 2 cores, that hop's queueing was most of the
/// latency measured); a slow one reads a FIFO channel from a task, so its
/// backlog builds up in its own session.
async fn subscribe(endpoint: String, instance: &str, delay: Duration, tally: Arc<Tally>) -> Client {
    let c = client(&[endpoint]).await;
    if delay.is_zero() {
        c.session
            .declare_subscriber(keys::state(PREFIX, instance))
            .callback(move |s| record(&tally, s.payload().to_bytes().as_ref()))
            .background()
            .await
            .expect("subscriber");
        return c;
    }
    let sub = c
        .session
        .declare_subscriber(keys::state(PREFIX, instance))
        .await
        .expect("subscriber");
    tokio::spawn(async move {
        while let Ok(s) = sub.recv_async().await {
            record(&tally, s.payload().to_bytes().as_ref());
            tokio::time::sleep(delay).await;
        }
    });
    c
}

/// zenoh's low-latency unicast transport (no batching, no TX task: a put
/// writes to each link from the caller) on every session, daemon and
/// readers alike (both ends must agree): `SOAK_LOWLATENCY=1`.
fn lowlatency() -> bool {
    std::env::var("SOAK_LOWLATENCY").is_ok_and(|v| v == "1")
}

/// A peer session connected to `endpoint` (see [`lowlatency`]).
async fn client(endpoints: &[String]) -> Client {
    let mut config = client_config(&ClientOptions::new(endpoints)).expect("client config");
    if lowlatency() {
        config
            .insert_json5("transport/unicast/lowlatency", "true")
            .expect("lowlatency");
        config
            .insert_json5("transport/unicast/qos/enabled", "false")
            .expect("qos");
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match zenoh::open(config.clone()).await {
            Ok(session) => {
                let mut c = Client::with_session(session, PREFIX);
                c.timeout = Duration::from_secs(5);
                return c;
            }
            Err(e) if Instant::now() > deadline => panic!("cannot connect to {endpoints:?}: {e}"),
            Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
        }
    }
}

/// Count a state and its latency (end of step → now).
fn record(tally: &Tally, payload: &[u8]) {
    let arrived = now_nanos();
    let state = v1::State::decode(payload).expect("State");
    tally.received.fetch_add(1, Ordering::Relaxed);
    if !state.transition {
        let ms = arrived.saturating_sub(state.stepped_unix_nanos) as f64 / 1e6;
        tally.latencies.lock().expect("latencies").push(ms);
    }
}

fn percentiles(mut v: Vec<f64>) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    v.sort_by(f64::total_cmp);
    let at = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    (at(0.5), at(0.99))
}

/// Mean real-time factor of `instance` over `seconds`, from its metrics.
async fn real_time_factor(c: &Client, instance: &str, seconds: f64) -> (f64, u64) {
    let sub = c
        .session
        .declare_subscriber(keys::metrics(PREFIX, instance))
        .await
        .expect("metrics");
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let (mut sum, mut n, mut overruns) = (0.0, 0, 0);
    while Instant::now() < end {
        match tokio::time::timeout(end.saturating_duration_since(Instant::now()), sub.recv_async()).await {
            Ok(Ok(s)) => {
                let m = v1::Metrics::decode(s.payload().to_bytes().as_ref()).expect("Metrics");
                sum += m.real_time_factor;
                n += 1;
                overruns = m.overruns;
            }
            _ => break,
        }
    }
    (if n > 0 { sum / n as f64 } else { f64::NAN }, overruns)
}

/// Kills the child process when dropped.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Child mode: `n` slow subscribers (100 ms per state), until killed.
async fn slow_subscribers(endpoint: String, n: usize) {
    let mut sessions = Vec::new();
    let tally = Arc::new(Tally::default());
    for _ in 0..n {
        sessions.push(subscribe(endpoint.clone(), "a", Duration::from_millis(100), tally.clone()).await);
    }
    loop {
        tokio::time::sleep(Duration::from_secs(1)).await;
        // Cumulative, one line a second, for the parent to read at the end.
        println!("{}", tally.received.load(Ordering::Relaxed));
    }
}

/// Child mode: `n` fast subscribers; every second, each new state as
/// `L <subscriber> <arrival unix ns> <latency ms>` on stdout, until killed.
async fn fast_subscribers(endpoint: String, n: usize) {
    let mut sessions = Vec::new();
    let seen: Arc<Mutex<Vec<(usize, u64, f64)>>> = Arc::default();
    for i in 0..n {
        let c = client(std::slice::from_ref(&endpoint)).await;
        let seen = seen.clone();
        c.session
            .declare_subscriber(keys::state(PREFIX, "a"))
            .callback(move |s| {
                let arrived = now_nanos();
                let state = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
                if !state.transition {
                    let ms = arrived.saturating_sub(state.stepped_unix_nanos) as f64 / 1e6;
                    seen.lock().expect("seen").push((i, arrived, ms));
                }
            })
            .background()
            .await
            .expect("subscriber");
        sessions.push(c);
    }
    loop {
        tokio::time::sleep(Duration::from_secs(1)).await;
        let batch = std::mem::take(&mut *seen.lock().expect("seen"));
        let text: String = batch.iter().map(|(i, t, ms)| format!("L {i} {t} {ms}\n")).collect();
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        let _ = out.write_all(text.as_bytes());
        let _ = out.flush();
    }
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--fast-child") {
        let endpoint = args[i + 1].clone();
        return fast_subscribers(endpoint, arg("--fast", 10.0) as usize).await;
    }
    if let Some(i) = args.iter().position(|a| a == "--slow-child") {
        let endpoint = args[i + 1].clone();
        return slow_subscribers(endpoint, arg("--slow", 10.0) as usize).await;
    }
    let subscribers = arg("--subscribers", 100.0) as usize;
    // 0: the fast subscribers are sessions of this process; P: they are
    // spread over P child processes (as separate clients would be).
    let fast_processes = arg("--fast-processes", 0.0) as usize;
    let minutes = arg("--minutes", 10.0);
    let phase = arg("--phase-seconds", 15.0);
    let dir = tempfile::tempdir().expect("temp dir");
    let (daemon, endpoint) = start_daemon(dir.path());
    let pid = daemon.0.id();
    let c = client(std::slice::from_ref(&endpoint)).await;
    let info = wait_info(&c, "a").await;
    println!(
        "daemon: instance a ({}, {} states/s); machine: {} cores",
        daemon::level_of(&daemon::collect_states(&c, "a", 0.2).await[0]),
        info.publish_hz,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );

    let single = baseline(&endpoint, &c, phase).await;
    let mut sessions = load(&c, &endpoint, &info, (subscribers, fast_processes), phase, single).await;
    let keep = sessions.len().min(10);
    for s in sessions.drain(keep..) {
        let _ = s.session.close().await;
    }
    if minutes > 0.0 {
        soak(&c, pid, minutes).await;
    }
    drop(daemon);
}

/// `lodcloth serve` in its own process on a free loopback port (zenoh's
/// low-latency transport with `SOAK_LOWLATENCY=1`), and its endpoint.
fn start_daemon(dir: &std::path::Path) -> (Child, String) {
    let port = daemon::free_port();
    let config = dir.join("soak.toml");
    let mut text = daemon::config_text(port, dir, ("a", "b"));
    if lowlatency() {
        let json5 = dir.join("zenoh.json5");
        std::fs::write(
            &json5,
            "{ transport: { unicast: { lowlatency: true, qos: { enabled: false } } } }",
        )
        .expect("zenoh config");
        text = text.replace(
            "[zenoh]\n",
            &format!("[zenoh]\nconfig_file = \"{}\"\n", json5.display()),
        );
    }
    std::fs::write(&config, text).expect("config");
    // The binary cargo built beside this benchmark.
    let lodcloth = std::path::Path::new(env!("CARGO_BIN_EXE_lodcloth"));
    let daemon = Child(
        std::process::Command::new(lodcloth)
            .args(["serve", "--config"])
            .arg(&config)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("{}: {e} (cargo build --release first)", lodcloth.display())),
    );
    let endpoint = format!("tcp/127.0.0.1:{port}");
    (daemon, endpoint)
}

/// Phase 1: one subscriber's latency p50/p99 (ms) and the real-time
/// factor over `phase` seconds.
async fn baseline(endpoint: &str, c: &Client, phase: f64) -> (f64, f64, f64) {
    let one = Arc::new(Tally::default());
    let single = subscribe(endpoint.to_string(), "a", Duration::ZERO, one.clone()).await;
    tokio::time::sleep(Duration::from_secs(1)).await;
    one.latencies.lock().expect("l").clear();
    let (rtf1, _) = real_time_factor(c, "a", phase).await;
    let (p50_1, p99_1) = percentiles(one.latencies.lock().expect("l").clone());
    let _ = single.session.close().await;

    (rtf1, p50_1, p99_1)
}

/// Phase 2: `subscribers` sessions (a tenth slow, in a child process; the
/// fast ones here or in `fast_processes` children) for `phase` seconds;
/// prints the load table against the `single`-subscriber baseline and
/// returns this process's sessions.
async fn load(
    c: &Client,
    endpoint: &str,
    info: &v1::InstanceInfo,
    (subscribers, fast_processes): (usize, usize),
    phase: f64,
    (rtf1, p50_1, p99_1): (f64, f64, f64),
) -> Vec<Client> {
    let exe = std::env::current_exe().expect("exe");
    // Many sessions, a tenth slow (in a child process, so their
    // blocked handlers back up their own links, not this process).
    let n_slow = subscribers / 10;
    let mut slow_child = Child(
        std::process::Command::new(&exe)
            .args(["--slow-child", endpoint, "--slow", &n_slow.to_string()])
            .stdout(std::process::Stdio::piped())
            .spawn()
            .expect("slow subscribers"),
    );
    let n_fast = subscribers - n_slow;
    // Each child's output is drained as it comes (a full pipe would stall it).
    let fast_children: Vec<(Child, usize, std::thread::JoinHandle<String>)> = (0..fast_processes)
        .map(|p| {
            let k = n_fast / fast_processes + usize::from(p < n_fast % fast_processes);
            let mut child = std::process::Command::new(&exe)
                .args(["--fast-child", endpoint, "--fast", &k.to_string()])
                .stdout(std::process::Stdio::piped())
                .spawn()
                .expect("fast subscribers");
            let mut out = child.stdout.take().expect("child stdout");
            let reader = std::thread::spawn(move || {
                use std::io::Read;
                let mut text = String::new();
                let _ = out.read_to_string(&mut text);
                text
            });
            (Child(child), k, reader)
        })
        .collect();
    let mut tallies = Vec::new();
    let mut sessions = Vec::new();
    for _ in 0..if fast_processes > 0 { 0 } else { n_fast } {
        let t = Arc::new(Tally::default());
        sessions.push(subscribe(endpoint.to_string(), "a", Duration::ZERO, t.clone()).await);
        tallies.push((false, t));
    }
    // Child processes open their sessions one after another: give them
    // time to have every subscriber declared before the phase.
    let settle = if fast_processes > 0 {
        2 + n_fast.div_ceil(fast_processes) as u64 / 3
    } else {
        2
    };
    tokio::time::sleep(Duration::from_secs(settle)).await;
    for (_, t) in &tallies {
        t.latencies.lock().expect("l").clear();
        t.received.store(0, Ordering::Relaxed);
    }
    let window = (now_nanos(), Instant::now());
    let (rtf_n, overruns) = real_time_factor(c, "a", phase).await;
    let window = (window.0, window.0 + window.1.elapsed().as_nanos() as u64);
    let mut fast: Vec<f64> = tallies
        .iter()
        .filter(|(slow, _)| !slow)
        .flat_map(|(_, t)| t.latencies.lock().expect("l").clone())
        .collect();
    let mut fast_received: Vec<u64> = tallies
        .iter()
        .filter(|(slow, _)| !slow)
        .map(|(_, t)| t.received.load(Ordering::Relaxed))
        .collect();
    // Let the children print their last second, then read what arrived
    // within the phase.
    tokio::time::sleep(Duration::from_millis(1200)).await;
    for (mut child, k, reader) in fast_children {
        let _ = child.0.kill();
        let _ = child.0.wait();
        let output = reader.join().unwrap_or_default();
        let mut per_sub: BTreeMap<usize, u64> = (0..k).map(|i| (i, 0)).collect();
        for line in output.lines() {
            let f: Vec<&str> = line.split_whitespace().collect();
            if let ["L", i, t, ms] = f[..] {
                let (Ok(i), Ok(t), Ok(ms)) = (i.parse::<usize>(), t.parse::<u64>(), ms.parse::<f64>()) else {
                    continue;
                };
                if (window.0..=window.1).contains(&t) {
                    fast.push(ms);
                    *per_sub.entry(i).or_default() += 1;
                }
            }
        }
        fast_received.extend(per_sub.values());
    }
    // The child prints its cumulative count every second: read it now and
    // compare with the count at the start of the phase.
    let _ = slow_child.0.kill();
    let output = slow_child.0.wait_with_output_lossy();
    let counts: Vec<u64> = output.lines().filter_map(|l| l.trim().parse().ok()).collect();
    let per_phase = counts.len().saturating_sub(phase as usize + 1);
    let slow_total = counts.last().copied().unwrap_or(0) - counts.get(per_phase).copied().unwrap_or(0);
    let slow_mean = slow_total / n_slow.max(1) as u64;
    let (p50_n, p99_n) = percentiles(fast);
    let published = info.publish_hz * phase;
    println!("\n| subscribers | real-time factor | fast: states received / published | fast latency p50 / p99 | slow: states received |");
    println!("|---|---|---|---|---|");
    println!("| 1 | {rtf1:.3} | – | {p50_1:.2} / {p99_1:.2} ms | – |");
    println!(
        "| {subscribers} ({n_slow} slow) | {rtf_n:.3} (overruns {overruns}) | min {:.0} % | {p50_n:.2} / {p99_n:.2} ms | {} each (mean) of {published:.0} |",
        100.0 * fast_received.iter().copied().min().unwrap_or(0) as f64 / published,
        slow_mean,
    );
    println!(
        "fast-subscriber latency under load / single: p50 ×{:.2}, p99 ×{:.2}",
        p50_n / p50_1,
        p99_n / p99_1
    );
    sessions
}

/// Phase 3: `minutes` of a switch and a bad request every second; the
/// daemon's resident memory sampled every 5 s into `out/soak/`.
async fn soak(c: &Client, pid: u32, minutes: f64) {
    let started = Instant::now();
    let end = started + Duration::from_secs_f64(60.0 * minutes);
    let mut samples: Vec<(f64, f64)> = Vec::new();
    let mut next_sample = started;
    let levels = [Level::new(8, 8), Level::new(12, 12), Level::new(16, 16)];
    let (mut switches, mut refused) = (0u64, 0u64);
    let mut i = 0;
    while Instant::now() < end {
        if Instant::now() >= next_sample {
            let t = started.elapsed().as_secs_f64();
            samples.push((t / 60.0, rss_mib(pid)));
            if samples.len() % 12 == 1 {
                eprintln!("soak {:.1} min: daemon RSS {:.1} MiB", t / 60.0, rss_mib(pid));
            }
            next_sample += Duration::from_secs(5);
        }
        let req = v1::SwitchRequest {
            target: Some(v1::switch_request::Target::Level(levels[i % 3].to_wire())),
            method: String::new(),
            at_once: false,
        };
        let bounded = Duration::from_secs(40);
        if let Ok(Ok(_)) = tokio::time::timeout(bounded, c.switch("a", &req, Duration::from_secs(30))).await {
            switches += 1;
        }
        if let Ok(Err(_)) = tokio::time::timeout(bounded, c.switch_raw("a", Some(vec![0xff; 7]))).await {
            refused += 1;
        }
        i += 1;
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    let simulated = {
        let m = real_time_factor(c, "a", 1.5).await;
        m.0 * 60.0 * minutes
    };
    std::fs::create_dir_all("out/soak").expect("out/soak");
    let csv: String = std::iter::once("minutes,rss_mib\n".to_string())
        .chain(samples.iter().map(|(t, m)| format!("{t:.3},{m:.2}\n")))
        .collect();
    std::fs::write("out/soak/memory.csv", csv).expect("csv");
    line_chart_svg(
        std::path::Path::new("out/soak/memory.svg"),
        "lodcloth soak: the daemon's resident memory",
        "minutes",
        "RSS (MiB)",
        &[Series {
            name: "RSS",
            points: samples.clone(),
            markers: true,
            color: plotters::style::RGBColor(31, 119, 180),
        }],
        false,
        false,
    )
    .expect("svg");
    let after_warmup: Vec<&(f64, f64)> = samples.iter().filter(|(t, _)| *t >= 1.0).collect();
    let (first, last) = (after_warmup.first(), after_warmup.last());
    let peak = samples.iter().map(|s| s.1).fold(0.0, f64::max);
    println!(
        "\nsoak: {minutes} min (≈{simulated:.0} s simulated per instance, 10 subscribers), {switches} switches, {refused} bad requests refused; \
         RSS {:.1} MiB at 1 min, {:.1} MiB at the end, peak {peak:.1} MiB; out/soak/memory.csv, out/soak/memory.svg",
        first.map_or(f64::NAN, |s| s.1),
        last.map_or(f64::NAN, |s| s.1),
    );
}

/// Read what a killed child wrote.
trait WaitLossy {
    fn wait_with_output_lossy(self) -> String;
}

impl WaitLossy for &mut std::process::Child {
    fn wait_with_output_lossy(self) -> String {
        use std::io::Read;
        let mut out = String::new();
        if let Some(mut s) = self.stdout.take() {
            let _ = s.read_to_string(&mut out);
        }
        let _ = self.wait();
        out
    }
}
