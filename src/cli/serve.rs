//! `lodcloth serve` and its clients: `list`, `watch`, `switch`, `record`,
//! `health`, and the visualisation front ends `view` and `foxglove`.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use prost::Message;

use lodcloth::foxglove_bridge::{relay, RelayChannels, RelayOptions};
use lodcloth::output::{Precision, TrajectoryWriter};
use lodcloth::plan::Level;
use lodcloth::proto::{unpack_positions, v1, WireLevel};
use lodcloth::service::client::{Client, ClientOptions, ClientSecurity};
use lodcloth::service::config::ServiceConfig;
use lodcloth::service::keys;
use lodcloth::sim::State;
use lodcloth::view::ViewOptions;

/// Where a client finds the daemon.
#[derive(Args, Clone)]
pub struct Connect {
    /// zenoh endpoint(s) of a daemon or router, e.g. tcp/127.0.0.1:7450
    /// (the default config's endpoint). Empty: discover peers by multicast.
    #[arg(
        long,
        env = "LODCLOTH_CONNECT",
        value_delimiter = ',',
        default_value = "tcp/127.0.0.1:7450"
    )]
    pub connect: Vec<String>,
    /// Key prefix of the daemon.
    #[arg(long, default_value = "lodcloth")]
    pub prefix: String,
    /// zenoh client mode: one connection, through a router (re-established
    /// when the router restarts), instead of a peer.
    #[arg(long, env = "LODCLOTH_CLIENT_MODE")]
    pub client_mode: bool,
    /// User name for a daemon that authenticates (with --password).
    #[arg(long, env = "LODCLOTH_USER")]
    pub user: Option<String>,
    /// Password of --user; prefer the environment variable to the command line.
    #[arg(long, env = "LODCLOTH_PASSWORD", hide_env_values = true)]
    pub password: Option<String>,
    /// PEM of the CA that signed the daemon's certificate (quic/ and tls/ endpoints).
    #[arg(long, env = "LODCLOTH_TLS_CA")]
    pub tls_ca: Option<PathBuf>,
    /// This client's PEM certificate, for a daemon that requires mTLS.
    #[arg(long, env = "LODCLOTH_TLS_CERT")]
    pub tls_cert: Option<PathBuf>,
    /// The private key of --tls-cert.
    #[arg(long, env = "LODCLOTH_TLS_KEY")]
    pub tls_key: Option<PathBuf>,
}

impl Connect {
    /// The zenoh side of these options.
    pub fn options(&self) -> ClientOptions {
        ClientOptions {
            connect: self.connect.clone(),
            client_mode: self.client_mode,
            security: ClientSecurity {
                user: self.user.clone(),
                password: self.password.clone(),
                tls_root_ca: self.tls_ca.clone(),
                tls_certificate: self.tls_cert.clone(),
                tls_private_key: self.tls_key.clone(),
            },
        }
    }
}

/// `serve` options. Each has an environment variable, for containers and
/// service managers; the command line wins over it.
#[derive(Args)]
pub struct ServeArgs {
    /// Service config (TOML).
    #[arg(long, env = "LODCLOTH_CONFIG", default_value = "config/default.toml")]
    pub config: PathBuf,
    /// Validate the config (every scene and surface file it names
    /// included), print what it would serve, and exit.
    #[arg(long)]
    pub check: bool,
    /// Serve /metrics (OpenMetrics) and /healthz on this address:port,
    /// replacing the config's `[http] listen`; `off`: not at all.
    #[arg(long, env = "LODCLOTH_HTTP")]
    pub http: Option<String>,
    /// Directory that relative state directories (the coefficient cache,
    /// snapshots) are placed in instead of the working directory. Without
    /// it, systemd's STATE_DIRECTORY (`StateDirectory=`) is used when set.
    #[arg(long, env = "LODCLOTH_STATE_DIR")]
    pub state_dir: Option<PathBuf>,
    /// Coefficient cache directory, replacing the config's `cache`.
    #[arg(long, env = "LODCLOTH_CACHE_DIR")]
    pub cache_dir: Option<PathBuf>,
    /// Snapshot directory, replacing the config's `[snapshots] dir` (and
    /// turning snapshots on, every 30 s, when the config has none).
    #[arg(long, env = "LODCLOTH_SNAPSHOT_DIR")]
    pub snapshot_dir: Option<PathBuf>,
    /// Override the config's zenoh listen endpoints (comma separated).
    #[arg(long, env = "LODCLOTH_LISTEN", value_delimiter = ',')]
    pub listen: Vec<String>,
    /// Override the config's zenoh connect endpoints (comma separated).
    #[arg(long, env = "LODCLOTH_CONNECT", value_delimiter = ',')]
    pub connect: Vec<String>,
    /// Override the zenoh mode (peer, client, router).
    #[arg(long, env = "LODCLOTH_MODE")]
    pub mode: Option<String>,
}

/// `router` options.
#[derive(Args)]
pub struct RouterArgs {
    /// Endpoints to listen on (comma separated).
    #[arg(
        long,
        env = "LODCLOTH_ROUTER_LISTEN",
        value_delimiter = ',',
        default_value = "tcp/0.0.0.0:7447"
    )]
    pub listen: Vec<String>,
    /// A zenoh JSON5 config to start from (TLS, users, access control,
    /// other routers to connect to); --listen overrides its endpoints.
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
}

pub fn router(args: RouterArgs) -> Result<()> {
    let mut config = match &args.zenoh_config {
        Some(f) => zenoh::Config::from_file(f).map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?,
        None => zenoh::Config::default(),
    };
    for e in &args.listen {
        e.parse::<zenoh::config::EndPoint>()
            .map_err(|err| anyhow::anyhow!("--listen: '{e}' is not a zenoh endpoint: {err}"))?;
    }
    let listen = serde_json::to_string(&args.listen)?;
    for (key, value) in [("mode", "\"router\""), ("listen/endpoints", listen.as_str())] {
        config
            .insert_json5(key, value)
            .map_err(|e| anyhow::anyhow!("{key}: {e}"))?;
    }
    lodcloth::service::security::warn_if_tls(&config);
    runtime()?.block_on(async {
        let session = zenoh::open(config).await.map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;
        tracing::info!(zid = %session.zid(), listen = ?args.listen, "zenoh router running");
        shutdown_signal().await;
        session.close().await.map_err(|e| anyhow::anyhow!("closing: {e}"))?;
        tracing::info!("router stopped");
        Ok(())
    })
}

pub(crate) fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("lodcloth-io")
        .build()
        .context("starting the tokio runtime")
}

/// SIGINT or SIGTERM.
async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => tracing::info!("SIGINT received"),
        _ = term => tracing::info!("SIGTERM received"),
    }
}

pub fn serve(args: ServeArgs) -> Result<()> {
    let mut config = ServiceConfig::load(&args.config)?;
    config
        .zenoh
        .override_with(args.listen, args.connect, args.mode, "command line")?;
    match args.http.as_deref().map(str::trim) {
        None => {}
        Some("off") => config.http = None,
        Some(a) => {
            config.http =
                Some(lodcloth::service::config::parse_http_listen(a).map_err(|e| anyhow::anyhow!("--http: {e}"))?)
        }
    }
    let state_dir = args
        .state_dir
        .or_else(|| std::env::var_os("STATE_DIRECTORY").map(PathBuf::from))
        .filter(|d| !d.as_os_str().is_empty());
    config.place_state(state_dir.as_deref(), args.cache_dir, args.snapshot_dir);
    if args.check {
        print_check(&args.config, &config);
        return Ok(());
    }
    tracing::info!(
        version = lodcloth::VERSION,
        config = %args.config.display(),
        cache = %config.cache.display(),
        snapshots = %config.snapshots.as_ref().map_or("off".into(), |s| s.dir.display().to_string()),
        http = %config.http.map_or("off".into(), |a| a.to_string()),
        "starting"
    );
    runtime()?.block_on(lodcloth::service::run(config, shutdown_signal()))?;
    Ok(())
}

/// `serve --check`: what a valid config would serve.
fn print_check(path: &std::path::Path, config: &ServiceConfig) {
    let z = config.zenoh.values();
    println!("{}: valid", path.display());
    println!("  prefix     {}", config.prefix);
    println!(
        "  zenoh      mode {}, listen {:?}, connect {:?}",
        z.mode.as_deref().unwrap_or("peer"),
        z.listen.as_deref().unwrap_or_default(),
        z.connect.as_deref().unwrap_or_default()
    );
    println!("  cache      {}", config.cache.display());
    match &config.snapshots {
        Some(s) => println!("  snapshots  {}", s.dir.display()),
        None => println!("  snapshots  off"),
    }
    match config.http {
        Some(a) => println!("  http       http://{a}/metrics, http://{a}/healthz"),
        None => println!("  http       off"),
    }
    for i in &config.instances {
        let levels: Vec<String> = i.levels.iter().map(|l| l.to_string()).collect();
        println!(
            "  instance   {:<20} start {:<8} levels {}",
            i.name,
            i.start.to_string(),
            levels.join(", ")
        );
    }
}

pub(crate) async fn connect(c: &Connect) -> Result<Client> {
    Client::open(&c.options(), &c.prefix)
        .await
        .with_context(|| format!("connecting to {}", c.connect.join(", ")))
}

fn level(l: &Option<v1::Level>) -> String {
    match l.as_ref().map(Level::from_wire) {
        Some(Ok(l)) => l.to_string(),
        Some(Err(e)) => format!("? ({e})"),
        None => "?".into(),
    }
}

/// The spring classes a level's cloth has, named as its model names them:
/// a grid's five; a mesh's or a surface's springs are stretch (on edges)
/// and bend (across them) alone (mesh/springs.rs, points/surface.rs), so
/// their other classes, which keep the prior's values, are not printed.
fn spring_classes(l: &Option<v1::Level>) -> Vec<(&'static str, lodcloth::sim::SpringClass)> {
    use lodcloth::sim::SpringClass;
    match l.as_ref().map(Level::from_wire) {
        Some(Ok(Level::Vertices(_) | Level::Points(_))) => {
            vec![("stretch", SpringClass::StructuralU), ("bend", SpringClass::BendU)]
        }
        _ => SpringClass::ALL.iter().map(|&c| (c.name(), c)).collect(),
    }
}

fn pct(e: Option<f64>) -> String {
    e.map_or("—".into(), |e| format!("{:.2} %", 100.0 * e))
}

pub fn list(c: Connect) -> Result<()> {
    runtime()?.block_on(async {
        let client = connect(&c).await?;
        let alive = client.alive().await?;
        let lists = client.list().await?;
        if lists.is_empty() && alive.is_empty() {
            bail!("no daemon answered on {}", c.connect.join(", "));
        }
        println!(
            "{:<20} {:<22} {:>8} {:>6} {:>7}  daemon",
            "instance", "scene", "level", "method", "pub Hz"
        );
        for l in &lists {
            for i in &l.instances {
                println!(
                    "{:<20} {:<22} {:>8} {:>6} {:>7.1}  {}",
                    i.instance,
                    i.scene,
                    level(&i.level),
                    i.method,
                    i.publish_hz,
                    l.daemon
                );
            }
        }
        let listed: Vec<&str> = lists
            .iter()
            .flat_map(|l| l.instances.iter().map(|i| i.instance.as_str()))
            .collect();
        for a in alive.iter().filter(|a| !listed.contains(&a.as_str())) {
            println!("{a:<20} (alive, did not answer the list query)");
        }
        let _ = client.session.close().await;
        Ok(())
    })
}

pub fn watch(c: Connect, instance: String, count: Option<u64>) -> Result<()> {
    runtime()?.block_on(async {
        let client = connect(&c).await?;
        let info = client.info(&instance).await?;
        println!(
            "{} — scene {} ({}), reference {}, levels {}",
            info.instance,
            info.scene,
            info.integrator,
            level(&info.reference),
            info.levels
                .iter()
                .map(|l| level(&l.level))
                .collect::<Vec<_>>()
                .join(" ")
        );
        let sub = client
            .session
            .declare_subscriber(keys::metrics(&c.prefix, &instance))
            .await
            .map_err(|e| anyhow::anyhow!("subscribing: {e}"))?;
        let tty = std::io::stdout().is_terminal();
        let header = format!(
            "{:>10} {:>8} {:>7} {:>6} {:>9} {:>9} {:>9} {:>6} {:>8} {:>9} {:>8}",
            "frame",
            "time s",
            "level",
            "method",
            "predicted",
            "live err",
            "step µs",
            "RTF",
            "overruns",
            "energy J",
            "strain"
        );
        println!("{header}");
        let mut seen = 0u64;
        loop {
            let sample = tokio::select! {
                s = sub.recv_async() => s.map_err(|e| anyhow::anyhow!("{e}"))?,
                _ = tokio::signal::ctrl_c() => break,
            };
            let m = match v1::Metrics::decode(sample.payload().to_bytes().as_ref()) {
                Ok(m) => m,
                Err(e) => {
                    eprintln!("undecodable metrics: {e}");
                    continue;
                }
            };
            // A touched episode's live error comes from a reference replay
            // that may lag: say how far when it is more than a blink.
            let lag = match (m.live_error, m.live_error_time) {
                (Some(_), Some(t)) if m.time - t > 0.1 => format!("  live err of {:.1} s ago", m.time - t),
                _ => String::new(),
            };
            // While touched, what the level is predicted to do under input.
            let lag = match m.predicted_error_under_input {
                Some(e) if m.touched => format!("{lag}  touched: predicted {:.3}% under input", 100.0 * e),
                _ => lag,
            };
            let line = format!(
                "{:>10} {:>8.3} {:>7} {:>6} {:>9} {:>9} {:>9.1} {:>6.2} {:>8} {:>9.4} {:>7.2}%{}{lag}",
                m.frame,
                m.time,
                level(&m.level),
                m.method,
                pct(m.predicted_error),
                pct(m.live_error),
                m.step_cost_us,
                m.real_time_factor,
                m.overruns,
                m.kinetic_energy + m.potential_energy,
                100.0 * m.max_strain,
                if m.paused { "  paused" } else { "" }
            );
            if tty {
                // A live view: the line is rewritten in place.
                print!("\r\x1b[2K{line}");
                let _ = std::io::stdout().flush();
            } else {
                println!("{line}");
            }
            seen += 1;
            if count.is_some_and(|n| seen >= n) {
                break;
            }
        }
        if tty {
            println!();
        }
        let _ = client.session.close().await;
        Ok(())
    })
}

/// `switch` options.
#[derive(Args)]
pub struct SwitchArgs {
    pub instance: String,
    /// Target level, e.g. 32x32.
    pub level: Option<Level>,
    /// Instead of a level: the cheapest level with at most this predicted
    /// relative error (0.05 = 5 %).
    #[arg(long, conflicts_with = "level")]
    pub max_error: Option<f64>,
    /// Estimation method (default: the instance's).
    #[arg(long)]
    pub method: Option<String>,
    /// When the level is not prepared yet: go live at once with the scene's
    /// own coefficients and let the method's estimate follow in place
    /// (coefficient version + 1), instead of waiting for it.
    #[arg(long)]
    pub at_once: bool,
    /// Seconds to wait for the reply (an uncached level is estimated first).
    #[arg(long, default_value_t = 600.0)]
    pub timeout: f64,
}

pub fn switch(c: Connect, args: SwitchArgs) -> Result<()> {
    let target = match (args.level, args.max_error) {
        (Some(l), None) => v1::switch_request::Target::Level(l.to_wire()),
        (None, Some(e)) => v1::switch_request::Target::MaxError(e),
        _ => bail!("give a level (e.g. 32x32) or --max-error"),
    };
    let request = v1::SwitchRequest {
        target: Some(target),
        method: args.method.unwrap_or_default(),
        at_once: args.at_once,
    };
    runtime()?.block_on(async {
        let client = connect(&c).await?;
        let r = client
            .switch(&args.instance, &request, Duration::from_secs_f64(args.timeout))
            .await?;
        let k = r.coefficients.unwrap_or_default();
        println!(
            "{}: {} → {} ({}), predicted error {}{}, dt {:.3e} s, took {:.3} s{}, coefficient version {}",
            r.instance,
            level(&r.previous),
            level(&r.level),
            r.method,
            pct(r.predicted_error),
            r.predicted_error_under_input
                .map_or(String::new(), |e| format!(" ({:.3}% under input)", 100.0 * e)),
            r.dt,
            r.seconds,
            if r.refining && r.predicted_error.is_none() {
                " (at once: the scene's coefficients; the estimate follows in place)"
            } else if r.refining {
                " (estimated quickly; the fit follows in place if it predicts less)"
            } else if r.cached {
                " (prepared)"
            } else {
                " (estimated now)"
            },
            r.coefficient_version
        );
        let m = lodcloth::proto::material(&k);
        let kc: Vec<String> = spring_classes(&r.level)
            .iter()
            .map(|&(name, c)| format!("{name} {:.4e}/{:.4e}", m.get(c).k, m.get(c).c))
            .collect();
        println!("  K/C {}", kc.join("  "));
        let _ = client.session.close().await;
        Ok(())
    })
}

pub fn record(c: Connect, instance: String, seconds: f64, out: PathBuf) -> Result<()> {
    if !(seconds > 0.0 && seconds.is_finite()) {
        bail!("--seconds {seconds} must be positive");
    }
    runtime()?.block_on(async {
        let client = connect(&c).await?;
        let info = client.info(&instance).await?;
        // Inputs first: none that acts on a recorded state is missed.
        let inputs_sub = client
            .session
            .declare_subscriber(keys::inputs(&c.prefix, &instance))
            .await
            .map_err(|e| anyhow::anyhow!("subscribing: {e}"))?;
        let sub = client
            .session
            .declare_subscriber(keys::state(&c.prefix, &instance))
            .await
            .map_err(|e| anyhow::anyhow!("subscribing: {e}"))?;
        let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(seconds);
        let mut writer: Option<(TrajectoryWriter, Level)> = None;
        let mut frames = 0u64;
        let mut inputs: Vec<v1::InputEvent> = Vec::new();
        // The episode's inputs from before the recording started.
        let mut earlier: Vec<v1::InputEvent> = Vec::new();
        loop {
            let sample = tokio::select! {
                () = tokio::time::sleep_until(deadline) => break,
                sample = inputs_sub.recv_async() => {
                    let Ok(sample) = sample else { break };
                    let e = v1::InputEvent::decode(sample.payload().to_bytes().as_ref()).context("undecodable input")?;
                    inputs.push(e);
                    continue;
                }
                sample = sub.recv_async() => match sample {
                    Ok(s) => s,
                    Err(_) => break,
                },
            };
            let s = v1::State::decode(sample.payload().to_bytes().as_ref()).context("undecodable state")?;
            let lv = match s.level.as_ref().map(Level::from_wire) {
                Some(Ok(l)) => l,
                Some(Err(e)) => bail!("state frame {}: {e}", s.frame),
                None => Level::new(0, 0),
            };
            // A surface publishes its whole cloud at every level.
            let nodes = match lv {
                Level::Points(_) => info.cloud_points as usize,
                Level::Grid { .. } | Level::Vertices(_) => lv.nodes(),
            };
            let Some(pos) = unpack_positions(&s.positions) else {
                bail!(
                    "state frame {} has {} position bytes, not a multiple of 12",
                    s.frame,
                    s.positions.len()
                );
            };
            if pos.len() != 3 * nodes {
                bail!("state frame {} carries {} nodes for level {lv}", s.frame, pos.len() / 3);
            }
            if let Some((_, l)) = &writer {
                if *l != lv && lv.grid().is_some() {
                    eprintln!("the level changed from {l} to {lv}; stopping (a trajectory has one level)");
                    break;
                }
            }
            if writer.is_none() {
                // States arrive: the inputs subscription, declared before
                // the states', reaches the daemon too.
                eprintln!("recording {instance} to {}", out.display());
                // Asked once subscribed: what came before is in the log,
                // what comes after on the subscription (merged by seq).
                match client.episode_inputs(&instance).await {
                    Ok(log) if log.episode == s.episode && !log.events.is_empty() => {
                        if !log.complete {
                            eprintln!("warning: the daemon kept only the last {} inputs of this episode; a replay misses the first", log.events.len());
                        }
                        earlier = log.events;
                    }
                    Ok(_) => {}
                    Err(e) => eprintln!(
                        "warning: the inputs before the recording started are unknown ({e}); a replay of an episode touched before it misses them"
                    ),
                }
                let dt = 1.0 / info.publish_hz.max(1e-9);
                let w = TrajectoryWriter::create(&out, nodes, lv.grid(), dt, 1, Precision::F32, false)?;
                writer = Some((w, lv));
            }
            let n = pos.len() / 3;
            let state = State {
                vel: vec![0.0; 3 * n],
                pos,
                time: s.time,
                step: s.frame,
            };
            if let Some((w, _)) = writer.as_mut() {
                w.write(&state)?;
            }
            frames += 1;
        }
        let Some((w, l)) = writer else {
            bail!("no state of '{instance}' arrived within {seconds} s");
        };
        // Inputs that came while the last state was on its way.
        while let Ok(Some(sample)) = inputs_sub.try_recv() {
            if let Ok(e) = v1::InputEvent::decode(sample.payload().to_bytes().as_ref()) {
                inputs.push(e);
            }
        }
        let live: std::collections::HashSet<u64> = inputs.iter().map(|e| e.seq).collect();
        earlier.retain(|e| !live.contains(&e.seq));
        let before = earlier.len();
        earlier.append(&mut inputs);
        let mut inputs = earlier;
        inputs.sort_by_key(|e| e.seq);
        w.finish_with_inputs(Some(&inputs))?;
        // "<n> frames of" is what scripts read (.ci/compose_check.py).
        println!(
            "{}: {frames} frames of {instance} at {l}, with {} inputs ({before} from before the recording began)",
            out.display(),
            inputs.len()
        );
        let _ = client.session.close().await;
        Ok(())
    })
}

pub fn health(c: Connect, instance: Option<String>) -> Result<()> {
    runtime()?.block_on(async {
        let mut client = connect(&c).await?;
        client.timeout = Duration::from_secs(3);
        let names = match instance {
            Some(i) => vec![i],
            None => {
                let lists = client.list().await?;
                let names: Vec<String> = lists
                    .iter()
                    .flat_map(|l| l.instances.iter().map(|i| i.instance.clone()))
                    .collect();
                if names.is_empty() {
                    bail!("unhealthy: no daemon answered on {}", c.connect.join(", "));
                }
                names
            }
        };
        for n in &names {
            let info = client.info(n).await.with_context(|| format!("unhealthy: {n}"))?;
            println!("{n}: ok, level {}, {}", level(&info.level), info.method);
        }
        let _ = client.session.close().await;
        Ok(())
    })
}

/// The Foxglove relay's options, checked.
fn relay_options(instance: Option<String>, max_hz: f64) -> Result<RelayOptions> {
    if !(max_hz > 0.0) {
        bail!("--max-hz {max_hz} must be positive");
    }
    Ok(RelayOptions { instance, max_hz })
}

pub fn record_mcap(c: Connect, instance: String, seconds: f64, path: PathBuf) -> Result<()> {
    if !(seconds > 0.0 && seconds.is_finite()) {
        bail!("--seconds {seconds} must be positive");
    }
    runtime()?.block_on(async {
        let client = connect(&c).await?;
        // Fail before creating the file when the instance is not there.
        client.info(&instance).await?;
        let ctx = foxglove::Context::new();
        let file = std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        let writer = foxglove::McapWriter::new()
            .context(&ctx)
            .create(std::io::BufWriter::new(file))
            .with_context(|| format!("starting the MCAP file {}", path.display()))?;
        let options = relay_options(Some(instance.clone()), f64::INFINITY)?;
        let bar = lodcloth::args::progress_bar((seconds * 10.0).ceil() as u64, "recording (0.1 s)");
        let started = Instant::now();
        let opened = RelayChannels::open(&ctx, std::slice::from_ref(&instance))?;
        let counts = relay(
            &client,
            &ctx,
            &options,
            opened,
            tokio::time::sleep(Duration::from_secs_f64(seconds)),
            |counts| {
                if counts.meshes == 1 {
                    // States arrive: the inputs subscription, declared
                    // before the states', reaches the daemon too.
                    eprintln!("recording {instance} to {}", path.display());
                }
                bar.set_position((started.elapsed().as_secs_f64() * 10.0) as u64)
            },
        )
        .await?;
        bar.finish_and_clear();
        writer
            .close()
            .with_context(|| format!("closing the MCAP file {}", path.display()))?;
        let _ = client.session.close().await;
        if counts.meshes == 0 {
            bail!(
                "no state of '{instance}' arrived within {seconds} s; {} is empty",
                path.display()
            );
        }
        println!(
            "{}: {} meshes, {} metrics and {} inputs of {instance} ({} states rejected)",
            path.display(),
            counts.meshes,
            counts.metrics,
            counts.inputs,
            counts.rejected
        );
        Ok(())
    })
}

pub fn foxglove(c: Connect, host: String, port: u16, instance: Option<String>, max_hz: f64) -> Result<()> {
    let options = relay_options(instance, max_hz)?;
    runtime()?.block_on(async {
        let client = connect(&c).await?;
        let ctx = foxglove::Context::new();
        // The channels of the instances known now exist before any client
        // can connect (see `RelayChannels`).
        let names = match &options.instance {
            Some(name) => vec![name.clone()],
            None => client
                .list()
                .await
                .map(|lists| {
                    lists
                        .iter()
                        .flat_map(|l| l.instances.iter().map(|i| i.instance.clone()))
                        .collect()
                })
                .unwrap_or_default(),
        };
        let opened = RelayChannels::open(&ctx, &names)?;
        let server = foxglove::WebSocketServer::new()
            .name("lodcloth")
            .bind(host.clone(), port)
            .context(&ctx)
            .start()
            .await
            .with_context(|| format!("starting the Foxglove WebSocket server on {host}:{port}"))?;
        println!(
            "foxglove bridge: ws://{host}:{} (open it in Foxglove: Open connection → Foxglove WebSocket)",
            server.port()
        );
        let _ = std::io::stdout().flush();
        // A periodic line instead of a bar: the bridge runs until stopped.
        let mut last_log = Instant::now();
        let counts = relay(&client, &ctx, &options, opened, shutdown_signal(), |n| {
            if last_log.elapsed() >= Duration::from_secs(30) {
                last_log = Instant::now();
                tracing::info!(
                    states = n.states,
                    meshes = n.meshes,
                    metrics = n.metrics,
                    clients = server.client_count(),
                    "relaying"
                );
            }
        })
        .await?;
        tracing::info!(
            states = counts.states,
            meshes = counts.meshes,
            metrics = counts.metrics,
            "bridge stopped"
        );
        server.stop().wait().await;
        let _ = client.session.close().await;
        Ok(())
    })
}

pub fn view(c: Connect, listen: std::net::SocketAddr) -> Result<()> {
    runtime()?.block_on(async {
        let options = ViewOptions {
            listen,
            zenoh: c.options(),
            prefix: c.prefix,
        };
        lodcloth::view::run(
            options,
            |addr| {
                println!("lodcloth view: http://{addr}/");
                let _ = std::io::stdout().flush();
            },
            shutdown_signal(),
        )
        .await?;
        Ok(())
    })
}
