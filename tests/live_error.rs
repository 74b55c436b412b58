//! Issue 22: the live error while a client touches the cloth. The daemon's
//! shadow reference re-runs under the episode's inputs on a background
//! thread; the error it publishes (`Metrics.live_error`, of the simulated
//! time `live_error_time`) must be what the level and the reference give
//! when both are replayed offline under the inputs the daemon published.

use crate::daemon;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use prost::Message;

use daemon::*;
use lodcloth::lod::Correlation;
use lodcloth::proto::v1;
use lodcloth::scene::Scene;
use lodcloth::service::client::Client;
use lodcloth::service::keys;
use lodcloth::touch::{Patch, Touch};

use crate::input::{patch_position, vec3};

use v1::input_request::Action;

/// (scheduling policy, nice) of each thread of this process named `name`
/// (as the kernel keeps it: the first 15 bytes), from
/// `/proc/self/task/*/stat` (fields 41 and 19).
#[cfg(target_os = "linux")]
fn thread_classes(name: &str) -> Vec<(i32, i32)> {
    let mut out = Vec::new();
    for task in std::fs::read_dir("/proc/self/task").expect("the process's threads") {
        let dir = task.expect("a thread").path();
        // A thread may end while it is read.
        let (Ok(comm), Ok(stat)) = (
            std::fs::read_to_string(dir.join("comm")),
            std::fs::read_to_string(dir.join("stat")),
        ) else {
            continue;
        };
        if comm.trim_end() != &name[..name.len().min(15)] {
            continue;
        }
        // Fields from the third on follow the parenthesised name.
        let fields: Vec<&str> = stat[stat.rfind(')').expect("a stat line") + 2..].split(' ').collect();
        out.push((
            fields[41 - 3].parse().expect("policy"),
            fields[19 - 3].parse().expect("nice"),
        ));
    }
    out
}

/// Every message on `key` from now on, decoded.
async fn collect<M: Message + Default + Send + 'static>(c: &Client, key: String) -> Arc<Mutex<Vec<M>>> {
    let sub = c.session.declare_subscriber(key).await.expect("subscriber");
    let out = Arc::new(Mutex::new(Vec::new()));
    let sink = out.clone();
    tokio::spawn(async move {
        while let Ok(s) = sub.recv_async().await {
            let m = M::decode(s.payload().to_bytes().as_ref()).expect("a message");
            sink.lock().expect("messages").push(m);
        }
    });
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn while_a_client_drags_the_live_error_is_the_reference_replaying_the_same_inputs() {
    let _serial = daemon::serial().await;
    let d = Daemon::start(("live", "live-b"));
    let c = client(&[d.endpoint()]).await;
    wait_info(&c, "live").await;
    let metrics = collect::<v1::Metrics>(&c, keys::metrics(PREFIX, "live")).await;
    let inputs = collect::<v1::InputEvent>(&c, keys::inputs(PREFIX, "live")).await;
    let states = collect::<v1::State>(&c, keys::state(PREFIX, "live")).await;
    let newest = |m: &Arc<Mutex<Vec<v1::Metrics>>>| m.lock().expect("metrics").last().cloned();

    // The shadow reference is up (the level's estimate is in), and the
    // episode is early enough to touch before it would loop.
    within(120, "a live error early in an episode", async {
        while !newest(&metrics).is_some_and(|m| m.live_error.is_some() && (0.5..2.5).contains(&m.time)) {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await;
    let untouched = newest(&metrics).expect("metrics");
    let interval = 25.0 * 1e-3; // metric_stride × the reference's dt
    let lag = untouched.time - untouched.live_error_time.expect("the time of the live error");
    assert!(
        (0.0..=interval + 1e-9).contains(&lag),
        "untouched, the live error is of t = {:?}, the cloth at t = {}",
        untouched.live_error_time,
        untouched.time
    );

    // A hand takes the bottom edge and carries it up and out over 0.6 s,
    // holds it, then lets go.
    let latest_state = || states.lock().expect("states").last().cloned().expect("states");
    let scene = Scene::load(&scene_path("paper-1-top-edge.toml")).expect("scene");
    let at = Patch {
        u: 0.5,
        v: 1.0,
        radius: 0.05,
    };
    let grab = grab_where_it_is(1, at, 4.0, 0.1);
    let reply = within(5, "grab", c.input("live", &grab)).await.expect("grab");
    // The replica runs in the class of work a client waits for (nice 19),
    // above the SCHED_IDLE predictions under input that start with the
    // touch and take both cores' idle time.
    #[cfg(target_os = "linux")]
    {
        let mut classes = Vec::new();
        for _ in 0..100 {
            classes = thread_classes("lodcloth-replica-live");
            if classes == [(libc::SCHED_OTHER, 19)] {
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert_eq!(
            classes,
            [(libc::SCHED_OTHER, 19)],
            "the replica's (policy, nice); SCHED_IDLE is {}",
            libc::SCHED_IDLE
        );
    }
    let n = 16 * 16;
    let bottom = patch_position(&scene, &latest_state(), at);
    for k in 1..=12 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        let f = f64::from(k) / 12.0;
        let mv = v1::InputRequest {
            action: Some(Action::Move(v1::input_request::Move {
                id: 1,
                target: vec3([bottom[0], bottom[1] + 0.3 * f, bottom[2] + 0.4 * f]),
            })),
        };
        within(5, "move", c.input("live", &mv)).await.expect("move");
    }
    tokio::time::sleep(Duration::from_millis(1000)).await;
    let release = v1::InputRequest {
        action: Some(Action::Release(v1::input_request::Release { id: 1 })),
    };
    within(5, "release", c.input("live", &release)).await.expect("release");
    tokio::time::sleep(Duration::from_millis(1000)).await;

    // What the daemon published: its inputs, and the live errors of times
    // from the first input on.
    let logged = inputs.lock().expect("inputs").clone();
    assert_eq!(logged.len(), 14, "{logged:#?}");
    assert_eq!((logged[0].frame, logged[0].time), (reply.frame, reply.time));
    let first = reply.time;
    let now = newest(&metrics).expect("metrics");
    // This episode's metrics: from the first input until the scene would
    // start over (time going back).
    let episode: Vec<v1::Metrics> = {
        let all = metrics.lock().expect("metrics");
        let from = all.iter().position(|m| m.time > first).expect("metrics after the grab");
        let mut out = vec![all[from].clone()];
        for m in &all[from + 1..] {
            if m.time < out.last().expect("one").time {
                break;
            }
            out.push(m.clone());
        }
        out
    };
    let mut touched: Vec<(f64, f64)> = episode
        .iter()
        .filter_map(|m| Some((m.live_error_time?, m.live_error?)))
        .filter(|(t, _)| *t > first)
        .collect();
    touched.dedup_by(|a, b| a.0 == b.0);
    let lags: Vec<f64> = episode
        .iter()
        .filter_map(|m| Some(m.time - m.live_error_time?))
        .collect();
    let mut sorted = lags.clone();
    sorted.sort_by(f64::total_cmp);
    eprintln!(
        "{} live errors while touched (from t = {first:.3} s to {:.3} s): {:.3} % to {:.3} %; \
         the replay's lag p50 {:.0} ms, max {:.0} ms; the cloth at t = {:.3} s",
        touched.len(),
        touched.last().map_or(f64::NAN, |t| t.0),
        100.0 * touched.iter().map(|t| t.1).fold(f64::INFINITY, f64::min),
        100.0 * touched.iter().map(|t| t.1).fold(0.0, f64::max),
        1e3 * sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN),
        1e3 * sorted.last().copied().unwrap_or(f64::NAN),
        now.time,
    );
    assert!(
        touched.len() >= 10,
        "only {} live errors while the cloth was touched: {:?}",
        touched.len(),
        touched
    );
    assert!(
        touched.last().expect("errors").0 > first + 2.0,
        "the replay got only to t = {:?} (first input at {first})",
        touched.last()
    );

    // The truth: the level and the reference replayed offline under the
    // published inputs, compared at the same times the same way.
    let replay = lodcloth::output::Replay::of(&logged, None, std::path::Path::new("the bus")).expect("a replay");
    let info = c.info("live").await.expect("info");
    let o_max = info.o_max;
    assert!(o_max > 0.0, "the recorded reference's largest displacement: {o_max}");
    let mut level_scene = scene.clone();
    level_scene.params.dt = info.dt;
    assert_eq!(
        info.coefficients,
        Some(lodcloth::proto::coefficients(&scene.material_at(16, 16))),
        "the level runs the scene's material (method same)"
    );
    let mut level = level_scene.build_at(16, 16).expect("the level");
    let mut reference = scene.build_at(24, 24).expect("the reference");
    let correlation = Correlation::grids(&scene.shape(24, 24), &scene.shape(16, 16)).expect("correlation");
    let (mut level_touch, mut reference_touch) = (Touch::new(&scene), Touch::new(&scene));
    let (mut next_l, mut next_r) = (0, 0);
    let mut mapped = vec![0.0; 3 * n];
    let mut worst = 0.0f64;
    let mut largest = 0.0f64;
    for (t, live) in &touched {
        for (sim, touch, next) in [
            (&mut level, &mut level_touch, &mut next_l),
            (&mut reference, &mut reference_touch, &mut next_r),
        ] {
            let dt = sim.params().dt;
            while sim.state().time < t - 0.5 * dt {
                replay.script.apply_due(next, touch, sim).expect("replays");
                sim.step();
            }
        }
        correlation.map(&reference.state().pos, &mut mapped);
        let pos = &level.state().pos;
        let offline = (0..n)
            .map(|k| {
                (0..3)
                    .map(|c| (mapped[c * n + k] - pos[c * n + k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum::<f64>()
            / n as f64
            / o_max;
        worst = worst.max((live - offline).abs());
        largest = largest.max(offline);
    }
    eprintln!(
        "offline replay of level and reference: the live errors agree within {worst:.1e} (largest {:.3} %)",
        100.0 * largest
    );
    assert!(worst <= 1e-9, "a live error is {worst} from the offline replay's");
    // The touch moved the cloth away from its script: the replay is not the
    // recording (against which the level would be far off).
    assert!(largest > 0.0);
    drop(c);
    d.shutdown().await.expect("clean shutdown");
}
