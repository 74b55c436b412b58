//! The operations endpoint of a live daemon (`[http] listen`): `/metrics`
//! in the OpenMetrics text format with what the daemon did counted as it
//! happened, `/healthz`, and a start that fails naming a taken address.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use lodcloth::plan::Level;
use lodcloth::proto::{v1, WireLevel};
use lodcloth::service::config::ServiceConfig;
use lodcloth::service::keys;

use crate::daemon::{
    client, config_text, free_port, http_get, refused_code, serial, wait_info, within, Daemon, PREFIX,
};

/// The samples of an OpenMetrics text, `name{labels}` → value, after
/// checking its grammar: every sample belongs to a family declared with
/// `# TYPE` and `# HELP` before it, label values are quoted, and the text
/// ends with `# EOF`.
fn parse_openmetrics(text: &str) -> BTreeMap<String, f64> {
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.last(), Some(&"# EOF"), "the text must end with # EOF");
    let mut typed = BTreeMap::new();
    let mut helped = std::collections::BTreeSet::new();
    let mut samples = BTreeMap::new();
    for line in &lines[..lines.len() - 1] {
        if let Some(rest) = line.strip_prefix("# TYPE ") {
            let (name, kind) = rest.split_once(' ').expect("# TYPE name kind");
            assert!(
                ["gauge", "counter", "info", "unknown"].contains(&kind),
                "unknown type in {line}"
            );
            typed.insert(name.to_string(), kind.to_string());
        } else if let Some(rest) = line.strip_prefix("# HELP ") {
            helped.insert(rest.split_once(' ').expect("# HELP name text").0.to_string());
        } else if line.starts_with("# UNIT ") {
        } else {
            let (series, value) = line
                .rsplit_once(' ')
                .unwrap_or_else(|| panic!("sample without value: {line}"));
            let value: f64 = value.parse().unwrap_or_else(|_| panic!("not a number in {line}"));
            let name = series.split('{').next().unwrap();
            if let Some(labels) = series.strip_prefix(name).filter(|l| !l.is_empty()) {
                assert!(labels.starts_with('{') && labels.ends_with('}'), "labels of {line}");
                for pair in labels[1..labels.len() - 1].split("\",") {
                    let (k, v) = pair.split_once('=').unwrap_or_else(|| panic!("label in {line}"));
                    assert!(k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'), "{line}");
                    assert!(v.starts_with('"'), "unquoted label value in {line}");
                }
            }
            let family = typed
                .keys()
                .find(|f| name == f.as_str() || name.strip_prefix(f.as_str()) == Some("_total"))
                .unwrap_or_else(|| panic!("{name} has no # TYPE before it"));
            assert!(helped.contains(family), "{family} has no # HELP");
            if typed[family] == "counter" {
                assert!(name.ends_with("_total"), "counter sample {name} must end in _total");
                assert!(value >= 0.0, "{line}");
            }
            samples.insert(series.to_string(), value);
        }
    }
    samples
}

async fn scrape(addr: SocketAddr) -> BTreeMap<String, f64> {
    let (status, head, body) = within(10, "GET /metrics", http_get(addr, "/metrics"))
        .await
        .expect("GET /metrics");
    assert_eq!(status, 200, "{head}\n{body}");
    assert!(
        head.to_ascii_lowercase()
            .contains("content-type: application/openmetrics-text; version=1.0.0"),
        "{head}"
    );
    parse_openmetrics(&body)
}

fn value(m: &BTreeMap<String, f64>, series: &str) -> f64 {
    *m.get(series)
        .unwrap_or_else(|| panic!("no {series} in {:#?}", m.keys().collect::<Vec<_>>()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn metrics_report_each_instance_and_count_what_the_daemon_did() {
    let _serial = serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let http: SocketAddr = format!("127.0.0.1:{}", free_port()).parse().unwrap();
    let text = config_text(port, dir.path(), ("op", "quiet")) + &format!("[http]\nlisten = \"{http}\"\n");
    let d = Daemon::run(port, &text, dir);
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "op").await;

    // Healthy once both instances publish metrics.
    let deadline = Instant::now() + Duration::from_secs(20);
    let health = loop {
        let (status, _, body) = within(10, "GET /healthz", http_get(http, "/healthz"))
            .await
            .expect("GET /healthz");
        let h: serde_json::Value = serde_json::from_str(&body).expect("healthz JSON");
        if status == 200
            && h["instances"]
                .as_array()
                .is_some_and(|a| a.iter().all(|i| !i["level"].is_null()))
        {
            break h;
        }
        assert!(Instant::now() < deadline, "not healthy within 20 s: {status} {body}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(health["status"], "ok");
    assert_eq!(health["version"], lodcloth::VERSION);
    let names: Vec<&str> = health["instances"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["instance"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["op", "quiet"]);

    // Nobody subscribes to "quiet".
    let sub = c
        .session
        .declare_subscriber(keys::state(PREFIX, "op"))
        .await
        .expect("subscriber");
    let mut received = 0u32;
    while received < 20 {
        within(10, "states of op", sub.recv_async()).await.expect("a state");
        received += 1;
    }
    let m = scrape(http).await;
    assert_eq!(value(&m, "lodcloth_state_subscribed{instance=\"op\"}"), 1.0);
    assert_eq!(value(&m, "lodcloth_state_subscribed{instance=\"quiet\"}"), 0.0);
    let op_states = value(&m, "lodcloth_states_published_total{instance=\"op\"}");
    assert!(op_states >= 20.0, "{received} states received, {op_states} counted");
    // quiet's states are skipped but for a switch's two transition states,
    // which are always sent: its start level's estimate going live (a
    // switch to the same level) may have sent them by now.
    let quiet_states = value(&m, "lodcloth_states_published_total{instance=\"quiet\"}");
    assert!(quiet_states <= 2.0, "{quiet_states} states of quiet published");
    assert!(value(&m, "lodcloth_metrics_published_total{instance=\"quiet\"}") >= 1.0);
    assert!(value(&m, "lodcloth_real_time_factor{instance=\"op\"}") > 0.0);
    let cost = value(&m, "lodcloth_step_cost_seconds{instance=\"op\"}");
    assert!(cost > 0.0 && cost < 0.1, "step cost {cost} s");
    assert_eq!(value(&m, "lodcloth_time_step_seconds{instance=\"quiet\"}"), 2.5e-3);
    assert_eq!(
        value(
            &m,
            "lodcloth_instance_info{instance=\"op\",level=\"16x16\",method=\"same\"}"
        ),
        1.0
    );
    assert_eq!(value(&m, "lodcloth_halted{instance=\"op\"}"), 0.0);
    assert_eq!(
        value(&m, "lodcloth_refusals_total{code=\"CODE_LEVEL_NOT_ALLOWED\"}"),
        0.0
    );
    assert_eq!(value(&m, "lodcloth_switches_total{instance=\"op\"}"), 0.0);
    assert_eq!(
        value(
            &m,
            &format!(
                "lodcloth_build_info{{version=\"{}\",revision=\"{}\"}}",
                env!("CARGO_PKG_VERSION"),
                lodcloth::REVISION
            )
        ),
        1.0
    );

    // A refused switch is counted by its code, a done one per instance, and
    // the info metric follows the level.
    let t = Duration::from_secs(30);
    let level = |nx, ny| v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(Level::new(nx, ny).to_wire())),
        method: String::new(),
    };
    let (code, _) = refused_code(c.switch("op", &level(17, 17), t).await);
    assert_eq!(code, "CODE_LEVEL_NOT_ALLOWED");
    let (code, _) = refused_code(c.switch("op", &level(17, 17), t).await);
    assert_eq!(code, "CODE_LEVEL_NOT_ALLOWED");
    within(60, "switch", c.switch("op", &level(8, 8), Duration::from_secs(60)))
        .await
        .expect("switch accepted");
    let deadline = Instant::now() + Duration::from_secs(10);
    let m = loop {
        let m = scrape(http).await;
        if m.contains_key("lodcloth_instance_info{instance=\"op\",level=\"8x8\",method=\"same\"}") {
            break m;
        }
        assert!(Instant::now() < deadline, "the level label never became 8x8");
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    assert_eq!(
        value(&m, "lodcloth_refusals_total{code=\"CODE_LEVEL_NOT_ALLOWED\"}"),
        2.0
    );
    assert_eq!(value(&m, "lodcloth_refusals_total{code=\"CODE_BUSY\"}"), 0.0);
    assert_eq!(value(&m, "lodcloth_switches_total{instance=\"op\"}"), 1.0);
    assert_eq!(value(&m, "lodcloth_switches_total{instance=\"quiet\"}"), 0.0);
    assert!(value(&m, "lodcloth_predicted_error{instance=\"op\"}") > 0.0);
    assert!(value(&m, "lodcloth_states_published_total{instance=\"op\"}") > op_states);
    assert!(value(&m, "lodcloth_states_published_total{instance=\"quiet\"}") <= 2.0);
    // Preparation progress: op's three configured levels, 8x8 among the prepared.
    assert_eq!(value(&m, "lodcloth_levels{instance=\"op\"}"), 3.0);
    assert_eq!(value(&m, "lodcloth_levels{instance=\"quiet\"}"), 2.0);
    let prepared = value(&m, "lodcloth_levels_prepared{instance=\"op\"}");
    assert!((1.0..=3.0).contains(&prepared), "{prepared} levels of op prepared");

    let (status, _, _) = http_get(http, "/nope").await.expect("GET /nope");
    assert_eq!(status, 404);
    drop(sub);
    drop(c);
    d.shutdown().await.expect("clean shutdown");
    assert!(
        http_get(http, "/metrics").await.is_err(),
        "the endpoint must close with the daemon"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_taken_http_address_fails_the_start_naming_it() {
    let _serial = serial().await;
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let http = taken.local_addr().unwrap();
    let dir = tempfile::tempdir().expect("temp dir");
    let text = config_text(free_port(), dir.path(), ("a", "b")) + &format!("[http]\nlisten = \"{http}\"\n");
    let config = ServiceConfig::from_toml(&text, "test").expect("valid config");
    let err = within(20, "start", lodcloth::service::run(config, std::future::pending()))
        .await
        .expect_err("the address is taken");
    let message = err.to_string();
    assert!(message.starts_with(&format!("http.listen {http}: ")), "{message}");

    // And a malformed address is a config problem named by its path.
    let bad = config_text(free_port(), dir.path(), ("a", "b")) + "[http]\nlisten = \"localhost\"\n";
    let err = ServiceConfig::from_toml(&bad, "test").expect_err("not an address");
    assert!(
        err.to_string()
            .contains("http.listen: 'localhost' is not an address:port"),
        "{err}"
    );
}

/// `lodcloth` itself, as an operator runs it.
fn lodcloth(args: &[&str], env: &[(&str, &str)]) -> std::process::Output {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_lodcloth"));
    cmd.args(args);
    for var in [
        "LODCLOTH_CONFIG",
        "LODCLOTH_HTTP",
        "LODCLOTH_STATE_DIR",
        "LODCLOTH_CACHE_DIR",
        "LODCLOTH_SNAPSHOT_DIR",
        "STATE_DIRECTORY",
    ] {
        cmd.env_remove(var);
    }
    cmd.envs(env.iter().copied());
    cmd.output().expect("running lodcloth")
}

fn stdout(o: &std::process::Output) -> String {
    assert!(
        o.status.success(),
        "exit {:?}\n{}\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The line of `serve --check` that starts with `key`.
fn check_line<'a>(text: &'a str, key: &str) -> &'a str {
    text.lines()
        .map(str::trim)
        .find(|l| l.starts_with(key))
        .unwrap_or_else(|| panic!("no '{key}' line in\n{text}"))
}

#[test]
fn state_directories_and_the_http_address_come_from_the_environment_under_a_service_manager() {
    // The shipped default: relative to the working directory.
    let text = stdout(&lodcloth(&["serve", "--check"], &[]));
    assert!(text.starts_with("config/default.toml: valid"), "{text}");
    assert_eq!(check_line(&text, "cache"), "cache      out/cache");
    assert_eq!(check_line(&text, "snapshots"), "snapshots  out/snapshots");
    assert_eq!(
        check_line(&text, "http"),
        "http       http://127.0.0.1:7460/metrics, http://127.0.0.1:7460/healthz"
    );
    assert_eq!(
        text.lines().filter(|l| l.trim_start().starts_with("instance")).count(),
        6
    );

    // systemd's StateDirectory=: every relative state directory moves under it.
    let text = stdout(&lodcloth(
        &["serve", "--check"],
        &[("STATE_DIRECTORY", "/var/lib/lodcloth"), ("LODCLOTH_HTTP", "off")],
    ));
    assert_eq!(check_line(&text, "cache"), "cache      /var/lib/lodcloth/out/cache");
    assert_eq!(
        check_line(&text, "snapshots"),
        "snapshots  /var/lib/lodcloth/out/snapshots"
    );
    assert_eq!(check_line(&text, "http"), "http       off");

    // The operator's own variables win over systemd's, the command line over both.
    let text = stdout(&lodcloth(
        &["serve", "--check", "--http", "127.0.0.1:9999"],
        &[
            ("STATE_DIRECTORY", "/var/lib/lodcloth"),
            ("LODCLOTH_STATE_DIR", "/srv/cloth"),
            ("LODCLOTH_CACHE_DIR", "/cache/lodcloth"),
            ("LODCLOTH_HTTP", "127.0.0.1:1234"),
        ],
    ));
    assert_eq!(check_line(&text, "cache"), "cache      /cache/lodcloth");
    assert_eq!(check_line(&text, "snapshots"), "snapshots  /srv/cloth/out/snapshots");
    assert!(check_line(&text, "http").contains("127.0.0.1:9999/metrics"), "{text}");

    // The config itself from the environment; a snapshot directory turns
    // snapshots on for a config without them.
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("no-snapshots.toml");
    std::fs::write(&path, config_text(free_port(), dir.path(), ("a", "b"))).expect("config");
    let text = stdout(&lodcloth(
        &["serve", "--check"],
        &[
            ("LODCLOTH_CONFIG", path.to_str().unwrap()),
            ("LODCLOTH_SNAPSHOT_DIR", "snaps"),
            ("LODCLOTH_STATE_DIR", "/srv/cloth"),
        ],
    ));
    assert!(text.starts_with(&format!("{}: valid", path.display())), "{text}");
    assert_eq!(check_line(&text, "snapshots"), "snapshots  /srv/cloth/snaps");

    // A bad address is named, and nothing starts.
    let o = lodcloth(&["serve", "--check", "--http", "localhost"], &[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--http: 'localhost' is not an address:port"), "{err}");
}

/// The product's binary offers what a user of the service runs; the
/// studies are the lab's (`lodcloth-lab`), and a study's name is refused.
#[test]
fn the_product_lists_no_study() {
    let help = stdout(&lodcloth(&["--help"], &[]));
    let commands: Vec<&str> = help
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    for command in [
        "serve", "switch", "input", "view", "simulate", "points", "mesh", "inspect",
    ] {
        assert!(commands.contains(&command), "{command} missing from {commands:?}");
    }
    for study in ["experiment", "stability"] {
        assert!(
            !commands.contains(&study),
            "the product offers the study {study}: {commands:?}"
        );
        assert!(
            !lodcloth(&[study, "--help"], &[]).status.success(),
            "{study} still runs"
        );
    }
    let points = stdout(&lodcloth(&["points", "--help"], &[]));
    assert!(points.contains("simulate") && !points.contains("accuracy"), "{points}");
}

#[test]
fn version_names_the_commit_and_completions_and_manual_pages_cover_every_subcommand() {
    let version = stdout(&lodcloth(&["--version"], &[]));
    assert_eq!(version.trim(), format!("lodcloth {}", lodcloth::VERSION));
    // Built from this checkout: the revision is HEAD's (tests run in the
    // package root; a tarball without .git says `unknown`).
    let head = std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    match head {
        Some(h) => assert_eq!(
            lodcloth::REVISION,
            h,
            "rebuild after a commit: build.rs watches .git/HEAD"
        ),
        None => assert_eq!(lodcloth::REVISION, "unknown"),
    }

    let bash = stdout(&lodcloth(&["completions", "bash"], &[]));
    for word in ["serve", "switch", "--max-error", "--http", "--state-dir"] {
        assert!(bash.contains(word), "bash completion lacks {word}");
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("man1");
    stdout(&lodcloth(&["man", "--out", out.to_str().unwrap()], &[]));
    for page in [
        "lodcloth.1",
        "lodcloth-serve.1",
        "lodcloth-switch.1",
        "lodcloth-simulate.1",
    ] {
        let text = std::fs::read_to_string(out.join(page)).unwrap_or_else(|e| panic!("{page}: {e}"));
        assert!(
            text.starts_with(".ie \\n(.g .ds Aq") || text.contains(".TH"),
            "{page} is not roff"
        );
    }
    let serve = std::fs::read_to_string(out.join("lodcloth-serve.1")).unwrap();
    assert!(
        serve.contains("LODCLOTH_CONFIG"),
        "the serve page names its environment"
    );
}

#[test]
fn background_work_runs_in_the_idle_class_and_a_bad_class_is_named() {
    // On Linux, without privileges: SCHED_IDLE for the calling thread only.
    let (class, policy) = std::thread::spawn(|| {
        let class = lodcloth::service::lower_priority();
        // SAFETY: sched_getscheduler(0) queries the calling thread.
        #[cfg(target_os = "linux")]
        let policy = unsafe { libc::sched_getscheduler(0) };
        #[cfg(not(target_os = "linux"))]
        let policy = -1;
        (class, policy)
    })
    .join()
    .expect("thread");
    if cfg!(target_os = "linux") {
        assert_eq!(class, lodcloth::service::Background::Idle);
        #[cfg(target_os = "linux")]
        assert_eq!(policy, libc::SCHED_IDLE, "the thread is not SCHED_IDLE");
    }
    // SAFETY: as above, for this (test) thread, which was not lowered.
    #[cfg(target_os = "linux")]
    assert_eq!(unsafe { libc::sched_getscheduler(0) }, libc::SCHED_OTHER);

    let dir = tempfile::tempdir().expect("temp dir");
    let text =
        config_text(free_port(), dir.path(), ("a", "b")).replace("[engine]\n", "[engine]\nbackground = \"low\"\n");
    let err = ServiceConfig::from_toml(&text, "test").expect_err("not a class");
    assert!(
        err.to_string()
            .contains("engine.background: 'low' is not one of idle, nice"),
        "{err}"
    );
}
