//! The daemon over real zenoh sessions on 127.0.0.1 (multicast scouting
//! off, a timeout on every await): publishing rate, switches and the
//! continuity of the motion across them, refusals of bad requests,
//! liveliness, two daemons seen by one client, graceful shutdown.

use crate::daemon;

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use prost::Message;
use tokio::sync::oneshot;

use daemon::*;
use lodcloth::estimate::Method;
use lodcloth::lod::Correlation;
use lodcloth::plan::{Level, Preparer};
use lodcloth::proto::{unpack_positions, v1, WireLevel};
use lodcloth::scene::Scene;
use lodcloth::service::client::{Client, ClientError};
use lodcloth::service::config::ServiceConfig;
use lodcloth::service::keys;
use lodcloth::sim::{SpringPrecision, Topology};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn states_arrive_at_the_configured_rate_and_pinned_nodes_stay_put() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("rate", "rate-fixed"));
    let c = client(&[d.endpoint()]).await;
    let info = wait_info(&c, "rate").await;
    assert_eq!(info.publish_hz, 50.0);
    // Let the stepping settle, then count over 3 s.
    collect_states(&c, "rate", 0.5).await;
    let states = collect_states(&c, "rate", 3.0).await;
    let rate = states.len() as f64 / 3.0;
    assert!((45.0..=55.0).contains(&rate), "{rate} states/s, configured 50");
    let mut pinned_at: HashMap<u32, [f64; 3]> = HashMap::new();
    let mut last_frame = 0;
    for s in states.iter().filter(|s| !s.transition) {
        assert!(s.frame > last_frame, "frames increase");
        last_frame = s.frame;
        let lv = level_of(s);
        let pos = unpack_positions(&s.positions).expect("packed positions");
        assert_eq!(pos.len(), 3 * lv.nodes());
        assert!(pos.iter().all(|v| v.is_finite()));
        if lv != Level::from_wire(info.level.as_ref().unwrap()).unwrap() {
            continue; // the estimate went live at another level (not here: same method)
        }
        let n = lv.nodes();
        for &k in &info.pinned {
            let p = [pos[k as usize], pos[n + k as usize], pos[2 * n + k as usize]];
            let first = *pinned_at.entry(k).or_insert(p);
            assert_eq!(p, first, "pinned node {k} moved");
        }
    }
    assert!(!info.pinned.is_empty());
    // Time advances with the wall clock: 3 s of states span about 3 s of
    // simulated time (modulo the scene's 6 s loop).
    let span = states.last().unwrap().time - states[0].time;
    assert!(
        span < 0.0 || (2.7..3.3).contains(&span),
        "simulated span {span} s over 3 s"
    );
    d.shutdown().await.expect("clean exit");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_switch_is_answered_and_the_motion_continues_without_a_jump() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("sw", "sw-fixed"));
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "sw").await;
    let sub = c
        .session
        .declare_subscriber(keys::state(PREFIX, "sw"))
        .await
        .expect("subscriber");
    // Let the cloth fall for a while so that it is moving at the switch.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let request = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(Level::new(8, 8).to_wire())),
        method: String::new(),
    };
    let reply = within(60, "switch", c.switch("sw", &request, Duration::from_secs(60)))
        .await
        .expect("switch accepted");
    assert_eq!(Level::from_wire(reply.level.as_ref().unwrap()), Ok(Level::new(8, 8)));
    assert_eq!(
        Level::from_wire(reply.previous.as_ref().unwrap()),
        Ok(Level::new(16, 16))
    );
    let predicted = reply.predicted_error.expect("calibrated");
    assert!(predicted > 0.0 && predicted < 0.5, "predicted error {predicted}");

    // Read states until three after the 16² → 8² transition pair (the
    // start-up estimate going live is a transition pair too, 16² → 16²).
    let mut transitions: Vec<v1::State> = Vec::new();
    let mut pair: Option<(v1::State, v1::State)> = None;
    let mut after = 0;
    within(10, "states after the switch", async {
        while after < 3 {
            let s = sub.recv_async().await.expect("state");
            let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
            if s.transition {
                transitions.push(s);
                if let [.., a, b] = transitions.as_slice() {
                    if level_of(a) == Level::new(16, 16) && level_of(b) == Level::new(8, 8) {
                        pair = Some((a.clone(), b.clone()));
                    }
                }
            } else if pair.is_some() {
                assert_eq!(
                    level_of(&s),
                    Level::new(8, 8),
                    "states after the switch carry the new level"
                );
                after += 1;
            }
        }
    })
    .await;
    let (old, new) = pair.as_ref().map(|(a, b)| (a, b)).expect("a transition pair");
    assert_eq!(level_of(old), Level::new(16, 16));
    assert_eq!(level_of(new), Level::new(8, 8));
    assert_eq!(old.frame, new.frame);
    assert_eq!(old.time, new.time);
    assert!(new.coefficient_version > old.coefficient_version);

    // The visible jump: the new (coarse) surface sampled at the old nodes,
    // against the old nodes, relative to the reference's largest
    // displacement. Within the level's predicted error.
    let info = c.info("sw").await.expect("info");
    assert!(info.o_max > 0.0);
    let scene = Scene::load(&scene_path("paper-1-top-edge.toml")).unwrap();
    let fine = Topology::grid(scene.shape(16, 16), scene.orientation);
    let coarse = Topology::grid(scene.shape(8, 8), scene.orientation);
    let coarse_to_fine = Correlation::between(&coarse, &fine).unwrap();
    let old_pos = unpack_positions(&old.positions).unwrap();
    let new_pos = unpack_positions(&new.positions).unwrap();
    let mut sampled = vec![0.0; old_pos.len()];
    coarse_to_fine.map(&new_pos, &mut sampled);
    let n = fine.n_nodes;
    let jump = (0..n)
        .map(|k| {
            (0..3)
                .map(|c| (sampled[c * n + k] - old_pos[c * n + k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .sum::<f64>()
        / n as f64
        / info.o_max;
    let moving = (0..n).any(|k| (old_pos[n + k] - fine.rest_positions[k][1]).abs() > 1e-3);
    assert!(moving, "the cloth should be moving at the switch");
    eprintln!(
        "switch 16x16 -> 8x8 at t = {:.3} s: jump {jump:.5}, predicted error {predicted:.5}",
        old.time
    );
    assert!(jump <= predicted, "jump {jump} above the predicted error {predicted}");
    d.shutdown().await.expect("clean exit");
}

/// Issue 21: a switch to an unprepared level answers at once when asked to
/// (`at_once`), with the scene's own coefficients, and the requested
/// method's estimate goes live in place afterwards, at the same level.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_at_once_switch_answers_before_its_estimate_which_follows_in_place() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("now", "now-fixed"));
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "now").await;
    // `gkd` is not the configured method (`same`): nothing prepares it in
    // the background, so 12x12 with gkd is unprepared when asked for.
    let request = v1::SwitchRequest {
        target: Some(v1::switch_request::Target::Level(Level::new(12, 12).to_wire())),
        method: "gkd".into(),
        at_once: true,
    };
    let reply = within(30, "at-once switch", c.switch("now", &request, Duration::from_secs(30)))
        .await
        .expect("switch accepted");
    assert_eq!(Level::from_wire(reply.level.as_ref().unwrap()), Ok(Level::new(12, 12)));
    assert!(reply.refining, "an unprepared level goes live before its estimate");
    assert_eq!(reply.method, "same", "live with the scene's own coefficients first");
    assert_eq!(reply.predicted_error, None, "no prediction before the estimate");
    assert!(!reply.cached);
    // The estimate follows in place: same level, method gkd, one more
    // coefficient version, a prediction.
    let info = within(60, "the estimate in place", async {
        loop {
            let info = c.info("now").await.expect("info");
            if info.coefficient_version > reply.coefficient_version {
                return info;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    })
    .await;
    assert_eq!(Level::from_wire(info.level.as_ref().unwrap()), Ok(Level::new(12, 12)));
    assert_eq!(info.method, "gkd");
    assert_eq!(info.coefficient_version, reply.coefficient_version + 1);
    assert!(info.o_max > 0.0, "the prepared level's normaliser is live");
    // Asked again, now prepared: an ordinary switch answers from the cache
    // (at_once changes nothing for a prepared level).
    let again = v1::SwitchRequest {
        target: Some(v1::switch_request::Target::Level(Level::new(12, 12).to_wire())),
        method: "gkd".into(),
        at_once: true,
    };
    let reply = within(30, "prepared switch", c.switch("now", &again, Duration::from_secs(30)))
        .await
        .expect("switch accepted");
    assert!(!reply.refining && reply.cached && reply.method == "gkd");
    assert!(reply.predicted_error.is_some());
    d.shutdown().await.expect("clean exit");
}

/// Issue 21: an ordinary switch to a level whose `fit` is not made yet
/// does not wait for the fit. It goes live with the quick methods' best
/// (the lowest predicted error of same, BCD, GKD and least squares, each
/// prepared here again in-process as independent truth), says `refining`,
/// and the fit follows in place only if it predicts less (here it does).
/// Asked again while the fit is made, it does not wait for the fit either.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_switch_to_an_unfitted_level_goes_live_with_the_quick_best_and_the_fit_follows_if_better() {
    let _serial = daemon::serial().await;
    let applied = first_switch_to_an_unfitted_level("", true).await;
    assert!(applied, "on this scene the fit predicts less than every quick method");
}

/// The other side of the rule: a fit of no iterations is its best start
/// (whichever of same, GKD, BCD and lsq trains best) or `same` by its
/// guard; on this scene none predicts less than the live quick best (the
/// truth computed in the helper says so), and it must not replace it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_that_predicts_no_less_than_the_live_quick_best_is_not_applied() {
    let _serial = daemon::serial().await;
    let applied = first_switch_to_an_unfitted_level("fit_iterations = 0\n", false).await;
    assert!(!applied);
}

/// The daemon config of [`first_switch_to_an_unfitted_level`]: instance
/// "first" runs `fit`, nothing is prepared at start but its start level,
/// and `estimation`'s lines are added to `[estimation]`.
fn unfitted_daemon_config(estimation: &str) -> (u16, tempfile::TempDir, String) {
    let port = daemon::free_port();
    let dir = tempfile::tempdir().expect("temp dir");
    let text = daemon::config_text(port, &dir.path().join("cache"), ("first", "first-fixed"))
        .replace(
            "[estimation]\n",
            &format!("[estimation]\nprecompute = false\n{estimation}"),
        )
        .replacen("method = \"same\"", "method = \"fit\"", 1);
    (port, dir, text)
}

/// What instance "first" of `text` prepares at `level`, made in this
/// process without a cache: the truth a daemon's switch is checked against.
struct Truth {
    /// The quick methods' best and its predicted error.
    best_method: String,
    best_error: f64,
    fit: Arc<lodcloth::plan::Prepared>,
    /// The fit alone, in seconds.
    fit_seconds: f64,
}

fn truth_at(text: &str, level: Level) -> Truth {
    let config = ServiceConfig::from_toml(text, "test").expect("valid config");
    let plan = config
        .instances
        .iter()
        .find(|p| p.name == "first")
        .expect("instance")
        .clone();
    let truth = Preparer::new(Arc::new(plan), config.estimation, None);
    let quick: Vec<(String, f64)> = truth
        .quick_methods()
        .iter()
        .filter_map(|&m| truth.prepare(level, m).ok())
        .map(|p| (p.method.to_string(), p.predicted_error))
        .collect();
    let (best_method, best_error) = quick
        .iter()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .cloned()
        .expect("a quick method prepares");
    let fit_started = Instant::now();
    let fit = truth.prepare(level, Method::Fit).expect("the fit prepares");
    let fit_seconds = fit_started.elapsed().as_secs_f64();
    eprintln!(
        "quick methods {quick:?}: best {best_method}; fit {:.5}",
        fit.predicted_error
    );
    Truth {
        best_method,
        best_error,
        fit,
        fit_seconds,
    }
}

/// Serve `text` and switch its instance "first" to `level` with `fit` (an
/// ordinary switch): the daemon, its client, the request and the reply,
/// which is at `level`.
async fn switch_first_to_fit(
    port: u16,
    text: &str,
    dir: tempfile::TempDir,
    level: Level,
) -> (Daemon, Client, v1::SwitchRequest, v1::SwitchReply) {
    let d = Daemon::run(port, text, dir);
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "first").await;
    let request = v1::SwitchRequest {
        target: Some(v1::switch_request::Target::Level(level.to_wire())),
        method: "fit".into(),
        at_once: false,
    };
    let reply = within(60, "switch", c.switch("first", &request, Duration::from_secs(60)))
        .await
        .expect("switch accepted");
    assert_eq!(Level::from_wire(reply.level.as_ref().unwrap()), Ok(level));
    (d, c, request, reply)
}

/// Issue 21: an ordinary switch waits for its estimate no longer than the
/// daemon's `switch_budget`. Past it (here 0: nothing is prepared, so the
/// level's reference alone is past it) the level goes live with the
/// scene's own coefficients, as at once; what the switch waited for (the
/// quick methods' best, checked against the truth) follows in place, and
/// then the fit, which predicts less on this scene.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_switch_past_its_budget_goes_live_at_once_and_what_it_waited_for_follows_in_place() {
    let _serial = daemon::serial().await;
    let (port, dir, text) = unfitted_daemon_config("switch_budget = 0.0\n");
    let level = Level::new(12, 12);
    let truth = truth_at(&text, level);
    assert!(
        truth.fit.predicted_error < truth.best_error,
        "on this scene the fit predicts less"
    );
    let (d, c, _, reply) = switch_first_to_fit(port, &text, dir, level).await;
    assert!(reply.refining && !reply.cached);
    assert_eq!(reply.method, "same", "live with the scene's own coefficients first");
    assert_eq!(reply.predicted_error, None, "no prediction before the estimate");
    // Then the quick best, then the fit, each one coefficient version on.
    let mut seen = Vec::new();
    within(120, "the quick best and the fit in place", async {
        loop {
            let info = c.info("first").await.expect("info");
            let entry = (info.coefficient_version, info.method.clone(), info.o_max > 0.0);
            if seen.last() != Some(&entry) {
                seen.push(entry);
            }
            if info.coefficient_version >= reply.coefficient_version + 2 {
                return;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await;
    eprintln!("versions seen after the switch: {seen:?}");
    let version = |v: u32| seen.iter().find(|e| e.0 == v).cloned();
    let quick = version(reply.coefficient_version + 1).expect("the quick best went live (or was skipped)");
    assert_eq!(quick.1, truth.best_method, "the quick methods' best follows first");
    assert!(quick.2, "with its prepared normaliser");
    let fit = version(reply.coefficient_version + 2).expect("the fit went live");
    assert_eq!(fit.1, "fit");
    let info = c.info("first").await.expect("info");
    assert_eq!(Level::from_wire(info.level.as_ref().unwrap()), Ok(level));
    d.shutdown().await.expect("clean exit");
}

/// A daemon (with `estimation`'s extra lines) asked for 12×12 with `fit`:
/// checks the provisional level against the truth and what follows it;
/// returns whether the fit went live in place. The instance's own method
/// is `fit` (so its levels' `ready` tells when a fit is prepared), and
/// nothing is prepared beforehand but its start level.
async fn first_switch_to_an_unfitted_level(estimation: &str, ask_again: bool) -> bool {
    let (port, dir, text) = unfitted_daemon_config(estimation);
    let level = Level::new(12, 12);
    let Truth {
        best_method,
        best_error,
        fit,
        fit_seconds,
    } = truth_at(&text, level);

    let (d, c, request, reply) = switch_first_to_fit(port, &text, dir, level).await;
    assert!(reply.refining, "the fit is still to come");
    assert!(!reply.cached);
    assert_eq!(reply.method, best_method, "the quick methods' best goes live");
    assert_eq!(reply.predicted_error, Some(best_error));
    // `ask_again`: asked again while the fit is made in the background,
    // the answer does not wait for the fit either. It used to, for the
    // whole fit (67 s in CI's daemon smoke test on 2 cores, the fit running
    // as SCHED_IDLE behind everything else). The refinement takes the fit's
    // lock within milliseconds of the first answer; asked before that, the
    // switch goes live on the quick best as well. This fit takes
    // `fit_seconds` alone (0.8 s; the one of no iterations 0.3 s, too
    // close to the 0.1 s for a sure answer).
    let reply = if ask_again {
        tokio::time::sleep(Duration::from_millis(100)).await;
        let asked = Instant::now();
        let second = within(
            60,
            "second switch",
            c.switch("first", &request, Duration::from_secs(60)),
        )
        .await
        .expect("switch accepted");
        let answered = asked.elapsed().as_secs_f64();
        eprintln!("the fit alone {fit_seconds:.2} s; the second switch answered in {answered:.2} s");
        assert!(second.refining, "the fit is still to come ({answered:.2} s)");
        assert_eq!(second.method, best_method);
        assert_eq!(second.predicted_error, Some(best_error));
        assert_eq!(second.coefficient_version, reply.coefficient_version + 1);
        second
    } else {
        reply
    };
    let applied = fit.predicted_error < best_error;
    if applied {
        let info = within(120, "the fit in place", async {
            loop {
                let info = c.info("first").await.expect("info");
                if info.coefficient_version > reply.coefficient_version {
                    return info;
                }
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        })
        .await;
        assert_eq!(info.method, "fit");
        assert_eq!(Level::from_wire(info.level.as_ref().unwrap()), Ok(level));
        assert_eq!(info.coefficient_version, reply.coefficient_version + 1);
    } else {
        // Once the fit is prepared, the refinement decides at once (under
        // the instance's switch lock, which a switch also takes): asked for
        // again, the fit runs one version after the provisional one, so the
        // refinement did not apply it.
        within(120, "the fit prepared", async {
            loop {
                let info = c.info("first").await.expect("info");
                let twelve = info.levels.iter().find(|l| l.level == Some(level.to_wire()));
                if twelve.is_some_and(|l| l.ready) {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        })
        .await;
        let again = within(
            120,
            "the fit prepared",
            c.switch("first", &request, Duration::from_secs(120)),
        )
        .await
        .expect("switch accepted");
        assert_eq!(again.method, "fit");
        assert!(!again.refining);
        assert_eq!(again.predicted_error, Some(fit.predicted_error));
        assert_eq!(again.coefficient_version, reply.coefficient_version + 1);
    }
    d.shutdown().await.expect("clean exit");
    applied
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_requests_get_errors_naming_the_problem_and_publishing_goes_on() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("bad", "bad-fixed"));
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "bad").await;
    let level = |nx, ny| v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(v1::Level {
            nx,
            ny,
            ..Default::default()
        })),
        method: String::new(),
    };
    let max_error = |e| v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::MaxError(e)),
        method: String::new(),
    };
    let t = Duration::from_secs(30);
    let cases: Vec<(&str, Result<v1::SwitchReply, ClientError>, &str, &str)> = vec![
        (
            "unknown instance",
            c.switch("nope", &level(8, 8), t).await,
            "CODE_UNKNOWN_INSTANCE",
            "no instance 'nope'",
        ),
        (
            "level outside the allowed set",
            c.switch("bad", &level(17, 17), t).await,
            "CODE_LEVEL_NOT_ALLOWED",
            "17x17 is not allowed",
        ),
        (
            "huge level",
            c.switch("bad", &level(u32::MAX, 3), t).await,
            "CODE_LEVEL_NOT_ALLOWED",
            "not allowed",
        ),
        (
            "malformed protobuf",
            c.switch_raw("bad", Some(vec![0xff, 0xff, 0xff, 0x01])).await,
            "CODE_BAD_REQUEST",
            "malformed lodcloth.v1.SwitchRequest",
        ),
        (
            "empty payload",
            c.switch_raw("bad", None).await,
            "CODE_BAD_REQUEST",
            "empty request",
        ),
        (
            "no target",
            c.switch_raw("bad", Some(Vec::new())).await,
            "CODE_BAD_REQUEST",
            "no target",
        ),
        (
            "NaN max error",
            c.switch("bad", &max_error(f64::NAN), t).await,
            "CODE_BAD_REQUEST",
            "max_error NaN",
        ),
        (
            "negative max error",
            c.switch("bad", &max_error(-0.1), t).await,
            "CODE_BAD_REQUEST",
            "max_error -0.1",
        ),
        (
            "unknown method",
            c.switch(
                "bad",
                &v1::SwitchRequest {
                    method: "magic".into(),
                    ..level(8, 8)
                },
                t,
            )
            .await,
            "CODE_BAD_REQUEST",
            "method 'magic'",
        ),
        (
            "a lab method",
            c.switch(
                "bad",
                &v1::SwitchRequest {
                    method: "bcd".into(),
                    ..level(8, 8)
                },
                t,
            )
            .await,
            "CODE_BAD_REQUEST",
            "method 'bcd' is not one of same, gkd, fit, follow, drape (the daemon's methods; 'bcd' is the lab's)",
        ),
        (
            "a level unstable at the instance's fixed dt",
            c.switch("bad-fixed", &level(16, 16), t).await,
            "CODE_UNSTABLE",
            "unstable at dt = 2.5e-3",
        ),
    ];
    for (what, result, code, needle) in cases {
        let (got_code, message) = refused_code(result);
        assert_eq!(got_code, code, "{what}: {message}");
        assert!(
            message.contains(needle),
            "{what}: '{message}' should mention '{needle}'"
        );
    }
    // A query on a wildcard names no single instance.
    let replies = c
        .session
        .get(format!("{PREFIX}/*/switch"))
        .payload(level(8, 8).encode_to_vec())
        .timeout(Duration::from_secs(5))
        .await
        .expect("get");
    let reply = within(10, "wildcard reply", replies.recv_async())
        .await
        .expect("a reply");
    let err = reply.result().expect_err("refused");
    let e = v1::Error::decode(err.payload().to_bytes().as_ref()).unwrap();
    assert_eq!(e.code, v1::error::Code::BadRequest as i32, "{}", e.message);

    // Nothing was disturbed: both instances still publish at their rate and
    // sit at their levels.
    let states = collect_states(&c, "bad", 2.0).await;
    assert!(states.len() >= 90, "{} states in 2 s at 50 Hz", states.len());
    assert!(states.iter().all(|s| level_of(s) == Level::new(16, 16)));
    let fixed = collect_states(&c, "bad-fixed", 2.0).await;
    assert!(fixed.len() >= 36, "{} states in 2 s at 20 Hz", fixed.len());
    assert!(fixed.iter().all(|s| level_of(s) == Level::new(8, 8)));
    d.shutdown().await.expect("clean exit");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_see_instances_appear_and_disappear() {
    let _serial = daemon::serial().await;
    // The client listens first; the daemon connects to it.
    let port = free_port();
    let listen = format!("tcp/127.0.0.1:{port}");
    let mut zc = zenoh::Config::default();
    zc.insert_json5("mode", "\"peer\"").unwrap();
    zc.insert_json5("listen/endpoints", &format!("[\"{listen}\"]")).unwrap();
    zc.insert_json5("scouting/multicast/enabled", "false").unwrap();
    let session = within(10, "open", async { zenoh::open(zc).await })
        .await
        .expect("session");
    let alive = session
        .liveliness()
        .declare_subscriber(keys::alive(PREFIX, "*"))
        .history(true)
        .await
        .expect("liveliness subscriber");

    let dir = tempfile::tempdir().unwrap();
    let text = config_text(free_port(), dir.path(), ("live-a", "live-b")).replace(
        "multicast_scouting = false",
        &format!("multicast_scouting = false\nconnect = [\"{listen}\"]"),
    );
    let config = ServiceConfig::from_toml(&text, "test").unwrap();
    let (tx, rx) = oneshot::channel::<()>();
    let task = tokio::spawn(lodcloth::service::run(config, async {
        let _ = rx.await;
    }));
    let mut present = std::collections::BTreeSet::new();
    within(20, "tokens appear", async {
        while present.len() < 2 {
            let s = alive.recv_async().await.expect("sample");
            assert_eq!(s.kind(), zenoh::sample::SampleKind::Put);
            present.insert(keys::alive_instance(PREFIX, s.key_expr().as_str()).unwrap().to_string());
        }
    })
    .await;
    assert_eq!(present.into_iter().collect::<Vec<_>>(), ["live-a", "live-b"]);

    let _ = tx.send(());
    within(20, "shutdown", task).await.unwrap().expect("clean exit");
    let mut gone = std::collections::BTreeSet::new();
    within(20, "tokens disappear", async {
        while gone.len() < 2 {
            let s = alive.recv_async().await.expect("sample");
            if s.kind() == zenoh::sample::SampleKind::Delete {
                gone.insert(keys::alive_instance(PREFIX, s.key_expr().as_str()).unwrap().to_string());
            }
        }
    })
    .await;
    assert_eq!(gone.len(), 2);
    session.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_client_sees_the_instances_of_two_daemons() {
    let _serial = daemon::serial().await;
    let a = Daemon::start(("east-1", "east-2"));
    let b = Daemon::start(("west-1", "west-2"));
    let c = client(&[a.endpoint(), b.endpoint()]).await;
    wait_info(&c, "east-1").await;
    wait_info(&c, "west-1").await;
    let lists = within(15, "list", c.list()).await.expect("list");
    assert_eq!(lists.len(), 2, "one list per daemon");
    let mut names: Vec<String> = lists
        .iter()
        .flat_map(|l| l.instances.iter().map(|i| i.instance.clone()))
        .collect();
    names.sort();
    assert_eq!(names, ["east-1", "east-2", "west-1", "west-2"]);
    let mut alive = within(15, "alive", c.alive()).await.expect("alive");
    alive.sort();
    assert_eq!(alive, names);
    // Each daemon's states reach the one client.
    assert!(!collect_states(&c, "west-2", 1.0).await.is_empty());
    assert!(!collect_states(&c, "east-1", 1.0).await.is_empty());
    a.shutdown().await.expect("clean exit");
    b.shutdown().await.expect("clean exit");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_invalid_config_is_refused_with_every_problem_by_path() {
    let _serial = daemon::serial().await;
    let text = r#"
prefix = "bad prefix"
[zenoh]
mode = "satellite"
listen = ["carrier-pigeon"]
[engine]
max_substeps = 0
max_catch_up = 0.5
[estimation]
reference_steps = 1000
estimate_stride = 2000
switch_budget = -1.0
[[instances]]
name = "instances"
scene = "no/such/scene.toml"
levels = ["1x1", "8x8", "8x8"]
start = "9x9"
method = "guess"
integrator = "leapfrog"
dt = -1.0
spring_precision = "f16"
"#;
    let err = ServiceConfig::from_toml(text, "bad.toml")
        .expect_err("rejected")
        .to_string();
    for needle in [
        "prefix:",
        "zenoh.mode: 'satellite'",
        "zenoh.listen[0]: 'carrier-pigeon'",
        "engine.max_substeps: replaced by engine.max_catch_up",
        "engine.max_catch_up: 0.5 s is more than engine.max_lag (0.25 s)",
        "estimation.estimate_stride: 2000 is longer than estimation.reference_steps (1000)",
        "estimation.switch_budget: must be in [0, 3600] seconds, got -1",
        "instances[0].name: must be 1–64 letters, digits, '-' or '_' and not one of [\"instances\", \"alive\"], got 'instances'",
        "instances[0].scene:",
        "instances[0].levels[0]: 1x1",
        "instances[0].levels[2]: 8x8 is listed twice",
        "instances[0].start: 9x9",
        "instances[0].method: 'guess'",
        "instances[0].integrator: 'leapfrog'",
        "instances[0].dt: must be positive and finite, got -1",
        "instances[0].spring_precision: 'f16' is not one of f64, f32",
    ] {
        assert!(err.contains(needle), "missing '{needle}' in:\n{err}");
    }
    // The lab's methods are not the daemon's: named with the daemon's.
    let lab = text.replace("method = \"guess\"", "method = \"lsq\"");
    let err = ServiceConfig::from_toml(&lab, "lab.toml")
        .expect_err("rejected")
        .to_string();
    assert!(
        err.contains("instances[0].method: 'lsq' is not one of same, gkd, fit, follow, drape (the daemon's methods; 'lsq' is the lab's)"),
        "{err}"
    );
    let unknown = ServiceConfig::from_toml("[engine]\nthreadz = 2\n", "typo.toml").expect_err("rejected");
    assert!(unknown.to_string().contains("threadz"), "{unknown}");
}

/// `spring_precision` reaches the instance's live simulations (its start,
/// an at-once level) and nothing else: the default config's cloths step
/// their springs in f32, its surface in f64, and without the key every
/// instance is f64.
#[test]
fn an_instance_steps_its_springs_in_the_configured_precision() {
    let text = std::fs::read_to_string("config/default.toml").expect("default config");
    let config = ServiceConfig::from_toml(&text, "default.toml").expect("valid");
    let precisions: Vec<SpringPrecision> = config.instances.iter().map(|i| i.spring_precision).collect();
    assert_eq!(
        precisions,
        [[SpringPrecision::F32; 5].as_slice(), &[SpringPrecision::F64]].concat()
    );
    for plan in &config.instances {
        let preparer = Preparer::new(Arc::new(plan.clone()), config.estimation, None);
        let start = preparer.quick_start().expect("builds");
        assert_eq!(start.sim.spring_precision(), plan.spring_precision, "{}", plan.name);
        let other = *plan.levels.iter().find(|l| **l != plan.start).expect("two levels");
        assert_eq!(
            preparer.quick(other).expect("builds").sim.spring_precision(),
            plan.spring_precision,
            "{}",
            plan.name
        );
    }
    let without: String = text
        .lines()
        .filter(|l| !l.starts_with("spring_precision"))
        .map(|l| format!("{l}\n"))
        .collect();
    let config = ServiceConfig::from_toml(&without, "default.toml").expect("valid");
    assert!(config
        .instances
        .iter()
        .all(|i| i.spring_precision == SpringPrecision::F64));
}

/// Frames (every 10th step) in which the default config's instance
/// `name`, at its start level with the scene's coefficients, passes through
/// itself over `seconds`, with `touch` setting its grabs before each step
/// (given the step's time); and how many frames were checked.
fn crossing_frames(
    text: &str,
    name: &str,
    seconds: f64,
    mut touch: impl FnMut(&mut lodcloth::sim::Simulation, f64),
) -> (usize, usize) {
    let config = ServiceConfig::from_toml(text, "default.toml").expect("valid");
    let plan = config.instances.iter().find(|i| i.name == name).expect("served");
    let preparer = Preparer::new(Arc::new(plan.clone()), config.estimation, None);
    let mut sim = preparer.quick_start().expect("builds").sim;
    let dt = sim.params().dt;
    let steps = (seconds / dt).round() as usize;
    let mut frames = 0;
    for s in 0..steps {
        touch(&mut sim, s as f64 * dt);
        sim.step();
        if s % 10 == 9 && !lodcloth::sim::crossings(sim.topology(), &sim.state().pos).is_empty() {
            frames += 1;
        }
    }
    (frames, steps / 10)
}

/// The default config without its instances' `contact` lines.
fn without_contact(text: &str) -> String {
    text.lines()
        .filter(|l| !l.starts_with("contact"))
        .map(|l| format!("{l}\n"))
        .collect()
}

/// The default daemon serves paper-2, which hangs from one corner and
/// folds over itself, with self-contact: its live level does not pass
/// through itself over the scene's first 4 s (exact check, every 10th
/// step), where the same level without the config's `contact` does (from
/// about 2.1 s at 16x16).
#[test]
fn the_default_daemon_keeps_paper_2_from_passing_through_itself() {
    let text = std::fs::read_to_string("config/default.toml").expect("default config");
    let (crossed, checked) = crossing_frames(&text, "paper-2", 4.0, |_, _| ());
    assert_eq!(
        crossed, 0,
        "paper-2 crossed itself in {crossed} of {checked} checked frames"
    );
    let (crossed, checked) = crossing_frames(&without_contact(&text), "paper-2", 4.0, |_, _| ());
    assert!(
        crossed > 0,
        "without self-contact paper-2 crossed itself in none of {checked} frames: this test would show nothing"
    );
}

/// A client drags a corner of the default daemon's hanging cloth up and
/// across in front of it, then back through it (as `lodcloth input` or the
/// view would): at its start level it folds over itself and does not pass
/// through, where without the config's `contact` the corner goes through
/// the sheet.
#[test]
fn a_corner_dragged_across_the_default_daemons_hanging_cloth_never_crosses_it() {
    let text = std::fs::read_to_string("config/default.toml").expect("default config");
    let drag = |sim: &mut lodcloth::sim::Simulation, t: f64, from: &mut Option<([f64; 3], [f64; 3])>| {
        // It falls from horizontal and swings below its pins (z = 0) for
        // 2 s; then over 0.8 s the target goes from the bottom-left corner
        // up and across to over the sheet's middle, 5 cm in front of the
        // pins' plane, and over the next 0.8 s to 12 cm behind it.
        if t < 2.0 {
            return;
        }
        let n = sim.topology().grid.expect("a grid").nx;
        let corner = (n - 1) * n;
        let k = sim.topology().n_nodes;
        let at = |sim: &lodcloth::sim::Simulation, c: usize| {
            let pos = &sim.state().pos;
            [pos[c], pos[k + c], pos[2 * k + c]]
        };
        let (start, middle) = *from.get_or_insert_with(|| (at(sim, corner), at(sim, n / 2 * n + n / 2)));
        let up = ((t - 2.0) / 0.8).min(1.0);
        let back = ((t - 2.8) / 0.8).clamp(0.0, 1.0);
        let lerp = |a: f64, b: f64, f: f64| a + (b - a) * f;
        let z = lerp(lerp(start[2], 0.05, up), -0.12, back);
        sim.set_grabs(vec![lodcloth::sim::Grab {
            nodes: vec![corner as u32],
            weights: vec![1.0],
            target: [lerp(start[0], middle[0], up), lerp(start[1], middle[1], up), z],
            stiffness: 40.0,
            damping: 0.4,
        }])
        .expect("a valid grab");
    };
    let mut from = None;
    let (crossed, checked) = crossing_frames(&text, "hanging", 4.5, |sim, t| drag(sim, t, &mut from));
    assert_eq!(
        crossed, 0,
        "the hanging cloth crossed itself in {crossed} of {checked} checked frames"
    );
    let mut from = None;
    let (crossed, checked) = crossing_frames(&without_contact(&text), "hanging", 4.5, |sim, t| {
        drag(sim, t, &mut from)
    });
    assert!(
        crossed > 0,
        "without self-contact the drag crossed the sheet in none of {checked} frames: this test would show nothing"
    );
}

/// A hand takes the default config's cloth `name` at its start level at
/// the material point (u, v) after 1 s, much as the standard drags do
/// (`estimate::touched`: a patch of half-side 5 % of √A, here on a 40 N/m
/// spring, about the drags' own on these scenes), lifts it 0.3 √A against
/// gravity, carries it to where the cloth's middle (½, ½) was and 0.3 √A
/// down past it, and lets go; the frames crossing over 4 s.
fn dragged_across(text: &str, name: &str, u: f64, v: f64) -> (usize, usize) {
    use lodcloth::touch::{Input, Patch};
    let config = ServiceConfig::from_toml(text, "default.toml").expect("valid");
    let plan = config.instances.iter().find(|i| i.name == name).expect("served");
    let area: f64 = {
        let sim = Preparer::new(Arc::new(plan.clone()), config.estimation, None)
            .quick_start()
            .expect("builds")
            .sim;
        sim.topology().node_areas.iter().sum()
    };
    let side = area.sqrt();
    let hand = Patch {
        u,
        v,
        radius: 0.05 * side,
    };
    let middle = Patch {
        u: 0.5,
        v: 0.5,
        radius: 0.05 * side,
    };
    let mut script: Option<lodcloth::touch::Script> = None;
    let mut touch: Option<(lodcloth::touch::Touch, usize)> = None;
    let scene = match &plan.kind {
        lodcloth::plan::InstanceKind::Cloth(scene) => scene.clone(),
        _ => panic!("a cloth"),
    };
    crossing_frames(text, name, 4.0, |sim, t| {
        if t >= 1.0 && script.is_none() {
            let at = |p: &Patch| {
                let (nodes, w) = p.on(sim.topology()).expect("a grid or a mesh");
                let (n, pos) = (sim.topology().n_nodes, &sim.state().pos);
                [0, 1, 2].map(|c| {
                    nodes
                        .iter()
                        .zip(&w)
                        .map(|(&k, w)| w * pos[c * n + k as usize])
                        .sum::<f64>()
                })
            };
            let (from, to) = (at(&hand), at(&middle));
            let g = sim.params().gravity;
            let gn = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let up = g.map(|x| -x / gn * 0.3 * side);
            let lifted = [0, 1, 2].map(|c| from[c] + up[c]);
            // From the lifted point to the middle, then as far again below it.
            let across = [0, 1, 2].map(|c| to[c] - lifted[c]);
            let grab = Input::Grab {
                id: 1,
                at: hand,
                target: None,
                stiffness: 40.0,
                damping: 0.4,
            };
            let events = lodcloth::estimate::touched::eased_drag(
                grab,
                t,
                from,
                &[up, across, [0, 1, 2].map(|c| -up[c])],
                0.5,
                0.1,
                60.0,
            );
            script = Some(lodcloth::touch::Script::new(events).expect("a valid drag"));
            touch = Some((lodcloth::touch::Touch::new(&scene), 0));
        }
        if let (Some(script), Some((touch, next))) = (&script, &mut touch) {
            script.apply_due(next, touch, sim).expect("applies");
        }
    })
}

/// The default daemon's skirt, a mesh cloth whose levels are simplified
/// meshes (with slivers: nodes closer than the thickness to a triangle
/// they do not share at rest), dragged by its hem up and across itself as
/// a client would at its start level, does not pass through itself;
/// without the config's `contact` it does.
#[test]
fn the_default_daemons_skirt_dragged_across_itself_never_crosses() {
    let text = std::fs::read_to_string("config/default.toml").expect("default config");
    // By its hem at the seam (u = 1, v = 1), as the first standard drag takes it.
    let (crossed, checked) = dragged_across(&text, "skirt", 1.0, 1.0);
    assert_eq!(
        crossed, 0,
        "the skirt crossed itself in {crossed} of {checked} checked frames"
    );
    let (crossed, checked) = dragged_across(&without_contact(&text), "skirt", 1.0, 1.0);
    assert!(
        crossed > 0,
        "without self-contact the skirt crossed itself in none of {checked} frames: this test would show nothing"
    );
}

// ---------------------------------------------------------------- surfaces

/// A small surface scene: an 800-point sphere, bottom cap pinned, sagging
/// under gravity with its top pulled up for 0.75 s.
const SURFACE_SCENE: &str = r#"
name = "test-sphere"
cloud = "sphere"
count = 800
size = 0.5
gravity = [0.0, 0.0, -9.81]
pin_below = -0.35
duration = 1.5
[[pulls]]
point = "top"
offset = [0.0, 0.0, 0.2]
stiffness = 20.0
release = 0.75
"#;

/// A daemon with one surface instance at levels 100 and 200 points.
fn start_surface_daemon(dir: &std::path::Path, method: &str) -> Daemon {
    let scene = dir.join("sphere.toml");
    std::fs::write(&scene, SURFACE_SCENE).expect("scene written");
    let port = free_port();
    let text = config_header(port, &dir.join("cache"))
        + &format!(
            r#"
[[instances]]
name = "sphere"
kind = "surface"
scene = "{scene}"
levels = [100, 200]
start = 200
method = "{method}"
shadow_reference = true
"#,
            scene = scene.display(),
        );
    // The cache lives in the caller's `dir`, so a second daemon finds it.
    Daemon::run(port, &text, tempfile::tempdir().expect("temp dir"))
}

fn packed_len(bytes: &[u8]) -> usize {
    unpack_positions(bytes).expect("packed f32 triples").len() / 3
}

/// Mean distance between two packed clouds of the same size.
fn mean_distance(a: &[u8], b: &[u8]) -> f64 {
    let (a, b) = (unpack_positions(a).unwrap(), unpack_positions(b).unwrap());
    let n = a.len() / 3;
    (0..n)
        .map(|k| {
            (0..3)
                .map(|c| (a[c * n + k] - b[c * n + k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .sum::<f64>()
        / n as f64
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_surface_publishes_its_whole_cloud_and_switches_size_without_a_jump() {
    let _serial = daemon::serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let d = start_surface_daemon(dir.path(), "same");
    let c = client(&[d.endpoint()]).await;
    let info = wait_info(&c, "sphere").await;
    assert_eq!(info.kind, "surface");
    assert_eq!(info.cloud_points, 800);
    assert_eq!(
        Level::from_wire(info.reference.as_ref().unwrap()),
        Ok(Level::Points(800))
    );
    let kept = info.simulation_points.clone();
    assert_eq!(kept.len(), 200);
    let mut unique = kept.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), 200, "simulated points are distinct cloud points");
    assert!(kept.iter().all(|&i| i < 800));
    assert!(!info.triangles.is_empty() && info.triangles.iter().all(|&t| t < 200));
    assert!(!info.pinned.is_empty());

    // The cloud at rest, as the scene generates it.
    let rest = lodcloth::points::generate::generate(lodcloth::points::generate::Shape::Sphere, 800, 0.5, 0.0, 1);
    let states = collect_states(&c, "sphere", 1.0).await;
    assert!(states.len() >= 20, "{} states in 1 s at 50 Hz", states.len());
    let last = states.last().unwrap();
    assert_eq!(level_of(last), Level::Points(200));
    assert_eq!(packed_len(&last.positions), 800, "every cloud point");
    assert_eq!(packed_len(&last.simulation_positions), 200, "every simulated point");
    let normals = unpack_positions(&last.normals).unwrap();
    for k in 0..800 {
        let len = (0..3).map(|c| normals[c * 800 + k].powi(2)).sum::<f64>().sqrt();
        assert!((len - 1.0).abs() < 1e-3, "normal {k} has length {len}");
    }
    // Deep in the pinned cap every MLS neighbour is pinned: those points
    // stay exactly at rest; the pulled top moves.
    let pos = unpack_positions(&last.positions).unwrap();
    let moved = |k: usize| {
        (0..3)
            .map(|c| (pos[c * 800 + k] - rest.positions[k][c]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let cap: Vec<usize> = (0..800).filter(|&k| rest.positions[k][2] < -0.48).collect();
    assert!(!cap.is_empty());
    for &k in &cap {
        assert!(moved(k) < 1e-6, "cap point {k} moved {}", moved(k));
    }
    let top = (0..800)
        .max_by(|&a, &b| rest.positions[a][2].total_cmp(&rest.positions[b][2]))
        .unwrap();
    assert!(moved(top) > 0.02, "the pulled top moved only {}", moved(top));

    // Bad requests name the problem.
    let t = Duration::from_secs(30);
    let grid = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(Level::new(16, 16).to_wire())),
        method: String::new(),
    };
    let (code, message) = refused_code(c.switch("sphere", &grid, t).await);
    assert_eq!(code, "CODE_LEVEL_NOT_ALLOWED", "{message}");
    assert!(message.contains("100pts") && message.contains("200pts"), "{message}");
    let mixed = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(v1::Level {
            nx: 16,
            ny: 16,
            points: 100,
            ..Default::default()
        })),
        method: String::new(),
    };
    let (code, message) = refused_code(c.switch("sphere", &mixed, t).await);
    assert_eq!(code, "CODE_BAD_REQUEST");
    assert!(message.contains("both"), "{message}");

    // Switch 200 → 100 points while the surface moves.
    let sub = c
        .session
        .declare_subscriber(keys::state(PREFIX, "sphere"))
        .await
        .expect("subscriber");
    let request = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(Level::Points(100).to_wire())),
        method: String::new(),
    };
    let reply = within(60, "switch", c.switch("sphere", &request, Duration::from_secs(60)))
        .await
        .expect("switch accepted");
    assert_eq!(Level::from_wire(reply.level.as_ref().unwrap()), Ok(Level::Points(100)));
    assert_eq!(
        Level::from_wire(reply.previous.as_ref().unwrap()),
        Ok(Level::Points(200))
    );
    let predicted = reply.predicted_error.expect("calibrated");
    assert!(predicted > 0.0 && predicted < 0.5, "predicted error {predicted}");
    let mut transitions: Vec<v1::State> = Vec::new();
    let mut pair = None;
    let mut after = 0;
    within(10, "states after the switch", async {
        while after < 3 {
            let s = sub.recv_async().await.expect("state");
            let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
            if s.transition {
                transitions.push(s);
                if let [.., a, b] = transitions.as_slice() {
                    if level_of(a) == Level::Points(200) && level_of(b) == Level::Points(100) {
                        pair = Some((a.clone(), b.clone()));
                    }
                }
            } else if pair.is_some() {
                assert_eq!(level_of(&s), Level::Points(100));
                assert_eq!(packed_len(&s.positions), 800, "the whole cloud at every level");
                assert_eq!(packed_len(&s.simulation_positions), 100);
                after += 1;
            }
        }
    })
    .await;
    let (old, new) = pair.expect("a transition pair");
    assert_eq!((old.frame, old.time), (new.frame, new.time));
    let info = c.info("sphere").await.expect("info");
    assert_eq!(info.simulation_points.len(), 100);
    assert!(info.o_max > 0.0);
    // The visible jump: the same 800 points before and after, relative to
    // the reference's largest displacement, within the predicted error.
    let jump = mean_distance(&old.positions, &new.positions) / info.o_max;
    let moving = mean_distance(&old.positions, &states[0].positions) / info.o_max;
    eprintln!("surface switch 200 -> 100 points: jump {jump:.5}, predicted {predicted:.5}, motion {moving:.4}");
    assert!(jump <= predicted, "jump {jump} above the predicted error {predicted}");

    // The shadow reference gives a live error once the new level runs.
    let metrics = c
        .session
        .declare_subscriber(keys::metrics(PREFIX, "sphere"))
        .await
        .expect("subscriber");
    let live = within(10, "a live error", async {
        loop {
            let m = metrics.recv_async().await.expect("metrics");
            let m = v1::Metrics::decode(m.payload().to_bytes().as_ref()).expect("Metrics");
            if let (Some(e), true) = (m.live_error, m.level == Some(Level::Points(100).to_wire())) {
                return e;
            }
        }
    })
    .await;
    assert!(live.is_finite() && live < 0.5, "live error {live}");
    // The paper's GKD on the local rings (the all-points run recorded with
    // estimation samples, mapped onto the simulated points).
    let gkd = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(Level::Points(200).to_wire())),
        method: "gkd".into(),
    };
    let reply = within(60, "gkd switch", c.switch("sphere", &gkd, Duration::from_secs(60)))
        .await
        .expect("gkd accepted");
    assert_eq!(reply.method, "gkd");
    assert!(reply.predicted_error.is_some_and(|e| e.is_finite() && e > 0.0));
    drop(metrics);
    drop(sub);
    d.shutdown().await.expect("clean exit");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_surface_fit_is_cached_and_reused_by_the_next_daemon() {
    let _serial = daemon::serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let request = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(Level::Points(100).to_wire())),
        method: String::new(),
    };
    let mut replies = Vec::new();
    for run in 0..2 {
        let d = start_surface_daemon(dir.path(), "fit");
        let c = client(&[d.endpoint()]).await;
        wait_info(&c, "sphere").await;
        let reply = within(120, "switch", c.switch("sphere", &request, Duration::from_secs(120)))
            .await
            .expect("switch accepted");
        assert_eq!(reply.method, "fit");
        eprintln!(
            "run {run}: fit for 100 points in {:.2} s (cached {}), predicted error {:?}",
            reply.seconds, reply.cached, reply.predicted_error
        );
        replies.push(reply);
        d.shutdown().await.expect("clean exit");
    }
    let (first, second) = (&replies[0], &replies[1]);
    assert!(second.cached, "the second daemon reads the fit from the cache");
    assert_eq!(first.coefficients, second.coefficients, "the same coefficients");
    let fitted = first.coefficients.as_ref().unwrap();
    assert_eq!(
        (fitted.shear_k, fitted.shear_c),
        (0.0, 0.0),
        "surfaces have no shear springs"
    );
    assert!(fitted.structural_k > 0.0 && fitted.bend_k > 0.0);
    assert_eq!(first.predicted_error, second.predicted_error);
}

#[test]
fn a_surface_instance_with_cloth_settings_is_refused_by_path() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scene = dir.path().join("sphere.toml");
    std::fs::write(&scene, SURFACE_SCENE).expect("scene written");
    let text = format!(
        r#"
[[instances]]
name = "s"
kind = "surface"
scene = "{scene}"
reference = "24x24"
levels = ["16x16", 5, 900, 200]
start = 200
method = "gkd"
dt = 1e-3
[[instances]]
name = "t"
kind = "membrane"
scene = "{scene}"
levels = [100]
start = 100
[[instances]]
name = "u"
scene = "{cloth}"
levels = [100]
start = 100
"#,
        scene = scene.display(),
        cloth = scene_path("paper-1-top-edge.toml").display(),
    );
    let err = ServiceConfig::from_toml(&text, "surface.toml")
        .expect_err("rejected")
        .to_string();
    for needle in [
        "instances[0].reference:",
        "instances[0].dt:",
        "instances[0].levels[0]: 16x16 is a grid",
        "instances[0].levels[1]: 5 points is outside 20..=800",
        "instances[0].levels[2]: 900 points",
        "instances[1].kind: 'membrane'",
        "instances[2].levels[0]: 100pts is a point count",
    ] {
        assert!(err.contains(needle), "missing '{needle}' in:\n{err}");
    }
}

/// A mesh cloth's instance takes vertex counts up to its mesh's own; a
/// grid level, a larger count, a count below its pinned vertices and a
/// `reference` are refused by path, naming the file; a grid scene refuses
/// a vertex count naming itself.
#[test]
fn a_mesh_instance_with_grid_settings_or_counts_its_chain_cannot_make_is_refused_by_path() {
    let scene = scene_path("skirt-swaying.toml");
    let text = format!(
        r#"
[[instances]]
name = "skirt"
scene = "{scene}"
reference = "64x64"
levels = ["32x32", "915v", "5000v", "10v"]
start = "915v"
[[instances]]
name = "ok"
scene = "{scene}"
levels = ["570v", "2288v"]
start = "570v"
[[instances]]
name = "grid"
scene = "{cloth}"
levels = ["16x16", "300v"]
start = "16x16"
"#,
        scene = scene.display(),
        cloth = scene_path("paper-1-top-edge.toml").display(),
    );
    let err = ServiceConfig::from_toml(&text, "mesh.toml")
        .expect_err("rejected")
        .to_string();
    for needle in [
        "instances[0].reference: skirt-swaying is a mesh cloth",
        "instances[0].levels[0]: 32x32 is not a vertex count",
        "skirt.obj",
        "instances[0].levels[2]: 5000v is more than the 2288 vertices",
        "instances[0].levels[3]: ",
        "pinned",
        "instances[2].levels[1]: 300v is a mesh's vertex count; paper-1",
    ] {
        assert!(err.contains(needle), "missing '{needle}' in:\n{err}");
    }
    assert!(
        !err.contains("instances[1]"),
        "a valid mesh instance is accepted:\n{err}"
    );
    assert!(
        !err.contains("instances[0].levels[1]"),
        "915v is a level of the skirt:\n{err}"
    );
}
