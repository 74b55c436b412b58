//! Bad input and abuse on the bus: a million generated requests through the
//! request checks, thousands over a real zenoh session while the daemon
//! publishes, a switch flood, a client that vanishes mid-request, and a
//! router that stops and comes back.

use crate::common;
use crate::daemon;
use crate::fuzz;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures_util::stream::{FuturesUnordered, StreamExt};
use prost::Message;

use common::Rng;
use daemon::{client, collect_states, config_text, wait_info, within, Daemon, PREFIX};
use fuzz::Leaf;
use lodcloth::estimate::Method;
use lodcloth::plan::{InstancePlan, Level};
use lodcloth::proto::{v1, WireLevel};
use lodcloth::service::client::{Client, ClientError, ClientOptions};
use lodcloth::service::config::ServiceConfig;
use lodcloth::service::request::{self, Refusal, SwitchTarget};
use lodcloth::service::snapshot;
use lodcloth::service::{encoding, keys};
use v1::error::Code;

/// What the daemon would do with a request, short of acting on it.
#[derive(Debug)]
enum Accepted {
    Switch(request::SwitchPlan),
    Control(v1::control_request::Action),
    Input(lodcloth::touch::Input),
    Info,
}

/// The daemon's checks, in its order: key, payload, fields.
fn check(r: &fuzz::Request, instances: &BTreeMap<String, InstancePlan>) -> Result<Accepted, Refusal> {
    let key = r.key(PREFIX);
    let name = request::instance_name(
        PREFIX,
        r.leaf.name(),
        &key,
        |n| instances.contains_key(n),
        || instances.keys().cloned().collect::<Vec<_>>().join(", "),
    )?;
    let (enc, payload) = (r.encoding.as_deref(), r.payload.as_deref());
    match r.leaf {
        Leaf::Switch => {
            let req: v1::SwitchRequest = request::decode("lodcloth.v1.SwitchRequest", enc, payload)?;
            request::switch_plan(&instances[name], &req).map(Accepted::Switch)
        }
        Leaf::Control => {
            let req: v1::ControlRequest = request::decode("lodcloth.v1.ControlRequest", enc, payload)?;
            request::control_action(&req).map(Accepted::Control)
        }
        Leaf::Input => {
            let req: v1::InputRequest = request::decode("lodcloth.v1.InputRequest", enc, payload)?;
            request::input(&req).map(Accepted::Input)
        }
        Leaf::Info => Ok(Accepted::Info),
    }
}

/// Words of which a refusal must name at least one: what was wrong.
const SUBJECTS: [&str; 16] = [
    "grab",
    "move",
    "release",
    "wind",
    "impulse",
    "no action",
    "key",
    "instance",
    "payload",
    "encoding",
    "method",
    "target",
    "level",
    "max_error",
    "action",
    "malformed",
];

fn assert_names_the_problem(code: i32, message: &str, what: &dyn std::fmt::Debug) {
    assert_ne!(code, Code::Unspecified as i32, "a refusal without a code for {what:?}");
    assert!(
        SUBJECTS.iter().any(|s| message.contains(s)),
        "the refusal '{message}' names no field for {what:?}"
    );
}

/// Abbreviated, for failure messages.
fn describe(r: &fuzz::Request) -> String {
    let payload = r.payload.as_ref().map(|p| {
        let head: Vec<u8> = p.iter().take(48).copied().collect();
        format!("{} bytes {head:02x?}", p.len())
    });
    format!("{} encoding={:?} payload={payload:?}", r.key(PREFIX), r.encoding)
}

fn test_config(port: u16, dir: &std::path::Path) -> ServiceConfig {
    ServiceConfig::from_toml(&config_text(port, dir, ("a", "b")), "test").expect("valid config")
}

#[test]
fn a_million_generated_requests_are_each_accepted_correctly_or_refused_by_name() {
    let _serial = daemon::serial_blocking();
    let dir = tempfile::tempdir().expect("temp dir");
    let config = test_config(7, dir.path());
    let instances: BTreeMap<String, InstancePlan> =
        config.instances.iter().map(|i| (i.name.clone(), i.clone())).collect();
    let names: Vec<&str> = instances.keys().map(String::as_str).collect();
    let n: u64 = std::env::var("LODCLOTH_FUZZ_REQUESTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1_000_000);
    let seed = 0x10dc_1074;
    let mut rng = Rng::new(seed);
    let mut outcomes: BTreeMap<String, u64> = BTreeMap::new();
    let started = Instant::now();
    for _ in 0..n {
        let r = fuzz::request(&mut rng, &names);
        let outcome = std::panic::catch_unwind(|| check(&r, &instances))
            .unwrap_or_else(|_| panic!("the checks panicked on {}", describe(&r)));
        let class = match outcome {
            Err(refusal) => {
                assert_names_the_problem(refusal.code as i32, &refusal.message, &describe(&r));
                format!("refused {}", refusal.code.as_str_name())
            }
            Ok(Accepted::Switch(plan)) => {
                // Independently: the payload is a switch request whose
                // target is allowed and whose method exists.
                let req = v1::SwitchRequest::decode(r.payload.as_deref().unwrap_or_default()).expect("decodes");
                let config = &instances[r.instance.as_str()];
                match plan.target {
                    SwitchTarget::Level(l) => assert!(config.levels.contains(&l), "{l} accepted"),
                    SwitchTarget::MaxError(e) => assert!(e > 0.0 && e.is_finite(), "max_error {e} accepted"),
                }
                assert!(req.method.is_empty() || Method::from_name(&req.method) == Some(plan.method));
                "switch accepted".into()
            }
            Ok(Accepted::Control(a)) => format!("control {} accepted", a.as_str_name()),
            Ok(Accepted::Input(input)) => {
                // Independently: every number of an accepted input is
                // finite, and material coordinates lie on the cloth.
                assert_input_in_range(&input);
                let name = format!("{input:?}");
                format!("input {} accepted", name.split([' ', '{']).next().unwrap_or_default())
            }
            Ok(Accepted::Info) => "info accepted".into(),
        };
        *outcomes.entry(class).or_default() += 1;
    }
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "{n} generated requests (seed {seed:#x}) checked in {seconds:.2} s ({:.0}/s):",
        n as f64 / seconds
    );
    for (class, count) in &outcomes {
        println!("  {class:<40} {count:>8}");
    }
    // The generator reaches every kind of answer.
    for class in [
        "refused CODE_BAD_REQUEST",
        "refused CODE_UNKNOWN_INSTANCE",
        "refused CODE_LEVEL_NOT_ALLOWED",
        "switch accepted",
        "control ACTION_PAUSE accepted",
        "input Grab accepted",
        "input Impulse accepted",
    ] {
        assert!(
            outcomes.get(class).copied().unwrap_or(0) > 0,
            "no '{class}' among {outcomes:?}"
        );
    }
}

/// Arrival times of `instance`'s states, collected in the background.
fn count_states(c: &Client, instance: &str) -> (Arc<Mutex<Vec<Instant>>>, tokio::task::JoinHandle<()>) {
    let arrivals = Arc::new(Mutex::new(Vec::new()));
    let session = c.session.clone();
    let key = keys::state(PREFIX, instance);
    let sink = arrivals.clone();
    let task = tokio::spawn(async move {
        let sub = session.declare_subscriber(key).await.expect("subscriber");
        while let Ok(_s) = sub.recv_async().await {
            sink.lock().expect("arrivals").push(Instant::now());
        }
    });
    (arrivals, task)
}

fn rate_between(arrivals: &Mutex<Vec<Instant>>, from: Instant, to: Instant) -> f64 {
    let n = arrivals
        .lock()
        .expect("arrivals")
        .iter()
        .filter(|&&t| t >= from && t < to)
        .count();
    n as f64 / (to - from).as_secs_f64()
}

/// Every reply to one raw query: (ok payloads, (code, message) of errors).
async fn ask(c: &Client, r: &fuzz::Request) -> (usize, Vec<(i32, String)>) {
    // A switch may wait for a level's `fit` (for a max_error target, every
    // level's): tens of seconds on 2 busy cores. Everything else is quick.
    let timeout = if r.leaf == Leaf::Switch { 120 } else { 10 };
    let mut get = c.session.get(r.key(PREFIX)).timeout(Duration::from_secs(timeout));
    if let Some(p) = &r.payload {
        get = get.payload(p.clone());
    }
    if let Some(e) = &r.encoding {
        get = get.encoding(zenoh::bytes::Encoding::from(e.clone()));
    }
    let replies = get.await.expect("a query");
    let (mut ok, mut errors) = (0, Vec::new());
    while let Ok(reply) = replies.recv_async().await {
        match reply.result() {
            Ok(_) => ok += 1,
            Err(e) => {
                let bytes = e.payload().to_bytes();
                let err = v1::Error::decode(bytes.as_ref()).unwrap_or_else(|_| {
                    panic!(
                        "an error reply that is not an Error ('{}') to {}",
                        String::from_utf8_lossy(&bytes),
                        describe(r)
                    )
                });
                errors.push((err.code, err.message));
            }
        }
    }
    (ok, errors)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn generated_requests_over_the_bus_are_all_answered_while_publishing_keeps_its_rate() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("a", "b"));
    let c = client(&[d.endpoint()]).await;
    let info = within(20, "info", wait_info(&c, "a")).await;
    within(20, "info b", wait_info(&c, "b")).await;
    let (arrivals, counter) = count_states(&c, "a");
    tokio::time::sleep(Duration::from_secs(2)).await;
    let before_end = Instant::now();
    let before = rate_between(&arrivals, before_end - Duration::from_millis(1500), before_end);

    // Requests go to `b` and to unknown names; `a` is the witness that
    // publishing goes on (b is legitimately paused, reset and switched).
    let n: usize = std::env::var("LODCLOTH_BUS_FUZZ_REQUESTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200_000);
    let mut rng = Rng::new(0xb05_f022);
    let started = Instant::now();
    let (mut unanswered, mut ok, mut refused) = (0usize, 0usize, 0usize);
    let mut in_flight = FuturesUnordered::new();
    let mut sent = 0;
    while sent < n || !in_flight.is_empty() {
        while sent < n && in_flight.len() < 32 {
            let r = fuzz::request(&mut rng, &["b"]);
            let c = &c;
            in_flight.push(async move { (ask(c, &r).await, r) });
            sent += 1;
        }
        let Some(((oks, errors), r)) = in_flight.next().await else {
            break;
        };
        if oks == 0 && errors.is_empty() {
            unanswered += 1;
            eprintln!("unanswered: {}", describe(&r));
        }
        ok += oks.min(1);
        for (code, message) in &errors {
            if *code != Code::Busy as i32 {
                assert_names_the_problem(*code, message, &describe(&r));
            }
        }
        refused += usize::from(!errors.is_empty());
    }
    let fuzz_end = Instant::now();
    let seconds = (fuzz_end - started).as_secs_f64();
    let during = rate_between(&arrivals, started, fuzz_end);
    println!(
        "{n} requests over the bus in {seconds:.1} s ({:.0}/s): {ok} accepted, {refused} refused, {unanswered} unanswered; \
         states of the witness: {before:.1}/s before, {during:.1}/s during (publish_hz {})",
        n as f64 / seconds,
        info.publish_hz
    );
    assert_eq!(unanswered, 0, "every request gets an answer");
    assert!(
        during >= 0.8 * before,
        "publishing fell from {before:.1}/s to {during:.1}/s under the request load"
    );
    // Both instances still serve, and `b` steps again once resumed.
    wait_info(&c, "a").await;
    c.control("b", v1::control_request::Action::Resume)
        .await
        .expect("resume b");
    let b_states = collect_states(&c, "b", 1.0).await;
    assert!(
        b_states.len() >= 5,
        "b publishes after the fuzz: {} states",
        b_states.len()
    );
    counter.abort();
    d.shutdown().await.expect("clean shutdown");
}

fn to(level: Level) -> v1::SwitchRequest {
    v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(level.to_wire())),
        method: String::new(),
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_switches_is_answered_and_the_instance_ends_consistent() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("a", "b"));
    let c = Arc::new(client(&[d.endpoint()]).await);
    within(20, "info", wait_info(&c, "a")).await;
    let (arrivals, counter) = count_states(&c, "a");
    let levels = [Level::new(8, 8), Level::new(12, 12), Level::new(16, 16)];
    // 100 requests a second for 10 s, cycling through the levels.
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    let mut tasks = Vec::new();
    let started = Instant::now();
    for i in 0..1000 {
        tick.tick().await;
        let c = c.clone();
        let level = levels[i % levels.len()];
        tasks.push(tokio::spawn(async move {
            let t0 = Instant::now();
            let r = c.switch("a", &to(level), Duration::from_secs(30)).await;
            (r, t0.elapsed().as_secs_f64())
        }));
    }
    let flood_end = Instant::now();
    let (mut ok, mut busy) = (Vec::new(), 0);
    let mut latencies = Vec::new();
    for t in tasks {
        let (r, seconds) = within(60, "a flood reply", t).await.expect("request task");
        latencies.push(seconds);
        match r {
            Ok(reply) => ok.push(reply),
            Err(ClientError::Refused { code, .. }) if code == "CODE_BUSY" => busy += 1,
            Err(e) => panic!("a flood request got neither a switch nor BUSY: {e}"),
        }
    }
    latencies.sort_by(f64::total_cmp);
    let gaps: Vec<f64> = {
        let a = arrivals.lock().expect("arrivals");
        a.windows(2)
            .filter(|w| w[0] >= started && w[1] <= flood_end)
            .map(|w| (w[1] - w[0]).as_secs_f64())
            .collect()
    };
    let max_gap = gaps.iter().copied().fold(0.0, f64::max);
    let rate = rate_between(&arrivals, started, flood_end);
    println!(
        "1000 switches at 100/s: {} applied, {busy} refused BUSY; reply latency p50 {:.1} ms, p99 {:.1} ms; \
         states {rate:.1}/s, largest gap {:.0} ms",
        ok.len(),
        1e3 * percentile(&latencies, 0.5),
        1e3 * percentile(&latencies, 0.99),
        1e3 * max_gap
    );
    assert!(!ok.is_empty(), "some switches are applied");
    assert!(max_gap < 0.5, "stepping stalled: {max_gap:.3} s without a state");
    assert!(rate >= 40.0, "publishing fell to {rate:.1}/s during the flood");
    // Consistent: the last applied switch (highest coefficient version) is
    // the level the daemon reports and publishes.
    let last = ok
        .iter()
        .max_by_key(|r| r.coefficient_version)
        .expect("an applied switch");
    let last_level = Level::from_wire(last.level.as_ref().expect("level")).expect("level");
    let info = c.info("a").await.expect("info");
    assert_eq!(info.coefficient_version, last.coefficient_version);
    assert_eq!(Level::from_wire(info.level.as_ref().expect("level")), Ok(last_level));
    daemon::assert_after_switch(&collect_states(&c, "a", 0.5).await, last);
    counter.abort();
    d.shutdown().await.expect("clean shutdown");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_vanishing_mid_request_disturbs_nothing() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("a", "b"));
    let c = client(&[d.endpoint()]).await;
    within(20, "info", wait_info(&c, "a")).await;
    // A switch that needs an estimate (gkd at 12×12 is not prepared yet),
    // from a client that disappears while it is being estimated.
    let leaving = client(&[d.endpoint()]).await;
    let request = v1::SwitchRequest {
        method: "gkd".into(),
        ..to(Level::new(12, 12))
    };
    let pending = {
        let session = leaving.session.clone();
        let key = keys::switch(PREFIX, "a");
        tokio::spawn(async move {
            session
                .get(key)
                .payload(request.encode_to_vec())
                .encoding(encoding("lodcloth.v1.SwitchRequest"))
                .timeout(Duration::from_secs(60))
                .await
        })
    };
    tokio::time::sleep(Duration::from_millis(100)).await;
    pending.abort();
    leaving.session.close().await.expect("close the leaving session");
    drop(leaving);
    // The daemon goes on: states flow, and a later switch queues behind the
    // orphaned one and wins.
    let states = collect_states(&c, "a", 1.0).await;
    assert!(
        states.len() >= 30,
        "{} states in 1 s after the client left",
        states.len()
    );
    let reply = within(
        60,
        "switch after",
        c.switch("a", &to(Level::new(16, 16)), Duration::from_secs(50)),
    )
    .await
    .expect("a switch after the client vanished");
    let info = c.info("a").await.expect("info");
    assert_eq!(
        info.coefficient_version, reply.coefficient_version,
        "the last switch is the one applied"
    );
    assert_eq!(
        Level::from_wire(reply.level.as_ref().expect("level")),
        Ok(Level::new(16, 16))
    );
    daemon::assert_after_switch(&collect_states(&c, "a", 0.5).await, &reply);
    d.shutdown().await.expect("clean shutdown");
}

/// The shipped `lodcloth router` on `port`, in its own process, multicast
/// scouting off (from a zenoh config file, so `--zenoh-config` is driven
/// too). Killed when dropped; [`Router::stop`] stops it with SIGTERM.
struct Router(std::process::Child);

impl Router {
    /// Start it and wait until it accepts connections (the port may linger
    /// briefly after the previous router, and then the router exits: retry).
    fn start(port: u16, zenoh_config: &std::path::Path) -> Router {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_lodcloth"))
                .args(["router", "--listen", &format!("tcp/127.0.0.1:{port}"), "--zenoh-config"])
                .arg(zenoh_config)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .expect("lodcloth router");
            loop {
                if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
                    return Router(child);
                }
                if let Ok(Some(status)) = child.try_wait() {
                    assert!(Instant::now() < deadline, "lodcloth router on {port} exits: {status}");
                    break;
                }
                assert!(Instant::now() < deadline, "lodcloth router on {port} does not listen");
                std::thread::sleep(Duration::from_millis(20));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// SIGTERM; the router must close its session and exit 0.
    fn stop(mut self) {
        let pid = self.0.id().to_string();
        let sent = std::process::Command::new("kill").args(["-TERM", &pid]).status();
        assert!(sent.is_ok_and(|s| s.success()), "kill -TERM {pid}");
        let deadline = Instant::now() + Duration::from_secs(10);
        let status = loop {
            if let Some(status) = self.0.try_wait().expect("router status") {
                break status;
            }
            assert!(Instant::now() < deadline, "lodcloth router ignores SIGTERM");
            std::thread::sleep(Duration::from_millis(10));
        };
        assert!(status.success(), "lodcloth router stopped with {status}");
    }
}

impl Drop for Router {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn publishing_resumes_by_itself_after_the_router_restarts() {
    let _serial = daemon::serial().await;
    let port = daemon::free_port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let dir = tempfile::tempdir().expect("temp dir");
    let router_config = dir.path().join("router.json5");
    std::fs::write(&router_config, "{ scouting: { multicast: { enabled: false } } }\n").expect("router config");
    let first = tokio::task::block_in_place(|| Router::start(port, &router_config));
    // The daemon and the client both in client mode, through the router.
    let text = config_text(daemon::free_port(), dir.path(), ("a", "b"))
        .replace(
            "mode = \"peer\"",
            &format!("mode = \"client\"\nconnect = [\"{endpoint}\"]"),
        )
        .replace("listen = [", "# listen = [");
    let d = Daemon::run(port, &text, dir);
    let options = ClientOptions {
        client_mode: true,
        ..ClientOptions::new(std::slice::from_ref(&endpoint))
    };
    let mut c = within(20, "client", Client::open(&options, PREFIX))
        .await
        .expect("client");
    c.timeout = Duration::from_secs(3);
    let info = within(30, "info through the router", wait_info(&c, "a")).await;
    let (arrivals, counter) = count_states(&c, "a");
    let before = collect_states(&c, "a", 1.0).await;
    let first_seen = Instant::now();
    let frame_before = before.last().map(|s| s.frame);
    assert!(
        !arrivals.lock().expect("arrivals").is_empty(),
        "states through the router"
    );

    let stopped = Instant::now();
    tokio::task::block_in_place(|| first.stop());
    tokio::time::sleep(Duration::from_secs(1)).await;
    let restarted = Instant::now();
    let _second = tokio::task::block_in_place(|| Router::start(port, &router_config));
    let deadline = Instant::now() + Duration::from_secs(30);
    let resumed = loop {
        let first_after = arrivals
            .lock()
            .expect("arrivals")
            .iter()
            .copied()
            .find(|&t| t > restarted);
        if let Some(t) = first_after {
            break t;
        }
        assert!(Instant::now() < deadline, "no state within 30 s of the router restart");
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    let last_before = arrivals
        .lock()
        .expect("arrivals")
        .iter()
        .copied()
        .rfind(|&t| t <= stopped + Duration::from_millis(50))
        .expect("states before the stop");
    println!(
        "router down {:.2} s; states resumed {:.2} s after its restart; gap seen by the client {:.2} s",
        (restarted - stopped).as_secs_f64(),
        (resumed - restarted).as_secs_f64(),
        (resumed - last_before).as_secs_f64()
    );
    // Nothing lost: the same instances, the same coefficients, still stepping.
    let lists = within(10, "list after", c.list()).await.expect("list");
    let names: Vec<&str> = lists
        .iter()
        .flat_map(|l| l.instances.iter().map(|i| i.instance.as_str()))
        .collect();
    assert_eq!(names, ["a", "b"]);
    let after = within(10, "info after", c.info("a")).await.expect("info after");
    assert!(after.coefficient_version >= info.coefficient_version);
    let states = collect_states(&c, "a", 1.0).await;
    assert!(
        states.len() >= 30,
        "{} states in the second after recovery",
        states.len()
    );
    // The cloth went on stepping through the outage (not restarted): its
    // step count covers the whole time since the first state.
    let first_frame = frame_before.expect("a frame before the stop");
    let last = states.last().expect("a state");
    let stepped = (last.frame - first_frame) as f64 * after.dt;
    let elapsed = (Instant::now() - first_seen).as_secs_f64();
    assert!(
        stepped > 0.8 * elapsed,
        "{stepped:.2} s simulated in {elapsed:.2} s: the instance lost time or restarted"
    );
    let alive = c.alive().await.expect("liveliness");
    assert_eq!(alive, ["a", "b"], "liveliness tokens come back");
    counter.abort();
    d.shutdown().await.expect("clean shutdown");
}

/// The latest metrics of `instance` once `pred` holds, within `seconds`.
async fn metrics_until(c: &Client, instance: &str, seconds: f64, pred: impl Fn(&v1::Metrics) -> bool) -> v1::Metrics {
    let sub = c
        .session
        .declare_subscriber(keys::metrics(PREFIX, instance))
        .await
        .expect("metrics subscriber");
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut last = None;
    while Instant::now() < end {
        let Ok(Ok(s)) = tokio::time::timeout(end.saturating_duration_since(Instant::now()), sub.recv_async()).await
        else {
            break;
        };
        let m = v1::Metrics::decode(s.payload().to_bytes().as_ref()).expect("Metrics");
        if pred(&m) {
            return m;
        }
        last = Some(m);
    }
    panic!("metrics of {instance} never satisfied the condition within {seconds} s; last: {last:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_diverging_instance_is_rolled_back_then_halted_and_reported_while_others_step_on() {
    let _serial = daemon::serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    // Explicit Euler at 25× its predicted limit, forced past the check.
    let scene = std::fs::read_to_string(daemon::scene_path("paper-1-top-edge.toml"))
        .expect("scene")
        .replace(
            "integrator = \"rk4\"",
            "integrator = \"explicit_euler\"\nforce_unstable = true",
        )
        .replace("dt = 2e-4", "dt = 5e-3");
    let scene_file = dir.path().join("unstable.toml");
    std::fs::write(&scene_file, scene).expect("write scene");
    // Snapshots every 0.2 s: a halted instance's must not be replaced by
    // its diverged state.
    let snapshots = dir.path().join("snapshots");
    let taken = |instance: &str| {
        snapshot::read(&snapshots, instance)
            .expect("a readable snapshot")
            .map(|s| (s.saved_unix_ms, s.snapshot.frame))
    };
    let port = daemon::free_port();
    let text = config_text(port, dir.path(), ("a", "b"))
        + &format!(
            r#"
[[instances]]
name = "bad"
scene = "{}"
reference = "16x16"
levels = ["8x8"]
start = "8x8"
method = "same"
dt = 5e-3
[snapshots]
dir = "{}"
interval = 0.2
"#,
            scene_file.display(),
            snapshots.display()
        );
    let d = Daemon::run(port, &text, dir);
    let c = client(&[d.endpoint()]).await;
    within(20, "info a", wait_info(&c, "a")).await;
    let (arrivals, counter) = count_states(&c, "a");
    let bad_states = Arc::new(Mutex::new(Vec::new()));
    let bad_counter = {
        let sub = c
            .session
            .declare_subscriber(keys::state(PREFIX, "bad"))
            .await
            .expect("subscriber");
        let sink = bad_states.clone();
        tokio::spawn(async move {
            while let Ok(s) = sub.recv_async().await {
                let state = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
                sink.lock().expect("states").push(state);
            }
        })
    };
    let halted = within(30, "halt", metrics_until(&c, "bad", 25.0, |m| !m.halted.is_empty())).await;
    println!(
        "bad: {} divergences, {} rollbacks, halted: {}",
        halted.divergences, halted.rollbacks, halted.halted
    );
    assert!(halted.paused, "a halted instance no longer steps");
    assert_eq!(halted.divergences, 3);
    assert_eq!(halted.rollbacks, 2, "two rollbacks, then the third divergence halts");
    assert!(halted.halted.contains("diverged 3 times"), "{}", halted.halted);
    let info = c.info("bad").await.expect("info of the halted instance");
    assert_eq!(info.halted, halted.halted, "info reports the halt too");
    assert!(info.paused);

    let (bad_before, a_before) = (taken("bad"), taken("a"));

    // The others step on at their rate, untouched.
    let t0 = Instant::now();
    tokio::time::sleep(Duration::from_secs(2)).await;
    // Snapshots went on for "a" but not for the halted "bad": its last one,
    // if any, is from before the halt.
    assert_eq!(taken("bad"), bad_before, "the halted instance's snapshot was replaced");
    if let Some((_, frame)) = bad_before {
        assert!(
            frame <= halted.frame,
            "snapshot at frame {frame}, halted at {}",
            halted.frame
        );
    }
    assert!(taken("a") > a_before, "snapshots stopped for the others: {a_before:?}");
    let rate = rate_between(&arrivals, t0, Instant::now());
    assert!(rate >= 45.0, "a publishes {rate:.1}/s beside the diverging instance");
    let a = metrics_until(&c, "a", 5.0, |_| true).await;
    assert_eq!((a.divergences, a.halted.as_str()), (0, ""));
    // Reset restarts the halted instance (which here diverges again).
    c.control("bad", v1::control_request::Action::Reset)
        .await
        .expect("reset");
    let resumed = c
        .control("bad", v1::control_request::Action::Resume)
        .await
        .expect("resume");
    assert!(!resumed.paused);
    let again = within(30, "halt again", metrics_until(&c, "bad", 25.0, |m| m.divergences >= 6)).await;
    assert!(!again.halted.is_empty());

    // No non-finite position was ever published.
    bad_counter.abort();
    let states = std::mem::take(&mut *bad_states.lock().expect("states"));
    assert!(!states.is_empty(), "the diverging instance published states");
    for s in &states {
        let pos = lodcloth::proto::unpack_positions(&s.positions).expect("positions");
        assert!(
            pos.iter().all(|x| x.is_finite()),
            "a published state of 'bad' has non-finite positions"
        );
    }
    counter.abort();
    d.shutdown().await.expect("clean shutdown");
}

/// What an accepted input must be, checked apart from `Input::check`.
fn assert_input_in_range(input: &lodcloth::touch::Input) {
    use lodcloth::touch::{Input, Patch};
    let on_cloth =
        |p: &Patch| (0.0..=1.0).contains(&p.u) && (0.0..=1.0).contains(&p.v) && p.radius >= 0.0 && p.radius.is_finite();
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    let ok = match input {
        Input::Grab {
            at,
            target,
            stiffness,
            damping,
            ..
        } => {
            on_cloth(at)
                && target.is_none_or(|t| finite(&t))
                && *stiffness > 0.0
                && finite(&[*stiffness, *damping])
                && *damping >= 0.0
        }
        Input::Move { target, .. } => finite(target),
        Input::MovePin { offset, seconds, .. } => finite(offset) && *seconds >= 0.0 && seconds.is_finite(),
        Input::Wind {
            velocity,
            gust,
            gust_hz,
        } => finite(velocity) && (0.0..=1.0).contains(gust) && gust_hz.is_finite() && *gust_hz >= 0.0,
        Input::Impulse { at, impulse } => on_cloth(at) && finite(impulse),
        Input::Release { .. } | Input::ReleaseAll | Input::SceneWind => true,
    };
    assert!(ok, "accepted out of range: {input:?}");
}
