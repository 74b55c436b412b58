//! A daemon on loopback for the integration tests that talk to it over
//! zenoh (`tests/service.rs`, `tests/clients.rs`), and the client helpers
//! they share. Every await has a timeout.
#![allow(dead_code)]

use std::future::Future;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use prost::Message;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

use lodcloth::plan::Level;
use lodcloth::proto::{v1, WireLevel};
use lodcloth::service::client::{Client, ClientError};
use lodcloth::service::config::ServiceConfig;
use lodcloth::service::{keys, ServiceError};

pub const PREFIX: &str = "lodtest";

/// Fail the test instead of hanging.
pub async fn within<T>(seconds: u64, what: &str, f: impl Future<Output = T>) -> T {
    match tokio::time::timeout(Duration::from_secs(seconds), f).await {
        Ok(v) => v,
        Err(_) => panic!("{what}: no result within {seconds} s"),
    }
}

/// A free loopback port for a test daemon (or its HTTP or QUIC endpoint),
/// below the kernel's ephemeral range. A daemon listens some time after
/// this returns while the test's client starts connecting at once: with a
/// port from the ephemeral range an outgoing connection (that client's own
/// included) may be given it as its source port in between, and the daemon
/// then cannot listen, or the client connects to itself (TCP's simultaneous
/// open). Ports are handed out in turn from a start that differs between
/// processes, each free for TCP and UDP when handed out.
pub fn free_port() -> u16 {
    use std::sync::atomic::{AtomicU32, Ordering};
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let low = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|r| r.split_whitespace().next()?.parse::<u32>().ok())
        .unwrap_or(32768);
    let first = 10_000;
    let span = low.saturating_sub(first).max(1000);
    let start = std::process::id().wrapping_mul(7919);
    for _ in 0..span {
        let k = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = (first + start.wrapping_add(k) % span) as u16;
        let free = std::net::TcpListener::bind(("127.0.0.1", port)).is_ok()
            && std::net::UdpSocket::bind(("127.0.0.1", port)).is_ok();
        if free {
            return port;
        }
    }
    panic!("no free loopback port between {first} and {}", first + span)
}

pub fn scene_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("config/scenes")
        .join(name)
}

/// What every test daemon shares: a peer on loopback `port`, multicast
/// off, two stepping threads, 50 states a second.
pub fn config_header(port: u16, cache: &std::path::Path) -> String {
    format!(
        r#"
prefix = "{PREFIX}"
cache = "{cache}"
[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false
[engine]
threads = 2
publish_hz = 50.0
"#,
        cache = cache.display()
    )
}

/// A small daemon: paper scene 1 with a 24×24 reference at levels 8², 12²,
/// 16² (method `same`: preparation takes well under a second), and a
/// fixed-dt instance whose finest level is unstable at that dt. The
/// reference covers the first second of the scene's 6 s loop.
pub fn config_text(port: u16, cache: &std::path::Path, names: (&str, &str)) -> String {
    config_text_recording(port, cache, names, 5000)
}

/// [`config_text`] with `reference_steps` recorded (30000: the whole loop,
/// so every state carries the shadow reference).
pub fn config_text_recording(port: u16, cache: &std::path::Path, names: (&str, &str), reference_steps: u64) -> String {
    config_header(port, cache)
        + &format!(
            r#"
[estimation]
reference_steps = {reference_steps}
metric_stride = 25
estimate_stride = 25
[[instances]]
name = "{a}"
scene = "{scene1}"
reference = "24x24"
levels = ["8x8", "12x12", "16x16"]
start = "16x16"
method = "same"
shadow_reference = true
[[instances]]
name = "{b}"
scene = "{scene1}"
reference = "24x24"
levels = ["8x8", "16x16"]
start = "8x8"
method = "same"
dt = 2.5e-3
publish_hz = 20.0
"#,
            a = names.0,
            b = names.1,
            scene1 = scene_path("paper-1-top-edge.toml").display(),
        )
}

pub struct Daemon {
    pub port: u16,
    stop: Option<oneshot::Sender<()>>,
    task: JoinHandle<Result<(), ServiceError>>,
    _dir: tempfile::TempDir,
}

impl Daemon {
    pub fn start(names: (&str, &str)) -> Daemon {
        Daemon::start_recording(names, 5000)
    }

    /// [`Daemon::start`] with `reference_steps` of reference recorded.
    pub fn start_recording(names: (&str, &str), reference_steps: u64) -> Daemon {
        let dir = tempfile::tempdir().expect("temp dir");
        let port = free_port();
        let text = config_text_recording(port, dir.path(), names, reference_steps);
        Daemon::run(port, &text, dir)
    }

    /// Serve `text` (which listens on `port`); `dir` lives as long as the daemon.
    pub fn run(port: u16, text: &str, dir: tempfile::TempDir) -> Daemon {
        let config = ServiceConfig::from_toml(text, "test").expect("valid config");
        let (tx, rx) = oneshot::channel();
        // A daemon that stops on its own says why, or a test waiting for
        // its replies would only time out.
        let task = tokio::spawn(async move {
            let result = lodcloth::service::run(config, async {
                let _ = rx.await;
            })
            .await;
            if let Err(e) = &result {
                eprintln!("the test daemon on port {port} stopped: {e}");
            }
            result
        });
        Daemon {
            port,
            stop: Some(tx),
            task,
            _dir: dir,
        }
    }

    pub fn endpoint(&self) -> String {
        format!("tcp/127.0.0.1:{}", self.port)
    }

    pub async fn shutdown(mut self) -> Result<(), ServiceError> {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        within(20, "graceful shutdown", self.task).await.expect("daemon task")
    }
}

pub async fn client(endpoints: &[String]) -> Client {
    // The daemon may still be opening its listener.
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match Client::connect(endpoints, PREFIX).await {
            Ok(mut c) => {
                c.timeout = Duration::from_secs(5);
                return c;
            }
            Err(e) if Instant::now() > deadline => panic!("cannot connect to {endpoints:?}: {e}"),
            Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
        }
    }
}

/// Info once the daemon answers.
pub async fn wait_info(c: &Client, instance: &str) -> v1::InstanceInfo {
    let deadline = Instant::now() + Duration::from_secs(15);
    loop {
        match c.info(instance).await {
            Ok(i) => return i,
            Err(e) if Instant::now() > deadline => panic!("info of {instance}: {e}"),
            Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
        }
    }
}

/// States of `instance` received for `seconds`.
pub async fn collect_states(c: &Client, instance: &str, seconds: f64) -> Vec<v1::State> {
    let sub = c
        .session
        .declare_subscriber(keys::state(PREFIX, instance))
        .await
        .expect("subscriber");
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut out = Vec::new();
    // The deadline is checked apart from the timeout: a subscriber with a
    // backlog is always ready, and a timeout polls its future first.
    while Instant::now() < end {
        let Ok(Ok(s)) = tokio::time::timeout(end.saturating_duration_since(Instant::now()), sub.recv_async()).await
        else {
            break;
        };
        out.push(v1::State::decode(s.payload().to_bytes().as_ref()).expect("a State"));
    }
    out
}

pub fn refused_code(r: Result<v1::SwitchReply, ClientError>) -> (String, String) {
    match r {
        Err(ClientError::Refused { code, message }) => (code, message),
        other => panic!("expected a refusal, got {other:?}"),
    }
}

pub fn level_of(s: &v1::State) -> Level {
    Level::from_wire(s.level.as_ref().expect("level")).expect("a valid level")
}

/// `states`, collected by a subscriber declared after `reply` came back,
/// against that switch: each is at its level and coefficient version,
/// except the switch's own last frame of the level before it. A switch
/// publishes two transition snapshots in order, the old level's last and
/// the new level's first (proto: `State.transition`); they are queued
/// before the reply is sent and put on the bus by the instance's publishing
/// task, so on a busy machine a subscriber declared after the reply can
/// still receive the old one. Anything else at another level (a switch
/// landing after this one, a state stepped after it at the old level)
/// fails. At least one state is at the new level.
pub fn assert_after_switch(states: &[v1::State], reply: &v1::SwitchReply) {
    let level = Level::from_wire(reply.level.as_ref().expect("level")).expect("a valid level");
    let previous = Level::from_wire(reply.previous.as_ref().expect("previous")).expect("a valid level");
    let version = reply.coefficient_version;
    let switched = |s: &v1::State| level_of(s) == level && s.coefficient_version == version;
    let its_last_old = |s: &v1::State| {
        s.transition && s.frame == reply.frame && level_of(s) == previous && s.coefficient_version + 1 == version
    };
    assert!(
        states.iter().any(switched),
        "none of {} states after the switch is at {level}, version {version}",
        states.len()
    );
    if let Some(s) = states.iter().find(|s| its_last_old(s)) {
        println!(
            "the switch's last frame at {previous} (frame {}) reached a subscriber declared after its reply",
            s.frame
        );
    }
    for s in states {
        assert!(
            switched(s) || its_last_old(s),
            "after the switch to {level} (version {version}, frame {}) a state at {} (version {}, frame {}, transition {})",
            reply.frame,
            level_of(s),
            s.coefficient_version,
            s.frame,
            s.transition
        );
    }
}

static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Held for the whole of a bus test, so they run one at a time (tests/bus.rs):
/// several measure rates and latencies that a test beside them would disturb.
pub async fn serial() -> tokio::sync::MutexGuard<'static, ()> {
    SERIAL.lock().await
}

/// [`serial`] for a test without a runtime.
pub fn serial_blocking() -> tokio::sync::MutexGuard<'static, ()> {
    SERIAL.blocking_lock()
}

/// `GET path` from an HTTP server on loopback: (status, headers, body).
/// HTTP/1.0, so the server closes the connection after the answer.
pub async fn http_get(addr: std::net::SocketAddr, path: &str) -> std::io::Result<(u16, String, String)> {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut s = tokio::net::TcpStream::connect(addr).await?;
    s.write_all(format!("GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n").as_bytes())
        .await?;
    let mut text = String::new();
    s.read_to_string(&mut text).await?;
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    Ok((status, head.to_string(), body.to_string()))
}

/// A grab of `at` without a target (the hand closes where the patch is).
pub fn grab_where_it_is(id: u32, at: lodcloth::touch::Patch, stiffness: f64, damping: f64) -> v1::InputRequest {
    v1::InputRequest {
        action: Some(v1::input_request::Action::Grab(v1::input_request::Grab {
            id,
            at: Some(v1::Patch {
                u: at.u,
                v: at.v,
                radius: at.radius,
            }),
            target: None,
            stiffness,
            damping,
        })),
    }
}
