//! Issue 22: clients touch the cloth over the bus (`<prefix>/<instance>/input`):
//! a grab pulls the cloth to its target, survives a level switch in the
//! middle of the drag without a jump, and lets go; bad inputs are refused
//! naming the field, a flood is cut to the configured rate, and stepping
//! goes on throughout.

use crate::daemon;

use std::time::{Duration, Instant};

use prost::Message;

use daemon::*;
use lodcloth::lod::Correlation;
use lodcloth::plan::Level;
use lodcloth::proto::{unpack_positions, v1, WireLevel};
use lodcloth::scene::Scene;
use lodcloth::service::client::{Client, ClientError};
use lodcloth::service::keys;
use lodcloth::sim::{Grab, Topology};
use lodcloth::touch::Patch;

use v1::input_request::Action;

pub(crate) fn vec3(p: [f64; 3]) -> Option<v1::Vec3> {
    Some(v1::Vec3 {
        x: p[0],
        y: p[1],
        z: p[2],
    })
}

fn grab(id: u32, at: Patch, target: [f64; 3], stiffness: f64) -> v1::InputRequest {
    v1::InputRequest {
        action: Some(Action::Grab(v1::input_request::Grab {
            id,
            at: Some(v1::Patch {
                u: at.u,
                v: at.v,
                radius: at.radius,
            }),
            target: vec3(target),
            stiffness,
            damping: 0.2,
        })),
    }
}

/// The patch's position in a published state (SoA positions), on the
/// state's level of `scene` (a grid or a mesh level).
pub(crate) fn patch_position(scene: &Scene, s: &v1::State, at: Patch) -> [f64; 3] {
    let level = level_of(s);
    let cloth = scene.cloth_level(level).expect("the state's level");
    let (nodes, weights) = at.on(&cloth.topology).expect("a grid or a mesh level");
    let pos = unpack_positions(&s.positions).expect("packed positions");
    let g = Grab {
        nodes,
        weights,
        target: [0.0; 3],
        stiffness: 0.0,
        damping: 0.0,
    };
    g.patch(&pos, &vec![0.0; pos.len()]).0
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
}

/// The newest state of `instance` that is not a transition.
async fn latest(c: &Client, instance: &str) -> v1::State {
    collect_states(c, instance, 0.15)
        .await
        .into_iter()
        .rfind(|s| !s.transition)
        .expect("states keep coming")
}

async fn metrics(c: &Client, instance: &str) -> v1::Metrics {
    let sub = c
        .session
        .declare_subscriber(keys::metrics(PREFIX, instance))
        .await
        .expect("subscriber");
    let m = within(5, "metrics", sub.recv_async()).await.expect("metrics");
    v1::Metrics::decode(m.payload().to_bytes().as_ref()).expect("Metrics")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_grab_pulls_the_cloth_to_its_target_and_a_switch_mid_drag_keeps_it_without_a_jump() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("touch", "touch-fixed"));
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "touch").await;
    let scene = Scene::load(&scene_path("paper-1-top-edge.toml")).expect("scene");
    // Let the cloth fall and hang (top edge pinned; it loops at 6 s, which
    // a touched cloth must not do).
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let at = Patch {
        u: 0.5,
        v: 1.0,
        radius: 0.05,
    };
    let before = latest(&c, "touch").await;
    let start = patch_position(&scene, &before, at);
    // Out of the hanging plane, 0.35 m towards +z.
    let target = [start[0], start[1] + 0.1, start[2] + 0.35];
    let away = dist(start, target);

    let sub = c
        .session
        .declare_subscriber(keys::state(PREFIX, "touch"))
        .await
        .expect("subscriber");
    let sent = Instant::now();
    let reply = within(5, "grab", c.input("touch", &grab(1, at, target, 20.0)))
        .await
        .expect("the grab is accepted");
    assert_eq!(reply.grabs, vec![1]);
    // Input to visible: the first state stepped after the input took effect.
    let seen = within(5, "a state after the grab", async {
        loop {
            let s = sub.recv_async().await.expect("state");
            let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
            if s.frame > reply.frame {
                return s;
            }
        }
    })
    .await;
    eprintln!(
        "input to visible: {:.1} ms (grab applied after frame {}, first state {})",
        sent.elapsed().as_secs_f64() * 1e3,
        reply.frame,
        seen.frame
    );
    drop(sub);

    tokio::time::sleep(Duration::from_millis(2500)).await;
    let pulled = patch_position(&scene, &latest(&c, "touch").await, at);
    let left = dist(pulled, target);
    eprintln!("grab: {away:.3} m from the target before, {left:.3} m after 2.5 s");
    assert!(
        left < 0.3 * away,
        "the patch is still {left} m from its target (was {away})"
    );
    let m = metrics(&c, "touch").await;
    assert!(
        m.touched && m.inputs >= 1,
        "metrics: touched {} inputs {}",
        m.touched,
        m.inputs
    );
    // A live error now is the reference replaying the grab (live_error.rs
    // checks its values), of a time after the grab, never the recording's.
    if m.live_error.is_some() {
        assert!(
            m.live_error_time.is_some_and(|t| t > reply.time && t <= m.time),
            "a live error of t = {:?} while touched since t = {} (now {})",
            m.live_error_time,
            reply.time,
            m.time
        );
    }

    // Switch in the middle of the drag: the grab carries over and the
    // motion continues without a jump.
    let sub = c
        .session
        .declare_subscriber(keys::state(PREFIX, "touch"))
        .await
        .expect("subscriber");
    let request = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(Level::new(8, 8).to_wire())),
        method: String::new(),
    };
    let switched = within(60, "switch", c.switch("touch", &request, Duration::from_secs(60)))
        .await
        .expect("switch accepted");
    let predicted = switched.predicted_error.expect("calibrated");
    let (old, new) = within(10, "the transition pair", async {
        let mut previous: Option<v1::State> = None;
        loop {
            let s = sub.recv_async().await.expect("state");
            let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
            if s.transition {
                if let Some(p) = previous.take().filter(|p| level_of(p) == Level::new(16, 16)) {
                    if level_of(&s) == Level::new(8, 8) {
                        return (p, s);
                    }
                }
                previous = Some(s);
            }
        }
    })
    .await;
    let fine = Topology::grid(scene.shape(16, 16), scene.orientation);
    let coarse = Topology::grid(scene.shape(8, 8), scene.orientation);
    let coarse_to_fine = Correlation::between(&coarse, &fine).expect("correlation");
    let (old_pos, new_pos) = (
        unpack_positions(&old.positions).unwrap(),
        unpack_positions(&new.positions).unwrap(),
    );
    let mut sampled = vec![0.0; old_pos.len()];
    coarse_to_fine.map(&new_pos, &mut sampled);
    let n = fine.n_nodes;
    let o_max = c.info("touch").await.expect("info").o_max;
    let jump = (0..n)
        .map(|k| {
            (0..3)
                .map(|d| (sampled[d * n + k] - old_pos[d * n + k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .sum::<f64>()
        / n as f64
        / o_max;
    let patch_jump = dist(patch_position(&scene, &old, at), patch_position(&scene, &new, at));
    eprintln!("switch mid-drag 16x16 -> 8x8: mean jump {jump:.5} (predicted error {predicted:.5}), the grabbed patch moved {patch_jump:.4} m");
    assert!(jump <= predicted, "jump {jump} above the predicted error {predicted}");
    drop(sub);
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let after = latest(&c, "touch").await;
    assert_eq!(level_of(&after), Level::new(8, 8));
    let still = dist(patch_position(&scene, &after, at), target);
    assert!(
        still < 0.3 * away,
        "after the switch the patch drifted to {still} m from its target"
    );

    // Let go: the grab is gone and the cloth falls back.
    let release = v1::InputRequest {
        action: Some(Action::Release(v1::input_request::Release { id: 1 })),
    };
    let released = within(5, "release", c.input("touch", &release))
        .await
        .expect("released");
    assert!(released.grabs.is_empty());
    // It swings back through its hanging place (a pendulum of about 2 s).
    let fallen = collect_states(&c, "touch", 2.0)
        .await
        .iter()
        .filter(|s| !s.transition)
        .map(|s| dist(patch_position(&scene, s, at), target))
        .fold(0.0, f64::max);
    assert!(
        fallen > 0.6 * away,
        "released, the patch swung at most {fallen} m from the target"
    );
    assert!(!metrics(&c, "touch").await.touched);
    d.shutdown().await.expect("clean exit");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_inputs_are_refused_naming_the_field_and_a_flood_is_cut_to_the_rate() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("poke", "poke-fixed"));
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "poke").await;
    let at = Patch {
        u: 0.5,
        v: 0.5,
        radius: 0.0,
    };
    let refusal = |r: Result<v1::InputReply, ClientError>| match r {
        Err(ClientError::Refused { code, message }) => (code, message),
        other => panic!("expected a refusal, got {other:?}"),
    };
    let cases = [
        (
            grab(1, Patch { u: 1.5, ..at }, [0.0; 3], 1.0),
            "CODE_BAD_REQUEST",
            "grab.at.u = 1.5",
        ),
        (
            grab(1, at, [0.0, f64::NAN, 0.0], 1.0),
            "CODE_BAD_REQUEST",
            "grab.target.y",
        ),
        (grab(1, at, [0.0; 3], 0.0), "CODE_BAD_REQUEST", "grab.stiffness"),
        (grab(1, at, [0.0; 3], 1e12), "CODE_UNSTABLE", "stable up to"),
        (
            v1::InputRequest {
                action: Some(Action::Move(v1::input_request::Move {
                    id: 42,
                    target: vec3([0.0; 3]),
                })),
            },
            "CODE_BAD_REQUEST",
            "move.id",
        ),
        (
            v1::InputRequest {
                action: Some(Action::MovePin(v1::input_request::MovePin {
                    pin: 3,
                    offset: vec3([0.0; 3]),
                    seconds: 1.0,
                })),
            },
            "CODE_BAD_REQUEST",
            "move_pin.pin",
        ),
        (v1::InputRequest { action: None }, "CODE_BAD_REQUEST", "no action"),
    ];
    for (req, code, needle) in &cases {
        let (got, message) = refusal(c.input("poke", req).await);
        assert_eq!(&got, code, "{message}");
        assert!(message.contains(needle), "'{message}' does not name {needle}");
    }
    let (got, message) = refusal(c.input("nobody", &grab(1, at, [0.0; 3], 1.0)).await);
    assert_eq!(got, "CODE_UNKNOWN_INSTANCE", "{message}");
    assert!(!metrics(&c, "poke").await.touched, "a refused input left a touch");

    // A flood: 1,000 inputs at once against a burst of 200 and 2,000/s.
    let release_all = v1::InputRequest {
        action: Some(Action::ReleaseAll(v1::input_request::ReleaseAll {})),
    };
    let started = Instant::now();
    // Joined: every query is sent before any reply is awaited.
    let results = futures_util::future::join_all((0..1000).map(|_| c.input("poke", &release_all))).await;
    let wall = started.elapsed().as_secs_f64();
    let ok = results.iter().filter(|r| r.is_ok()).count();
    let busy = |why: &str| {
        results
            .iter()
            .filter(|r| matches!(r, Err(ClientError::Refused { code, message }) if code == "CODE_BUSY" && message.contains(why)))
            .count()
    };
    // Two limits answer BUSY: the instance's input rate, and the daemon's
    // requests in flight (an input is in flight until the engine answers
    // it, so on a loaded machine the 65th can be refused before the
    // bucket's 200 are spent).
    let (rate_busy, flight_busy) = (busy("inputs/s"), busy("requests; retry shortly"));
    eprintln!(
        "flood: {ok} applied, {rate_busy} refused BUSY by the rate, {flight_busy} by the requests in flight, of 1000 in {wall:.3} s"
    );
    assert_eq!(
        ok + rate_busy + flight_busy,
        1000,
        "every input is answered, applied or BUSY"
    );
    assert!(rate_busy + flight_busy > 0, "1000 inputs at once passed a burst of 200");
    let allowed = 200.0 + 2000.0 * wall;
    assert!((ok as f64) <= allowed + 1.0, "{ok} applied; the limit allows {allowed}");
    // The first requests in flight are never refused; without that limit
    // engaging, the whole burst passes.
    let least = if flight_busy == 0 {
        200
    } else {
        lodcloth::service::MAX_REQUESTS_IN_FLIGHT
    };
    assert!(ok >= least, "{ok} applied, fewer than {least}");
    // Stepping went on in real time through it all.
    let m = metrics(&c, "poke").await;
    assert!(
        m.real_time_factor > 0.9,
        "real-time factor {} after the flood",
        m.real_time_factor
    );
    assert!(!latest(&c, "poke").await.positions.is_empty());

    // The command line grabs and lets go the same way, and says why not.
    let cli = |args: &[&str]| {
        let endpoint = d.endpoint();
        let mut all: Vec<String> = vec!["input".into(), "poke".into()];
        all.extend(["--connect".into(), endpoint, "--prefix".into(), PREFIX.into()]);
        all.extend(args.iter().map(|a| a.to_string()));
        std::process::Command::new(env!("CARGO_BIN_EXE_lodcloth"))
            .args(&all)
            .output()
            .expect("the lodcloth binary runs")
    };
    let out = tokio::task::block_in_place(|| {
        cli(&[
            "grab",
            "--id",
            "4",
            "--u",
            "0.5",
            "--v",
            "1",
            "--target",
            "0.5,-0.9,0.2",
        ])
    });
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("grabs held: [4]"),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(metrics(&c, "poke").await.touched);
    let out = tokio::task::block_in_place(|| cli(&["grab", "--u", "2", "--v", "1", "--target", "0,0,0"]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("grab.at.u = 2"), "{err}");
    let out = tokio::task::block_in_place(|| cli(&["release", "--all"]));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("grabs held: []"), "{text}");
    d.shutdown().await.expect("clean exit");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_instance_left_untouched_for_the_idle_time_lets_go_and_returns_to_its_script() {
    let _serial = daemon::serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let text = config_text(port, dir.path(), ("idle", "idle-fixed")) + "\n[input]\nidle = 1.0\n";
    let d = Daemon::run(port, &text, dir);
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "idle").await;
    let scene = Scene::load(&scene_path("paper-1-top-edge.toml")).expect("scene");
    let at = Patch {
        u: 0.5,
        v: 1.0,
        radius: 0.05,
    };
    // Grab where it is and hold it there; no further input.
    let r = within(5, "grab", c.input("idle", &grab_here(2, at)))
        .await
        .expect("grab");
    assert_eq!(r.grabs, vec![2]);
    let held = Instant::now();
    assert!(metrics(&c, "idle").await.touched);
    // Still held just before the idle time runs out...
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(metrics(&c, "idle").await.touched, "let go before the idle time");
    // ... and let go after it: the grab is gone (a move of it is refused).
    let released = within(5, "letting go", async {
        loop {
            if !metrics(&c, "idle").await.touched {
                return held.elapsed();
            }
        }
    })
    .await;
    eprintln!(
        "let go {:.2} s after the last input (idle = 1 s)",
        released.as_secs_f64()
    );
    assert!(released >= Duration::from_millis(900), "let go after only {released:?}");
    let mv = v1::InputRequest {
        action: Some(Action::Move(v1::input_request::Move {
            id: 2,
            target: vec3([0.0, 0.0, 0.0]),
        })),
    };
    match c.input("idle", &mv).await {
        Err(ClientError::Refused { message, .. }) => assert!(message.contains("move.id"), "{message}"),
        other => panic!("the released grab still moves: {other:?}"),
    }
    // The cloth goes on stepping and publishing.
    let s = latest(&c, "idle").await;
    assert!(patch_position(&scene, &s, at).iter().all(|x| x.is_finite()));
    d.shutdown().await.expect("clean exit");
}

fn grab_here(id: u32, at: Patch) -> v1::InputRequest {
    grab_where_it_is(id, at, 20.0, 0.2)
}

/// Start `lodcloth record <instance> <args…>` and return once it says it is
/// recording (its subscriptions are declared: nothing published from then
/// on is missed).
fn start_recorder(d: &Daemon, instance: &str, args: &[&str]) -> std::process::Child {
    use std::io::BufRead;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_lodcloth"))
        .args(["record", instance, "--connect", &d.endpoint(), "--prefix", PREFIX])
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the lodcloth binary runs");
    let mut lines = std::io::BufReader::new(child.stderr.take().expect("stderr")).lines();
    loop {
        match lines.next() {
            Some(Ok(l)) if l.starts_with("recording ") => break,
            Some(Ok(_)) => {}
            other => panic!("the recorder stopped before recording: {other:?}"),
        }
    }
    // Keep draining stderr so the recorder never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    child
}

/// Replay `script` (none: the scene alone) on `scene` at 16×16 from rest
/// against the recorded `frames` of one episode, from `first` (the first
/// input's time) on, then on to `until`: the largest distance from a
/// recorded position, how many positions differ as f32, how many states
/// were compared, and the simulation at the end.
fn replay_recorded(
    scene: &Scene,
    frames: &[lodcloth::output::Frame],
    script: Option<&lodcloth::touch::Script>,
    first: f64,
    until: f64,
) -> (f64, usize, usize, lodcloth::sim::Simulation) {
    let mut sim = scene.build_at(16, 16).expect("the level");
    let mut touch = lodcloth::touch::Touch::new(scene);
    let mut next = 0;
    let dt = sim.params().dt;
    let mut step = |sim: &mut lodcloth::sim::Simulation, next: &mut usize| {
        if let Some(script) = script {
            script.apply_due(next, &mut touch, sim).expect("replays");
        }
        sim.step();
    };
    let mut worst = 0.0f64;
    let mut mismatches = 0;
    let mut compared = 0;
    let mut last_time = f64::NEG_INFINITY;
    for f in frames {
        // Until the episode ends (a loop).
        if f.time < last_time {
            break;
        }
        last_time = f.time;
        while sim.state().time < f.time - 0.5 * dt {
            step(&mut sim, &mut next);
        }
        if f.time < first {
            continue;
        }
        let n = sim.topology().n_nodes;
        let pos = &sim.state().pos;
        for (k, p) in f.positions.iter().enumerate() {
            let x = [pos[k], pos[n + k], pos[2 * n + k]];
            // The recording holds f32: the replay rounded the same way.
            worst = worst.max(dist(*p, x));
            mismatches += usize::from((0..3).any(|c| p[c] as f32 != x[c] as f32));
        }
        compared += 1;
    }
    while sim.state().time < until - 0.5 * dt {
        step(&mut sim, &mut next);
    }
    (worst, mismatches, compared, sim)
}

/// A session recorded with `lodcloth record` (.lct and MCAP) replays
/// offline: the scene at the instance's level, with the recorded inputs at
/// their simulated times, reproduces every recorded state bit for bit (as
/// f32, the wire's precision); without the inputs it misses them by
/// centimetres. The idle rule's
/// letting go is in the log and replays too, and `simulate --inputs` runs
/// the same replay.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recorded_session_replays_offline_to_the_recorded_states() {
    let _serial = daemon::serial().await;
    let dir = tempfile::tempdir().expect("temp dir");
    let out = tempfile::tempdir().expect("temp dir");
    let port = free_port();
    let text = config_text(port, dir.path(), ("rec", "rec-b")) + "\n[input]\nidle = 1.0\n";
    let d = Daemon::run(port, &text, dir);
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "rec").await;
    let lct = out.path().join("rec.lct");
    let mcap = out.path().join("rec.mcap");
    let seconds = "4.5";
    let (lct_rec, mcap_rec) = tokio::task::block_in_place(|| {
        (
            start_recorder(&d, "rec", &["--seconds", seconds, "--out", lct.to_str().unwrap()]),
            start_recorder(&d, "rec", &["--seconds", seconds, "--mcap", mcap.to_str().unwrap()]),
        )
    });

    // A hand closes on the bottom edge, drags it out and up, the wind
    // rises and a finger flicks the cloth; then nobody touches it.
    let scene = Scene::load(&scene_path("paper-1-top-edge.toml")).expect("scene");
    let at = Patch {
        u: 0.5,
        v: 1.0,
        radius: 0.05,
    };
    let mut sent = vec![grab_here(1, at)];
    let mut replies = vec![within(5, "grab", c.input("rec", &sent[0])).await.expect("grab")];
    let p0 = patch_position(&scene, &latest(&c, "rec").await, at);
    for k in 1..=12 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        let s = k as f64 / 12.0;
        let mv = v1::InputRequest {
            action: Some(Action::Move(v1::input_request::Move {
                id: 1,
                target: vec3([p0[0], p0[1] + 0.15 * s, p0[2] + 0.3 * s]),
            })),
        };
        replies.push(within(5, "move", c.input("rec", &mv)).await.expect("move"));
        sent.push(mv);
    }
    for request in [
        v1::InputRequest {
            action: Some(Action::Wind(v1::input_request::Wind {
                velocity: vec3([0.0, 0.0, 3.0]),
                gust: 0.2,
                gust_hz: 1.0,
            })),
        },
        v1::InputRequest {
            action: Some(Action::Impulse(v1::input_request::Impulse {
                at: Some(v1::Patch {
                    u: 0.25,
                    v: 0.75,
                    radius: 0.05,
                }),
                impulse: vec3([0.0, 0.0, 0.01]),
            })),
        },
    ] {
        replies.push(within(5, "input", c.input("rec", &request)).await.expect("input"));
        sent.push(request);
    }
    let (lct_done, mcap_done) = tokio::task::block_in_place(|| {
        (
            lct_rec.wait_with_output().expect("recorder"),
            mcap_rec.wait_with_output().expect("recorder"),
        )
    });
    assert!(lct_done.status.success() && mcap_done.status.success());
    eprintln!(
        "{}{}",
        String::from_utf8_lossy(&lct_done.stdout),
        String::from_utf8_lossy(&mcap_done.stdout)
    );

    // Every input is in the log, in order, as sent and at the step it took
    // effect; then the idle rule's letting go (grab released, scene wind).
    let logged = lodcloth::output::recorded_inputs(&lct).expect("the input log");
    assert_eq!(
        lodcloth::output::recorded_inputs(&mcap).expect("the MCAP inputs"),
        logged
    );
    assert_eq!(logged.len(), sent.len() + 2, "{logged:#?}");
    for ((e, request), reply) in logged.iter().zip(&sent).zip(&replies) {
        assert_eq!(e.input.as_ref(), Some(request));
        assert_eq!((e.frame, e.time, e.idle), (reply.frame, reply.time, false));
    }
    let idle: Vec<_> = logged[sent.len()..].iter().map(|e| (e.idle, e.input)).collect();
    assert_eq!(
        idle,
        vec![
            (
                true,
                Some(lodcloth::proto::input_request(&lodcloth::touch::Input::ReleaseAll))
            ),
            (
                true,
                Some(lodcloth::proto::input_request(&lodcloth::touch::Input::SceneWind))
            ),
        ]
    );

    // Replay offline from the episode's start, with and without the inputs.
    let replay = lodcloth::output::Replay::of(&logged, None, &lct).expect("a replay");
    assert_eq!(replay.level, Some(Level::new(16, 16)));
    let mut reader = lodcloth::output::TrajectoryReader::open(&lct).expect("the trajectory");
    let mut frames = Vec::new();
    while let Some(f) = reader.next_frame().expect("a frame") {
        frames.push(f);
    }
    let first = logged[0].time;
    // The instance's level steps at its own dt (a coarse level may take a
    // longer step than the scene's); its coefficients are the scene's
    // (method `same` at 16², checked here).
    let info = c.info("rec").await.expect("info");
    let mut scene = scene;
    scene.params.dt = info.dt;
    assert_eq!(
        info.coefficients,
        Some(lodcloth::proto::coefficients(&scene.material_at(16, 16)))
    );
    let run = |with_inputs: bool, until: f64| {
        replay_recorded(&scene, &frames, with_inputs.then_some(&replay.script), first, until)
    };
    let (with, mismatches, compared, replayed) = run(true, 6.0);
    let (without, _, _, _) = run(false, 0.0);
    eprintln!(
        "replayed {} inputs over {compared} recorded states: {mismatches} f32 positions differ \
         (largest difference {with:.2e} m; {without:.3} m without the inputs)",
        logged.len()
    );
    assert!(compared >= 100, "only {compared} states to compare");
    assert_eq!(mismatches, 0, "the replay is up to {with} m from the recording");
    assert!(without > 0.02, "the inputs moved the cloth only {without} m");

    // `simulate --inputs` runs the same replay (to 6 s, the scene's end).
    let sim_out = out.path().join("replay");
    let cli = tokio::task::block_in_place(|| {
        std::process::Command::new(env!("CARGO_BIN_EXE_lodcloth"))
            .args([
                "simulate",
                "--scene",
                scene_path("paper-1-top-edge.toml").to_str().unwrap(),
            ])
            .args(["--nx", "16", "--ny", "16", "--dt", &info.dt.to_string(), "--fps", "50"])
            .args(["--inputs", lct.to_str().unwrap()])
            .args(["--out", sim_out.to_str().unwrap()])
            .output()
            .expect("the lodcloth binary runs")
    });
    let text = String::from_utf8_lossy(&cli.stdout);
    assert!(
        cli.status.success() && text.contains(&format!("replaying {} inputs of 'rec'", logged.len())),
        "{text}{}",
        String::from_utf8_lossy(&cli.stderr)
    );
    let mut reader = lodcloth::output::TrajectoryReader::open(&sim_out.join("trajectory.lct")).expect("its trajectory");
    let mut last = None;
    while let Some(f) = reader.next_frame().expect("a frame") {
        last = Some(f);
    }
    let last = last.expect("frames");
    assert!(
        (last.time - replayed.state().time).abs() < 1e-9,
        "{} vs {}",
        last.time,
        replayed.state().time
    );
    let n = replayed.topology().n_nodes;
    let pos = &replayed.state().pos;
    for (k, p) in last.positions.iter().enumerate() {
        assert!(dist(*p, [pos[k], pos[n + k], pos[2 * n + k]]) < 1e-5);
    }

    // The touched session scored against a reference replaying its inputs
    // (the live error the daemon withholds while a cloth is touched): the
    // level itself as the reference scores zero to the wire's rounding;
    // the 24² reference (the instance's, at the scene's dt) scores the
    // level's real error under the touch.
    let recorded: Vec<(f64, Vec<f64>)> = frames
        .iter()
        .take_while({
            let mut last = f64::NEG_INFINITY;
            move |f| {
                let rising = f.time >= last;
                last = f.time;
                rising
            }
        })
        .map(|f| {
            let n = f.positions.len();
            let mut soa = vec![0.0; 3 * n];
            for (k, p) in f.positions.iter().enumerate() {
                for c in 0..3 {
                    soa[c * n + k] = p[c];
                }
            }
            (f.time, soa)
        })
        .collect();
    let score = |scene: &Scene, reference| {
        lodcloth::estimate::score_session(scene, reference, (16, 16), &recorded, &replay.script, &mut |_| {})
            .expect("scored")
    };
    let itself = score(&scene, (16, 16));
    let fine_scene = Scene::load(&scene_path("paper-1-top-edge.toml")).expect("scene");
    let fine = score(&fine_scene, (24, 24));
    eprintln!(
        "touched 16x16 against itself replayed: {:.2e} %; against the 24x24 reference replayed: mean {:.3} %, \
         max frame {:.3} % (O_max {:.3} m)",
        100.0 * itself.report.mean,
        100.0 * fine.report.mean,
        100.0 * fine.report.worst_frame_mean,
        fine.o_max
    );
    assert!(itself.report.mean < 1e-6, "{}", itself.report.mean);
    assert!(
        fine.report.mean > 1e-3 && fine.report.mean < 0.5,
        "{}",
        fine.report.mean
    );
    d.shutdown().await.expect("clean exit");
}

/// A recorder started in the middle of a touched episode gets the inputs
/// from before it subscribed (`<prefix>/<instance>/episode_inputs`), merged
/// with those it saw by their number: the recording holds every input of
/// the episode once, and replays from rest to the recorded states exactly.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_started_mid_episode_gets_the_inputs_before_it_and_replays_exactly() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("late", "late-b"));
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "late").await;
    let out = tempfile::tempdir().expect("temp dir");
    let lct = out.path().join("late.lct");
    let scene = Scene::load(&scene_path("paper-1-top-edge.toml")).expect("scene");
    let at = Patch {
        u: 0.5,
        v: 1.0,
        radius: 0.05,
    };
    let episode = latest(&c, "late").await.episode;
    let mut replies = vec![within(5, "grab", c.input("late", &grab_here(1, at)))
        .await
        .expect("grab")];
    let p0 = patch_position(&scene, &latest(&c, "late").await, at);
    let mv = |s: f64| v1::InputRequest {
        action: Some(Action::Move(v1::input_request::Move {
            id: 1,
            target: vec3([p0[0] + 0.2 * s, p0[1] + 0.1 * s, p0[2] + 0.2 * s]),
        })),
    };
    for k in 1..=6 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        replies.push(
            within(5, "move", c.input("late", &mv(f64::from(k) / 12.0)))
                .await
                .expect("move"),
        );
    }
    // The daemon's log of the episode so far. An input's event is logged
    // as the input takes effect, which can come after its reply: ask until
    // the seventh is there (or 5 s have passed).
    let log = within(5, "episode inputs", async {
        loop {
            let log = c.episode_inputs("late").await.expect("the log");
            if log.events.len() >= 7 {
                return log;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await;
    assert_eq!((log.episode, log.events.len(), log.complete), (episode, 7, true));
    let recorder = tokio::task::block_in_place(|| {
        start_recorder(&d, "late", &["--seconds", "2.0", "--out", lct.to_str().unwrap()])
    });
    for k in 7..=12 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        replies.push(
            within(5, "move", c.input("late", &mv(f64::from(k) / 12.0)))
                .await
                .expect("move"),
        );
    }
    let done = tokio::task::block_in_place(|| recorder.wait_with_output().expect("recorder"));
    let said = String::from_utf8_lossy(&done.stdout);
    eprintln!("{said}");
    assert!(
        done.status.success() && said.contains("with 13 inputs (7 from before the recording began)"),
        "{said}"
    );

    // Every input once, in order, as the replies named them.
    let logged = lodcloth::output::recorded_inputs(&lct).expect("the input log");
    assert_eq!(logged.len(), 13, "{logged:#?}");
    for (k, (e, reply)) in logged.iter().zip(&replies).enumerate() {
        assert_eq!(
            (e.seq, e.frame, e.time, e.episode),
            (k as u64 + 1, reply.frame, reply.time, episode)
        );
    }

    // From rest, with every input, the replay is the recording.
    let mut reader = lodcloth::output::TrajectoryReader::open(&lct).expect("the trajectory");
    let mut frames = Vec::new();
    while let Some(f) = reader.next_frame().expect("a frame") {
        frames.push(f);
    }
    let info = c.info("late").await.expect("info");
    let mut level_scene = scene.clone();
    level_scene.params.dt = info.dt;
    let all = lodcloth::output::Replay::of(&logged, None, &lct).expect("a replay");
    let (worst, mismatches, compared, _) = replay_recorded(&level_scene, &frames, Some(&all.script), 0.0, 0.0);
    // Without the grab, the moves after it do not even apply; the scene
    // alone is this far off.
    let (without, _, _, _) = replay_recorded(&level_scene, &frames, None, 0.0, 0.0);
    eprintln!(
        "recorded from t = {:.3} s: {compared} states, {mismatches} f32 positions differ from the replay with every input \
         (largest {worst:.1e} m); the scene without them {without:.3} m off",
        frames[0].time
    );
    assert!(compared >= 50, "only {compared} states");
    assert_eq!(mismatches, 0, "the replay is up to {worst} m from the recording");
    assert!(without > 0.01, "the earlier inputs moved the cloth only {without} m");
    drop(c);
    d.shutdown().await.expect("clean shutdown");
}
