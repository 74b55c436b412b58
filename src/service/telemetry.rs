//! What operators scrape: the daemon's counters (states and metrics
//! published, switches, refusals by code, who listens) kept beside the
//! engine's own per-instance metrics, and both encoded as OpenMetrics text
//! for `/metrics` and judged for `/healthz` (see `super::http`).
//!
//! The service's tasks bump atomics here; a scrape reads them and the
//! newest [`MetricsFrame`] of every instance (a `watch` borrow). Nothing is
//! computed per step and nothing here waits on the engine.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::registry::{Registry, Unit};

use super::Context;
use crate::engine::MetricsFrame;
use crate::proto::v1::error::Code;

/// The service's own counters, one set per instance plus refusals by code.
#[derive(Debug)]
pub(crate) struct Telemetry {
    started: Instant,
    started_at: SystemTime,
    instances: BTreeMap<String, InstanceCounters>,
    /// Refused requests by [`Code`] (indexed by its value).
    refusals: Vec<AtomicU64>,
}

/// Counters of one instance.
#[derive(Debug, Default)]
pub(crate) struct InstanceCounters {
    pub states_published: AtomicU64,
    pub metrics_published: AtomicU64,
    pub switches: AtomicU64,
    /// Whether a subscriber matched the state publisher at its last state
    /// (zenoh reports matching, not a count).
    pub state_subscribed: AtomicBool,
    /// Milliseconds after `started` of the newest metrics message
    /// (0: none yet).
    last_metrics_ms: AtomicU64,
}

/// Every refusal code of the wire contract, in order of value.
const CODES: [Code; 9] = [
    Code::Unspecified,
    Code::BadRequest,
    Code::UnknownInstance,
    Code::LevelNotAllowed,
    Code::Unstable,
    Code::EstimationFailed,
    Code::Unavailable,
    Code::NoLevelMeetsError,
    Code::Busy,
];

impl Telemetry {
    pub(crate) fn new<'a>(instances: impl IntoIterator<Item = &'a str>) -> Telemetry {
        let size = CODES.iter().map(|c| *c as usize).max().unwrap_or(0) + 1;
        Telemetry {
            started: Instant::now(),
            started_at: SystemTime::now(),
            instances: instances
                .into_iter()
                .map(|n| (n.to_string(), InstanceCounters::default()))
                .collect(),
            refusals: (0..size).map(|_| AtomicU64::new(0)).collect(),
        }
    }

    /// The counters of `instance` (every configured instance has some).
    pub(crate) fn instance(&self, instance: &str) -> Option<&InstanceCounters> {
        self.instances.get(instance)
    }

    pub(crate) fn refused(&self, code: Code) {
        if let Some(c) = self.refusals.get(code as usize) {
            c.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// A metrics message of `instance` went out now.
    pub(crate) fn metrics_published(&self, instance: &str) {
        if let Some(c) = self.instances.get(instance) {
            c.metrics_published.fetch_add(1, Ordering::Relaxed);
            let ms = self.started.elapsed().as_millis().max(1);
            c.last_metrics_ms
                .store(u64::try_from(ms).unwrap_or(u64::MAX), Ordering::Relaxed);
        }
    }

    /// How long ago `instance` last published metrics (`None`: never).
    fn metrics_age(&self, instance: &str, now: Instant) -> Option<Duration> {
        let ms = self.instances.get(instance)?.last_metrics_ms.load(Ordering::Relaxed);
        (ms > 0).then(|| now.saturating_duration_since(self.started + Duration::from_millis(ms)))
    }
}

/// One instance as `/healthz` judges it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct InstanceHealth {
    pub instance: String,
    pub healthy: bool,
    /// Why not, when not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub problem: Option<String>,
    /// Seconds since its last metrics message (`None`: none yet).
    pub metrics_age_s: Option<f64>,
    pub real_time_factor: Option<f64>,
    pub level: Option<String>,
    pub paused: bool,
}

/// `/healthz`'s answer.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Health {
    /// `ok` or `failing`.
    pub status: &'static str,
    pub version: &'static str,
    pub uptime_s: f64,
    pub instances: Vec<InstanceHealth>,
}

/// An instance whose metrics are this much older than their interval (or
/// than [`MIN_SILENCE`]) has stopped stepping or publishing.
pub const SILENT_INTERVALS: f64 = 5.0;
/// The shortest silence judged unhealthy, whatever the metrics rate.
pub const MIN_SILENCE: Duration = Duration::from_secs(2);
/// Time after start during which an instance that has not published yet
/// is still starting, not failing.
pub const START_GRACE: Duration = Duration::from_secs(30);

/// Judge one instance: healthy unless it halted (kept diverging), or its
/// metrics stopped for longer than `silence` (or never came within
/// [`START_GRACE`] of start).
pub fn judge(
    instance: &str,
    frame: Option<&MetricsFrame>,
    age: Option<Duration>,
    uptime: Duration,
    silence: Duration,
) -> InstanceHealth {
    let problem = if let Some(reason) = frame.and_then(|m| m.halted.as_deref()) {
        Some(format!("halted: {reason}"))
    } else {
        match age {
            Some(a) if a > silence => Some(format!(
                "no metrics for {:.1} s (expected every {:.2} s)",
                a.as_secs_f64(),
                silence.as_secs_f64() / SILENT_INTERVALS
            )),
            None if uptime > START_GRACE => Some(format!("no metrics since start {:.0} s ago", uptime.as_secs_f64())),
            _ => None,
        }
    };
    InstanceHealth {
        instance: instance.to_string(),
        healthy: problem.is_none(),
        problem,
        metrics_age_s: age.map(|a| a.as_secs_f64()),
        real_time_factor: frame.map(|m| m.real_time_factor),
        level: frame.map(|m| m.level.to_string()),
        paused: frame.is_some_and(|m| m.paused),
    }
}

/// Every instance of the daemon judged now.
pub(crate) fn health(ctx: &Context) -> Health {
    let now = Instant::now();
    let t = &ctx.telemetry;
    let uptime = now.saturating_duration_since(t.started);
    let silence = MIN_SILENCE.max(Duration::from_secs_f64(SILENT_INTERVALS / ctx.metrics_hz.max(1e-3)));
    let instances: Vec<InstanceHealth> = ctx
        .instances
        .iter()
        .map(|(name, i)| {
            let frame = i.handle.metrics.borrow().clone();
            judge(name, frame.as_deref(), t.metrics_age(name, now), uptime, silence)
        })
        .collect();
    Health {
        status: if instances.iter().all(|i| i.healthy) {
            "ok"
        } else {
            "failing"
        },
        version: crate::VERSION,
        uptime_s: uptime.as_secs_f64(),
        instances,
    }
}

/// A registry holding the daemon's collector: `/metrics` encodes it.
pub(crate) fn registry(ctx: Arc<Context>) -> Registry {
    let mut r = Registry::default();
    r.register_collector(Box::new(DaemonCollector(ctx)));
    r
}

/// Reads the context at every scrape.
struct DaemonCollector(Arc<Context>);

impl fmt::Debug for DaemonCollector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DaemonCollector").finish_non_exhaustive()
    }
}

/// `instance="name"`.
type InstanceLabel<'a> = [(&'static str, &'a str); 1];

/// One metric family with a value per instance (instances without a value,
/// e.g. no predicted error yet, are left out).
fn family<M: EncodeMetric>(
    enc: &mut DescriptorEncoder,
    name: &str,
    help: &str,
    unit: Option<&Unit>,
    values: &[(&str, Option<M>)],
) -> fmt::Result {
    let Some(first) = values.iter().find_map(|(_, v)| v.as_ref()) else {
        return Ok(());
    };
    let mut metric = enc.encode_descriptor(name, help, unit, first.metric_type())?;
    for (instance, v) in values {
        if let Some(v) = v {
            let labels: InstanceLabel = [("instance", instance)];
            v.encode(metric.encode_family(&labels)?)?;
        }
    }
    Ok(())
}

impl Collector for DaemonCollector {
    fn encode(&self, mut enc: DescriptorEncoder) -> fmt::Result {
        let ctx = &self.0;
        let t = &ctx.telemetry;

        let build: [(&str, &str); 2] = [("version", env!("CARGO_PKG_VERSION")), ("revision", crate::REVISION)];
        let mut m = enc.encode_descriptor(
            "lodcloth_build_info",
            "The daemon's version and git revision (value 1)",
            None,
            prometheus_client::metrics::MetricType::Gauge,
        )?;
        ConstGauge::new(1i64).encode(m.encode_family(&build)?)?;
        let start = t
            .started_at
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        let m = enc.encode_descriptor(
            "process_start_time_seconds",
            "Start of the daemon, Unix time",
            None,
            prometheus_client::metrics::MetricType::Gauge,
        )?;
        ConstGauge::new(start).encode(m)?;
        let m = enc.encode_descriptor(
            "lodcloth_client_preparations_running",
            "Preparations a client waits for, running now: background preparation holds while any runs",
            None,
            prometheus_client::metrics::MetricType::Gauge,
        )?;
        ConstGauge::new(i64::try_from(super::turns::client_work_running()).unwrap_or(i64::MAX)).encode(m)?;

        // Refusals by code (every code, zero included, so rates start at 0).
        let mut m = enc.encode_descriptor(
            "lodcloth_refusals",
            "Requests refused, by the wire contract's error code",
            None,
            prometheus_client::metrics::MetricType::Counter,
        )?;
        for code in CODES {
            let n = t.refusals.get(code as usize).map_or(0, |c| c.load(Ordering::Relaxed));
            let labels: [(&str, &str); 1] = [("code", code.as_str_name())];
            ConstCounter::new(n).encode(m.encode_family(&labels)?)?;
        }

        let frames: Vec<(&str, Option<Arc<MetricsFrame>>)> = ctx
            .instances
            .iter()
            .map(|(n, i)| (n.as_str(), i.handle.metrics.borrow().clone()))
            .collect();
        let gauge = |f: &dyn Fn(&MetricsFrame) -> Option<f64>| -> Vec<(&str, Option<ConstGauge<f64>>)> {
            frames
                .iter()
                .map(|(n, m)| (*n, m.as_deref().and_then(f).map(ConstGauge::new)))
                .collect()
        };
        let counter = |f: &dyn Fn(&MetricsFrame) -> u64| -> Vec<(&str, Option<ConstCounter<u64>>)> {
            frames
                .iter()
                .map(|(n, m)| (*n, m.as_deref().map(|m| ConstCounter::new(f(m)))))
                .collect()
        };
        let flag = |b: bool| if b { 1.0 } else { 0.0 };

        // Which level and estimator each instance runs: labels on a 1.
        let mut m = enc.encode_descriptor(
            "lodcloth_instance_info",
            "The level and coefficient estimator an instance runs (value 1)",
            None,
            prometheus_client::metrics::MetricType::Gauge,
        )?;
        for (n, f) in &frames {
            if let Some(f) = f {
                let (level, method) = (f.level.to_string(), f.method.to_string());
                let labels: [(&str, &str); 3] = [("instance", n), ("level", &level), ("method", &method)];
                ConstGauge::new(1i64).encode(m.encode_family(&labels)?)?;
            }
        }

        family(
            &mut enc,
            "lodcloth_real_time_factor",
            "Simulated seconds per wall second over the last metrics interval (1: real time)",
            None,
            &gauge(&|m| Some(m.real_time_factor)),
        )?;
        family(
            &mut enc,
            "lodcloth_step_cost",
            "Wall time of one step, mean over the last metrics interval",
            Some(&Unit::Seconds),
            &gauge(&|m| Some(m.step_cost_us * 1e-6)),
        )?;
        family(
            &mut enc,
            "lodcloth_time_step",
            "The instance's simulation time step",
            Some(&Unit::Seconds),
            &gauge(&|m| Some(m.dt)),
        )?;
        family(
            &mut enc,
            "lodcloth_simulated_time",
            "Simulated time of the instance's current episode",
            Some(&Unit::Seconds),
            &gauge(&|m| Some(m.time)),
        )?;
        family(
            &mut enc,
            "lodcloth_predicted_error",
            "Eq. 9 displacement error predicted for the level when it was prepared (fraction of the reference's largest displacement)",
            None,
            &gauge(&|m| m.predicted_error),
        )?;
        family(
            &mut enc,
            "lodcloth_live_error",
            "Eq. 9 error against the shadow reference now (fraction of its largest displacement)",
            None,
            &gauge(&|m| m.live_error),
        )?;
        family(
            &mut enc,
            "lodcloth_live_error_lag",
            "How far the live error is behind the cloth in simulated time (a touched episode's reference replays its inputs in the background)",
            Some(&Unit::Seconds),
            &gauge(&|m| m.live_error_time.map(|t| m.time - t)),
        )?;
        family(
            &mut enc,
            "lodcloth_max_strain",
            "Largest spring strain of the cloth now",
            None,
            &gauge(&|m| Some(m.max_strain)),
        )?;
        family(
            &mut enc,
            "lodcloth_kinetic_energy",
            "Kinetic energy of the cloth now",
            Some(&Unit::Joules),
            &gauge(&|m| Some(m.kinetic_energy)),
        )?;
        family(
            &mut enc,
            "lodcloth_coefficient_version",
            "Coefficient version of the instance (increments at every switch or re-estimation)",
            None,
            &gauge(&|m| Some(f64::from(m.coefficient_version))),
        )?;
        family(
            &mut enc,
            "lodcloth_paused",
            "1 while the instance is paused",
            None,
            &gauge(&|m| Some(flag(m.paused))),
        )?;
        family(
            &mut enc,
            "lodcloth_halted",
            "1 once the instance stopped stepping because it kept diverging",
            None,
            &gauge(&|m| Some(flag(m.halted.is_some()))),
        )?;
        family(
            &mut enc,
            "lodcloth_overruns",
            "Passes that could not catch up with real time within max_catch_up",
            None,
            &counter(&|m| m.overruns),
        )?;
        family(
            &mut enc,
            "lodcloth_stalls",
            "Passes of the instance's stepping thread that woke over 10 ms later than asked (the machine did not run it)",
            None,
            &counter(&|m| m.stalls),
        )?;
        family(
            &mut enc,
            "lodcloth_lag_resets",
            "Times the backlog exceeded max_lag and was dropped",
            None,
            &counter(&|m| m.lag_resets),
        )?;
        family(
            &mut enc,
            "lodcloth_divergences",
            "Steps that produced a non-finite or exploding state",
            None,
            &counter(&|m| m.divergences),
        )?;
        family(
            &mut enc,
            "lodcloth_rollbacks",
            "Divergences answered by rolling back to the last checkpoint",
            None,
            &counter(&|m| m.rollbacks),
        )?;
        family(
            &mut enc,
            "lodcloth_inputs",
            "Clients' inputs applied (grabs, moves, releases, pin moves, wind, impulses)",
            None,
            &counter(&|m| m.inputs),
        )?;
        family(
            &mut enc,
            "lodcloth_touched",
            "1 while a client's input acts on the cloth",
            None,
            &gauge(&|m| Some(flag(m.touched))),
        )?;

        // The service's own per-instance counters.
        let own = |f: &dyn Fn(&InstanceCounters) -> u64| -> Vec<(&str, Option<ConstCounter<u64>>)> {
            t.instances
                .iter()
                .map(|(n, c)| (n.as_str(), Some(ConstCounter::new(f(c)))))
                .collect()
        };
        family(
            &mut enc,
            "lodcloth_states_published",
            "State messages put on the bus (skipped while nobody subscribes)",
            None,
            &own(&|c| c.states_published.load(Ordering::Relaxed)),
        )?;
        family(
            &mut enc,
            "lodcloth_metrics_published",
            "Metrics messages put on the bus",
            None,
            &own(&|c| c.metrics_published.load(Ordering::Relaxed)),
        )?;
        family(
            &mut enc,
            "lodcloth_switches",
            "Level switches done",
            None,
            &own(&|c| c.switches.load(Ordering::Relaxed)),
        )?;
        let subscribed: Vec<(&str, Option<ConstGauge<i64>>)> = t
            .instances
            .iter()
            .map(|(n, c)| {
                (
                    n.as_str(),
                    Some(ConstGauge::new(i64::from(c.state_subscribed.load(Ordering::Relaxed)))),
                )
            })
            .collect();
        family(
            &mut enc,
            "lodcloth_state_subscribed",
            "1 when a subscriber on the bus matched the instance's states at its last state (zenoh reports matching, not a count)",
            None,
            &subscribed,
        )?;
        let pending: Vec<(&str, Option<ConstGauge<i64>>)> = ctx
            .instances
            .iter()
            .map(|(n, i)| {
                let p = i.pending_switches.load(Ordering::Relaxed);
                (n.as_str(), Some(ConstGauge::new(i64::try_from(p).unwrap_or(i64::MAX))))
            })
            .collect();
        family(
            &mut enc,
            "lodcloth_switches_pending",
            "Switch requests in progress or queued",
            None,
            &pending,
        )?;
        // Preparation progress: the configured levels ready with the
        // instance's method (a switch to one answers from memory).
        let levels = |prepared: bool| -> Vec<(&str, Option<ConstGauge<i64>>)> {
            ctx.instances
                .iter()
                .map(|(n, i)| {
                    let plan = i.preparer.plan();
                    let count = plan
                        .levels
                        .iter()
                        .filter(|&&l| !prepared || i.preparer.get(l, plan.method).is_some())
                        .count();
                    (
                        n.as_str(),
                        Some(ConstGauge::new(i64::try_from(count).unwrap_or(i64::MAX))),
                    )
                })
                .collect()
        };
        family(
            &mut enc,
            "lodcloth_levels",
            "Levels the instance may switch to (its configured levels)",
            None,
            &levels(false),
        )?;
        family(
            &mut enc,
            "lodcloth_levels_prepared",
            "Configured levels prepared with the instance's method: a switch to one answers from memory",
            None,
            &levels(true),
        )?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::Method;
    use crate::plan::Level;

    fn frame(halted: Option<&str>) -> MetricsFrame {
        MetricsFrame {
            frame: 10,
            time: 0.5,
            level: Level::Grid { nx: 16, ny: 16 },
            method: Method::Same,
            predicted_error: Some(0.02),
            live_error: None,
            live_error_time: None,
            step_cost_us: 40.0,
            real_time_factor: 1.0,
            overruns: 0,
            stalls: 0,
            lag_resets: 0,
            divergences: 0,
            rollbacks: 0,
            halted: halted.map(Arc::from),
            kinetic_energy: 0.0,
            potential_energy: 0.0,
            max_strain: 0.0,
            coefficient_version: 1,
            paused: false,
            dt: 1e-3,
            inputs: 0,
            touched: false,
        }
    }

    #[test]
    fn an_instance_is_healthy_while_its_metrics_keep_coming_and_it_has_not_halted() {
        let s = Duration::from_secs(2);
        let up = Duration::from_secs(100);
        let ok = judge("a", Some(&frame(None)), Some(Duration::from_millis(100)), up, s);
        assert!(ok.healthy, "{ok:?}");
        assert_eq!(ok.level.as_deref(), Some("16x16"));
        let silent = judge("a", Some(&frame(None)), Some(Duration::from_secs(3)), up, s);
        assert!(!silent.healthy);
        assert!(silent.problem.unwrap().contains("no metrics for 3.0 s"));
        let halted = judge("a", Some(&frame(Some("diverged 8 times"))), Some(Duration::ZERO), up, s);
        assert!(!halted.healthy);
        assert!(halted.problem.unwrap().contains("halted: diverged 8 times"));
        // Never published: starting within the grace period, failing after.
        assert!(judge("a", None, None, Duration::from_secs(1), s).healthy);
        assert!(!judge("a", None, None, START_GRACE + Duration::from_secs(1), s).healthy);
    }

    #[test]
    fn every_refusal_code_of_the_contract_is_counted() {
        for v in 0..64 {
            if let Ok(code) = Code::try_from(v) {
                assert!(CODES.contains(&code), "{code:?} is missing from CODES");
            }
        }
    }

    #[test]
    fn refusals_count_by_code_and_metrics_ages_run_from_the_last_message() {
        let t = Telemetry::new(["a", "b"]);
        t.refused(Code::Busy);
        t.refused(Code::Busy);
        t.refused(Code::LevelNotAllowed);
        assert_eq!(t.refusals[Code::Busy as usize].load(Ordering::Relaxed), 2);
        assert_eq!(t.refusals[Code::LevelNotAllowed as usize].load(Ordering::Relaxed), 1);
        assert_eq!(t.refusals[Code::Unstable as usize].load(Ordering::Relaxed), 0);
        assert_eq!(t.metrics_age("a", Instant::now()), None);
        std::thread::sleep(Duration::from_millis(5));
        t.metrics_published("a");
        let later = Instant::now() + Duration::from_secs(1);
        let age = t.metrics_age("a", later).unwrap();
        // Ages are kept in whole milliseconds, rounded down at publication.
        assert!(
            age > Duration::from_millis(900) && age <= Duration::from_millis(1001),
            "{age:?}"
        );
        assert_eq!(t.metrics_age("b", later), None);
        assert_eq!(t.metrics_age("nope", later), None);
    }
}
