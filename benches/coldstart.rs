//! Cold start of the default daemon (issue 21): does preparing every level
//! in the background take real time away from the instances?
//!
//! Starts `lodcloth serve --config config/default.toml` in its own process
//! with an empty coefficient cache and no snapshots (a first start), on
//! free loopback ports. A subscriber counts every instance's states; every
//! second `/metrics` is scraped for overruns, lag resets, the real-time
//! factor and how many levels are prepared. `--switch-after` seconds in, a
//! switch to a level not yet prepared is sent and timed. The run ends when
//! every configured level is prepared (or after `--minutes`).
//!
//! Prints the machine, a line per 10 s and a summary (overruns and lag
//! resets during preparation, each second with an overrun beside the
//! host's steal time and how late a 1 ms sleep of the bench's own probe
//! thread woke (a stall the probe shares is the machine's), the lowest
//! one-second state rate of each instance against its configured rate,
//! the switch's answer time, the
//! time to prepare everything); writes `out/coldstart-<class>/coldstart.csv`,
//! `coldstart_rates.svg` (state rates and preparation over time),
//! `coldstart_rtf.svg` (each instance's real-time factor) and
//! `coldstart_stalls.svg` (the probe's lateness, steal time and overruns
//! per second).
//!
//! `cargo bench --bench coldstart -- [--minutes 15] [--switch-after 5]
//! [--switch paper-3=40x40] [--at-once] [--background idle|nice] [--log FILE]
//! [--binary PATH] [--switch-budget SECONDS] [--load BUSY/PERIOD,…]`
//! (`--log`: keep the daemon's log there, else it goes with its temporary
//! directory)
//! (`--at-once`: the switch goes live with the scene's coefficients and its
//! estimate follows in place; `--background` replaces the config's
//! `[engine] background`, to compare the classes; `--binary`: serve with
//! another build of `lodcloth`, the config's keys it knows the same;
//! `--switch-budget`: set the config's `[estimation] switch_budget`, or
//! `none` to leave it out;
//! `--load`: one busy thread per BUSY/PERIOD (ms), for the whole run).

#[path = "../tests/daemon/mod.rs"]
mod daemon;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use lodcloth::output::{line_chart_svg, CsvTable, Series, PALETTE};
use lodcloth::plan::Level;
use lodcloth::proto::{v1, WireLevel};
use lodcloth::service::client::{client_config, Client, ClientOptions};

const PREFIX: &str = "lodcloth";
const CONFIG: &str = "config/default.toml";

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
}

/// `name{labels} value` → value, for the families read here.
fn parse_metrics(text: &str) -> BTreeMap<String, f64> {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.rsplit_once(' '))
        .filter_map(|(series, v)| Some((series.to_string(), v.parse().ok()?)))
        .collect()
}

fn per_instance(m: &BTreeMap<String, f64>, family: &str, instance: &str) -> f64 {
    m.get(&format!("{family}{{instance=\"{instance}\"}}"))
        .copied()
        .unwrap_or(0.0)
}

/// One second of the run.
struct Sample {
    t: f64,
    /// The host's steal time over this second, summed over cores (ms):
    /// time the hypervisor ran something else while this VM's cores wanted
    /// to run.
    steal_ms: f64,
    /// The longest a 1 ms sleep of the bench's own probe thread overslept
    /// in this second (ms). The probe is another process than the daemon:
    /// a stall it shares with every instance is the machine's, not a lock
    /// or a scheduling class inside the daemon.
    probe_late_ms: f64,
    /// Per instance: cumulative overruns, lag resets, states received in
    /// this second, real-time factor, levels prepared.
    overruns: Vec<f64>,
    /// Cumulative passes whose stepping thread woke over 10 ms late
    /// (`lodcloth_stalls_total`: the daemon's own view of the machine's
    /// stalls, beside the probe's).
    stalls: Vec<f64>,
    lag_resets: Vec<f64>,
    states: Vec<f64>,
    rtf: Vec<f64>,
    prepared: f64,
}

/// The daemon's process, stopped (SIGTERM, then killed) when dropped.
struct Daemon(std::process::Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        // SAFETY: kill(2) on our own child's pid has no memory-safety preconditions.
        unsafe {
            libc::kill(self.0.id() as libc::pid_t, libc::SIGTERM);
        }
        let deadline = Instant::now() + Duration::from_secs(20);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .unwrap_or_default()
        .lines()
        .find_map(|l| {
            l.strip_prefix("model name")
                .map(|v| v.trim_start_matches([' ', '\t', ':']).to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into())
}

/// Steal time of all cores so far, in ms (`/proc/stat`'s 8th field of
/// the `cpu` line, in USER_HZ = 100 ticks a second); 0 where unreadable.
fn steal_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/stat").unwrap_or_default();
    stat.lines()
        .find(|l| l.starts_with("cpu "))
        .and_then(|l| l.split_whitespace().nth(8))
        .and_then(|v| v.parse::<f64>().ok())
        .map_or(0.0, |ticks| ticks * 10.0)
}

/// A thread sleeping 1 ms at a time and keeping, in µs, how much longer
/// than asked its longest sleep of the current second took (read and reset
/// by the sampler with `swap`).
fn stall_probe() -> Arc<std::sync::atomic::AtomicU64> {
    let worst = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let keep = worst.clone();
    std::thread::spawn(move || loop {
        let asked = Duration::from_millis(1);
        let t0 = Instant::now();
        std::thread::sleep(asked);
        let late = t0.elapsed().saturating_sub(asked).as_micros() as u64;
        keep.fetch_max(late, std::sync::atomic::Ordering::Relaxed);
    });
    worst
}

/// Threads busy-waiting `busy` ms of every `period` ms (`"1.0/2,0.8/2"`)
/// until the returned flag is set.
fn emulated_load(spec: &str) -> Arc<std::sync::atomic::AtomicBool> {
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    for part in spec.split(',') {
        let (busy, period) = part.split_once('/').expect("--load BUSY/PERIOD in ms");
        let busy = Duration::from_secs_f64(busy.parse::<f64>().expect("busy ms") / 1e3);
        let period = Duration::from_secs_f64(period.parse::<f64>().expect("period ms") / 1e3);
        assert!(busy <= period, "--load: busy longer than its period");
        let stop = stop.clone();
        std::thread::spawn(move || {
            let mut next = Instant::now();
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let start = next;
                while start.elapsed() < busy {
                    std::hint::spin_loop();
                }
                next += period;
                match next.checked_duration_since(Instant::now()) {
                    Some(rest) => std::thread::sleep(rest),
                    None => next = Instant::now(),
                }
            }
        });
    }
    stop
}

#[tokio::main(flavor = "multi_thread", worker_threads = 1)]
async fn main() {
    let minutes: f64 = arg("--minutes").and_then(|v| v.parse().ok()).unwrap_or(15.0);
    let switch_after: f64 = arg("--switch-after").and_then(|v| v.parse().ok()).unwrap_or(5.0);
    let switch = arg("--switch").unwrap_or_else(|| "paper-3=40x40".into());
    let (switch_instance, switch_level) = switch.split_once('=').expect("--switch INSTANCE=LEVEL");
    let switch_level: Level = switch_level.parse().expect("--switch level");
    let at_once = std::env::args().any(|a| a == "--at-once");

    let config = lodcloth::service::config::ServiceConfig::load(std::path::Path::new(CONFIG)).expect("default config");
    let names: Vec<String> = config.instances.iter().map(|i| i.name.clone()).collect();
    let rates: Vec<f64> = config.instances.iter().map(|i| i.publish_hz).collect();
    let total_levels: usize = config.instances.iter().map(|i| i.levels.len()).sum();

    let dir = tempfile::tempdir().expect("temp dir");
    // The default config, with another background class when asked.
    let background = arg("--background").unwrap_or_else(|| "idle".into());
    let text = std::fs::read_to_string(CONFIG).expect("default config");
    assert!(
        text.contains("background = \"idle\""),
        "{CONFIG} no longer sets background = \"idle\""
    );
    let config_path = dir.path().join("default.toml");
    let mut text = text.replace("background = \"idle\"", &format!("background = \"{background}\""));
    if let Some(budget) = arg("--switch-budget") {
        assert!(
            text.contains("switch_budget = 5.0"),
            "{CONFIG} no longer sets switch_budget = 5.0"
        );
        // `none`: the key left out, for an older binary that knows none.
        let line = match budget.as_str() {
            "none" => String::new(),
            b => format!("switch_budget = {b}"),
        };
        text = text.replace("switch_budget = 5.0", &line);
    }
    std::fs::write(&config_path, text).expect("config");
    let port = daemon::free_port();
    let http: SocketAddr = format!("127.0.0.1:{}", daemon::free_port()).parse().expect("addr");
    // The binary cargo built beside this benchmark, or another one
    // (`--binary`: an A/B of two commits on the same config and machine).
    let lodcloth = arg("--binary").map_or_else(
        || std::path::PathBuf::from(env!("CARGO_BIN_EXE_lodcloth")),
        std::path::PathBuf::from,
    );
    let log_path = arg("--log").map_or_else(|| dir.path().join("serve.log"), std::path::PathBuf::from);
    let log = std::fs::File::create(&log_path).expect("log");
    let _daemon = Daemon(
        std::process::Command::new(&lodcloth)
            .arg("serve")
            .arg("--config")
            .arg(&config_path)
            .arg("--listen")
            .arg(format!("tcp/127.0.0.1:{port}"))
            .arg("--http")
            .arg(http.to_string())
            .arg("--cache-dir")
            .arg(dir.path().join("cache"))
            .arg("--snapshot-dir")
            .arg(dir.path().join("snapshots"))
            .stdout(std::process::Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap_or_else(|e| panic!("{}: {e} (cargo build --release first)", lodcloth.display())),
    );
    // `--load 1.0/2,0.8/2`: busy threads beside the daemon, each busy so
    // many ms of every period (ms), unpinned at nice 0: a machine whose
    // stepping leaves less free (a Zen 3's cores were 0.85 and 0.55 busy
    // with this config, a Zen 5's 0.36 and 0.14).
    let load = arg("--load").map(|spec| emulated_load(&spec));
    let started = Instant::now();
    let probe = stall_probe();
    let mut steal_before = steal_ms();
    println!(
        "cold start of {CONFIG} ({} instances, {total_levels} levels, background {background}) on {} ({} cores), bench of lodcloth {}, serving {}",
        names.len(),
        cpu_model(),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        lodcloth::VERSION,
        lodcloth.display()
    );

    if let Some(spec) = arg("--load") {
        println!("beside it, busy threads (ms busy/period): {spec}");
    }
    // Every instance's states, counted per instance.
    let options = ClientOptions::new(&[format!("tcp/127.0.0.1:{port}")]);
    let session = loop {
        match zenoh::open(client_config(&options).expect("client config")).await {
            Ok(s) => break s,
            Err(e) if started.elapsed() > Duration::from_secs(20) => panic!("cannot connect: {e}"),
            Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
        }
    };
    let client = Arc::new(Client::with_session(session, PREFIX));
    let counts: Arc<Mutex<BTreeMap<String, u64>>> = Arc::default();
    let tally = counts.clone();
    client
        .session
        .declare_subscriber(format!("{PREFIX}/*/state"))
        .callback(move |s| {
            if let Some(name) = s.key_expr().as_str().split('/').nth(1) {
                *tally.lock().expect("counts").entry(name.to_string()).or_default() += 1;
            }
        })
        .background()
        .await
        .expect("subscriber");

    let mut samples: Vec<Sample> = Vec::new();
    let mut switch_task = None;
    let mut switch_answer: Option<(f64, String)> = None;
    // After a `refining` answer: the coefficient version live (read once a
    // second, so what follows is timed to the second).
    let mut refining: Option<u32> = None;
    let mut followed: Vec<(f64, String)> = Vec::new();
    let mut all_prepared_at = None;
    let mut last_counts: BTreeMap<String, u64> = BTreeMap::new();
    let mut next = Instant::now() + Duration::from_secs(1);
    println!(
        "{:>6} {:>9} {:>9} {:>30} {:>9}",
        "t (s)", "overruns", "lag rst", "states/s (min over instances)", "prepared"
    );
    loop {
        tokio::time::sleep_until(next.into()).await;
        next += Duration::from_secs(1);
        let t = started.elapsed().as_secs_f64();
        let Ok((200, _, body)) = daemon::http_get(http, "/metrics").await else {
            assert!(t < 30.0, "no /metrics within 30 s");
            continue;
        };
        let m = parse_metrics(&body);
        let now_counts = counts.lock().expect("counts").clone();
        let states: Vec<f64> = names
            .iter()
            .map(|n| (now_counts.get(n).copied().unwrap_or(0) - last_counts.get(n).copied().unwrap_or(0)) as f64)
            .collect();
        last_counts = now_counts;
        let steal_now = steal_ms();
        let s = Sample {
            t,
            steal_ms: steal_now - steal_before,
            probe_late_ms: probe.swap(0, std::sync::atomic::Ordering::Relaxed) as f64 / 1e3,
            overruns: names
                .iter()
                .map(|n| per_instance(&m, "lodcloth_overruns_total", n))
                .collect(),
            stalls: names
                .iter()
                .map(|n| per_instance(&m, "lodcloth_stalls_total", n))
                .collect(),
            lag_resets: names
                .iter()
                .map(|n| per_instance(&m, "lodcloth_lag_resets_total", n))
                .collect(),
            rtf: names
                .iter()
                .map(|n| per_instance(&m, "lodcloth_real_time_factor", n))
                .collect(),
            states,
            prepared: names
                .iter()
                .map(|n| per_instance(&m, "lodcloth_levels_prepared", n))
                .sum(),
        };
        if samples.len().is_multiple_of(10) {
            let worst = s
                .states
                .iter()
                .zip(&rates)
                .map(|(got, want)| got / want)
                .fold(f64::INFINITY, f64::min);
            println!(
                "{:>6.0} {:>9.0} {:>9.0} {:>29.0}% {:>5.0}/{total_levels}",
                t,
                s.overruns.iter().sum::<f64>(),
                s.lag_resets.iter().sum::<f64>(),
                100.0 * worst,
                s.prepared
            );
        }
        steal_before = steal_now;
        if all_prepared_at.is_none() && s.prepared as usize >= total_levels {
            all_prepared_at = Some(t);
        }
        samples.push(s);

        if switch_task.is_none() && t >= switch_after {
            let c = client.clone();
            let instance = switch_instance.to_string();
            let request = v1::SwitchRequest {
                target: Some(v1::switch_request::Target::Level(switch_level.to_wire())),
                method: String::new(),
                at_once,
            };
            switch_task = Some(tokio::spawn(async move {
                let sent = Instant::now();
                let reply = c.switch(&instance, &request, Duration::from_secs(600)).await;
                (sent.elapsed().as_secs_f64(), reply)
            }));
        }
        if let Some(task) = switch_task
            .as_mut()
            .filter(|t| t.is_finished() && switch_answer.is_none())
        {
            let (secs, reply) = task.await.expect("switch task");
            let text = reply
                .as_ref()
                .map_or_else(|e| format!("refused: {e}"), |r| format!("{r:?}"));
            println!("switch of {switch_instance} to {switch_level} answered in {secs:.2} s: {text}");
            // A provisional answer: watch for what follows it in place.
            refining = reply.ok().filter(|r| r.refining).map(|r| r.coefficient_version);
            switch_answer = Some((secs, text));
        }
        // Each same-level switch that follows (until the run ends).
        if let Some(version) = refining {
            if let Ok(info) = client.info(switch_instance).await {
                if info.coefficient_version > version {
                    let since = t - switch_after;
                    println!(
                        "{switch_instance}: {} live in place {since:.1} s after the switch was sent (version {})",
                        info.method, info.coefficient_version
                    );
                    followed.push((since, info.method));
                    refining = Some(info.coefficient_version);
                }
            }
        }
        if (all_prepared_at.is_some() && switch_answer.is_some()) || t > minutes * 60.0 {
            break;
        }
    }

    if let Some(stop) = &load {
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    // Summary.
    let first = &samples[0];
    let last = samples.last().expect("a sample");
    println!("\n| instance | overruns | stalls | lag resets | states/s configured | lowest 1-s rate (from 2 s) | mean rate | lowest RTF |");
    println!("|---|---|---|---|---|---|---|---|");
    for (i, n) in names.iter().enumerate() {
        let steady: Vec<&Sample> = samples.iter().filter(|s| s.t >= 2.0).collect();
        let lowest = steady.iter().map(|s| s.states[i]).fold(f64::INFINITY, f64::min);
        let mean = steady.iter().map(|s| s.states[i]).sum::<f64>() / steady.len().max(1) as f64;
        let rtf = steady
            .iter()
            .map(|s| s.rtf[i])
            .filter(|r| *r > 0.0)
            .fold(f64::INFINITY, f64::min);
        println!(
            "| {n} | {:.0} | {:.0} | {:.0} | {:.0} | {lowest:.0} | {mean:.1} | {rtf:.3} |",
            last.overruns[i] - first.overruns[i].min(0.0),
            last.stalls[i],
            last.lag_resets[i],
            rates[i]
        );
    }
    // Each second in which some instance counted an overrun, beside what
    // the machine did in it: a stall every instance shares with the probe
    // (another process) or with steal time is the host's.
    let per_second: Vec<(&Sample, f64)> = samples
        .windows(2)
        .map(|w| {
            (
                &w[1],
                w[1].overruns.iter().sum::<f64>() - w[0].overruns.iter().sum::<f64>(),
            )
        })
        .collect();
    let stalls: Vec<&(&Sample, f64)> = per_second.iter().filter(|(_, more)| *more > 0.0).collect();
    let worst_probe = samples.iter().map(|s| s.probe_late_ms).fold(0.0, f64::max);
    // The daemon's stalls per second: the most any instance counted (the
    // instances of one thread count the same stall each).
    let daemon_stalls = |w: &[Sample]| {
        (0..names.len())
            .map(|i| w[1].stalls[i] - w[0].stalls[i])
            .fold(0.0, f64::max)
    };
    let stall_seconds = samples.windows(2).filter(|w| daemon_stalls(w) > 0.0).count();
    let steal: f64 = samples.iter().map(|s| s.steal_ms).sum();
    println!(
        "machine: steal {steal:.0} ms over the run, the probe's longest oversleep {worst_probe:.1} ms, \
         {stall_seconds} seconds with a stall of a stepping thread; {} seconds with overruns{}",
        stalls.len(),
        if stalls.is_empty() { "" } else { ":" }
    );
    for (s, more) in &stalls {
        println!(
            "  at {:.0} s: {more:.0} overruns, steal {:.0} ms, probe late {:.1} ms",
            s.t, s.steal_ms, s.probe_late_ms
        );
    }
    match all_prepared_at {
        Some(t) => println!("every level prepared {t:.0} s after start"),
        None => println!(
            "after {minutes} min, {:.0} of {total_levels} levels prepared",
            last.prepared
        ),
    }
    if let Some((secs, _)) = &switch_answer {
        let how = if at_once { ", at once" } else { "" };
        println!("first switch to an unprepared level ({switch_instance} → {switch_level}, sent at {switch_after} s{how}) answered in {secs:.2} s");
        for (since, method) in &followed {
            println!("  then {method} live in place within {since:.0} s of the request");
        }
    }

    let out_dir = format!("out/coldstart-{background}");
    let out = std::path::Path::new(&out_dir);
    std::fs::create_dir_all(out).expect("out/coldstart");
    let mut header = vec![
        "t_s".to_string(),
        "levels_prepared".to_string(),
        "steal_ms".to_string(),
        "probe_late_ms".to_string(),
    ];
    for n in &names {
        header.extend([
            format!("{n}_overruns"),
            format!("{n}_stalls"),
            format!("{n}_lag_resets"),
            format!("{n}_states"),
            format!("{n}_rtf"),
        ]);
    }
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    let mut csv = CsvTable::create(&out.join("coldstart.csv"), &header).expect("csv");
    for s in &samples {
        let mut row = vec![
            format!("{:.2}", s.t),
            format!("{:.0}", s.prepared),
            format!("{:.0}", s.steal_ms),
            format!("{:.2}", s.probe_late_ms),
        ];
        for i in 0..names.len() {
            row.extend([
                format!("{:.0}", s.overruns[i]),
                format!("{:.0}", s.stalls[i]),
                format!("{:.0}", s.lag_resets[i]),
                format!("{:.0}", s.states[i]),
                format!("{:.4}", s.rtf[i]),
            ]);
        }
        csv.row(&row).expect("row");
    }
    csv.finish().expect("csv");
    let labels: Vec<String> = names.iter().map(|n| format!("{n}: states/s ÷ configured")).collect();
    let mut rates_series: Vec<Series<'_>> = names
        .iter()
        .enumerate()
        .map(|(i, _)| Series {
            name: &labels[i],
            points: samples.iter().map(|s| (s.t, 100.0 * s.states[i] / rates[i])).collect(),
            markers: false,
            color: PALETTE[i % PALETTE.len()],
        })
        .collect();
    rates_series.push(Series {
        name: "levels prepared (of all)",
        points: samples
            .iter()
            .map(|s| (s.t, 100.0 * s.prepared / total_levels as f64))
            .collect(),
        markers: false,
        color: PALETTE[5],
    });
    line_chart_svg(
        &out.join("coldstart_rates.svg"),
        &format!("Cold start, background {background}: states published, levels prepared"),
        "seconds since start",
        "%",
        &rates_series,
        false,
        false,
    )
    .expect("chart");
    // Real-time factor (each metrics interval) and overruns: the overruns
    // are in the CSV; the factor shows lost time even before it adds up to
    // an overrun.
    let rtf_series: Vec<Series<'_>> = names
        .iter()
        .enumerate()
        .map(|(i, n)| Series {
            name: n,
            points: samples.iter().filter(|s| s.t >= 2.0).map(|s| (s.t, s.rtf[i])).collect(),
            markers: false,
            color: PALETTE[i % PALETTE.len()],
        })
        .collect();
    line_chart_svg(
        &out.join("coldstart_rtf.svg"),
        &format!("Cold start, background {background}: real-time factor (metrics interval)"),
        "seconds since start",
        "simulated s per wall s",
        &rtf_series,
        false,
        false,
    )
    .expect("chart");
    // The machine beside the daemon: how late the probe woke, and the
    // overruns of all instances, second by second.
    let stall_series = [
        Series {
            name: "probe: longest oversleep of a 1 ms sleep (ms)",
            points: samples.iter().map(|s| (s.t, s.probe_late_ms)).collect(),
            markers: false,
            color: PALETTE[0],
        },
        Series {
            name: "overruns of all instances in the second",
            points: per_second.iter().map(|(s, more)| (s.t, *more)).collect(),
            markers: true,
            color: PALETTE[1],
        },
        Series {
            name: "steal time (ms, all cores)",
            points: samples.iter().map(|s| (s.t, s.steal_ms)).collect(),
            markers: false,
            color: PALETTE[2],
        },
    ];
    line_chart_svg(
        &out.join("coldstart_stalls.svg"),
        &format!("Cold start, background {background}: the machine's stalls beside the daemon's overruns"),
        "seconds since start",
        "ms / count",
        &stall_series,
        false,
        false,
    )
    .expect("chart");
    println!("wrote {out_dir}/coldstart.csv, coldstart_rates.svg, coldstart_rtf.svg and coldstart_stalls.svg");
}
