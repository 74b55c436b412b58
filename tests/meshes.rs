//! A mesh cloth through the daemon, on loopback (issue 23): `info` gives
//! the level's triangles, rest shape and material coordinates; states carry
//! the level's vertices; a grab resolves on the mesh and pulls its patch to
//! the target; a switch to another level of the chain carries the state
//! exactly (the new vertices where the old surface was) and keeps the grab;
//! the page draws the mesh and picks the material point under the pointer.

use crate::browser;
use crate::clients::{pixel, px_dist, start_view, Camera};
use crate::daemon;

use daemon::*;
use lodcloth::level::Level;
use lodcloth::lod::Correlation;
use lodcloth::proto::{unpack_positions, v1, WireLevel};
use lodcloth::scene::Scene;
use lodcloth::sim::Topology;
use lodcloth::touch::Patch;
use prost::Message;
use std::sync::Arc;
use std::time::Duration;

use v1::input_request::Action;

/// A 0.6 × 0.4 m sheet of 3 cm near-equilateral triangles, horizontal,
/// pinned along its top edge: it falls and swings as paper scene 1 does.
const SCENE: &str = r#"
name = "mesh-sheet"
description = "A mesh sheet pinned along its top edge"
[cloth]
mesh = "sheet.obj"
areal_density = 0.2
[material]
stiffness = { stretch_u = 300.0, stretch_v = 300.0, shear = 40.0, bend_u = 1.0, bend_v = 1.0 }
damping_time = 1e-4
[simulation]
integrator = "symplectic_euler"
dt = 2e-4
duration = 6.0
drag = 0.5
[[pins]]
nodes = { edge = "top" }
"#;

/// The daemon with the sheet at three levels (every vertex, 60 %, 35 %),
/// starting at 60 %, each with the scene's own material made on it
/// (`same`: what this test checks is the serving, not an estimator); the
/// scene and its three levels.
fn start(dir: tempfile::TempDir) -> (Daemon, Scene, [Level; 3]) {
    let sheet = lodcloth::mesh::generate::sheet(0.6, 0.4, 0.03);
    std::fs::write(
        dir.path().join("sheet.obj"),
        lodcloth::mesh::generate::to_obj(&sheet, "sheet"),
    )
    .expect("mesh written");
    let scene_file = dir.path().join("mesh-sheet.toml");
    std::fs::write(&scene_file, SCENE).expect("scene written");
    let scene = Scene::load(&scene_file).expect("the scene");
    let all = scene.reference_level().nodes();
    let levels = [all, all * 3 / 5, all * 7 / 20].map(Level::Vertices);
    let port = free_port();
    let text = config_header(port, dir.path())
        + &format!(
            r#"
[estimation]
reference_steps = 5000
[[instances]]
name = "mesh"
scene = "{}"
levels = ["{}", "{}", "{}"]
start = "{}"
method = "same"
"#,
            scene_file.display(),
            levels[0],
            levels[1],
            levels[2],
            levels[1]
        );
    (Daemon::run(port, &text, dir), scene, levels)
}

/// The level's topology as the daemon builds it.
fn topology(scene: &Scene, level: Level) -> Arc<Topology> {
    scene.cloth_level(level).expect("the level").topology
}

/// Where patch `at` is in state `s`, which must be of `level`.
fn patch_position(scene: &Scene, level: Level, s: &v1::State, at: Patch) -> [f64; 3] {
    assert_eq!(level_of(s), level, "a state of {level}");
    crate::input::patch_position(scene, s, at)
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f64>().sqrt()
}

async fn latest(c: &lodcloth::service::client::Client) -> v1::State {
    collect_states(c, "mesh", 0.15)
        .await
        .into_iter()
        .rfind(|s| !s.transition)
        .expect("states keep coming")
}

/// How far patch `at` is from `target`, on average over the states of
/// `level` published in 0.3 s (a held patch still sways about its target).
async fn settled(
    c: &lodcloth::service::client::Client,
    scene: &Scene,
    level: Level,
    at: Patch,
    target: [f64; 3],
) -> f64 {
    let d: Vec<f64> = collect_states(c, "mesh", 0.3)
        .await
        .iter()
        .filter(|s| !s.transition && level_of(s) == level)
        .map(|s| dist(patch_position(scene, level, s, at), target))
        .collect();
    assert!(d.len() > 5, "{} states of {level} in 0.3 s", d.len());
    d.iter().sum::<f64>() / d.len() as f64
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mesh_instance_is_served_touched_and_switched_without_a_jump() {
    let _serial = daemon::serial().await;
    let (d, scene, levels) = start(tempfile::tempdir().expect("temp dir"));
    let [_, start_level, coarse] = levels;
    let c = client(&[d.endpoint()]).await;
    let info = wait_info(&c, "mesh").await;

    // What a client draws and touches with.
    let topo = topology(&scene, start_level);
    let n = topo.n_nodes;
    assert_eq!(info.kind, "cloth");
    assert_eq!(Level::from_wire(info.level.as_ref().expect("a level")), Ok(start_level));
    assert_eq!(
        Level::from_wire(info.reference.as_ref().expect("a reference")),
        Ok(scene.reference_level())
    );
    assert_eq!(info.triangles.len(), 3 * topo.triangles.len());
    assert!(info.triangles.iter().all(|&k| (k as usize) < n));
    let rest = unpack_positions(&info.rest_positions).expect("rest positions");
    assert_eq!(rest.len(), 3 * n, "the level's {n} vertices");
    let uv: Vec<f32> = info
        .material_uv
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect();
    let want = topo.material_uv().expect("material coordinates");
    assert_eq!(uv.len(), 2 * n);
    assert!(
        want.iter().flatten().zip(&uv).all(|(&a, &b)| (a as f32) == b),
        "the level's UVs"
    );
    for l in &info.levels {
        assert!(matches!(
            Level::from_wire(l.level.as_ref().expect("a level")),
            Ok(Level::Vertices(_))
        ));
    }

    // It falls from its pinned edge (the states are the level's vertices).
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let before = latest(&c).await;
    let pos = unpack_positions(&before.positions).expect("positions");
    assert_eq!(pos.len(), 3 * n);
    let dropped = (0..n).map(|k| rest[n + k] - pos[n + k]).fold(0.0, f64::max);
    assert!(dropped > 0.1, "the free edge fell only {dropped} m");
    // Foxglove gets the level's triangles over its vertices, as for a grid.
    let (update, _) = lodcloth::foxglove_bridge::scene_update(&before, &info).expect("a scene update");
    let drawn = &update.entities[0].triangles[0];
    assert_eq!((drawn.points.len(), &drawn.indices), (n, &info.triangles));
    assert_eq!(drawn.colors.len(), n, "a colour per vertex");

    // A grab on the free edge's middle, pulled out and up from where it
    // hangs at rest: 0.4 m straight below the pinned edge's middle. Not
    // from where it is now: the cloth still swings, and a target taken on
    // a swing's far side was out of the cloth's reach (CI, and 1 run in 3
    // here: the patch stopped 0.093 m short of a target 0.269 m from it).
    let at = Patch {
        u: 0.5,
        v: 1.0,
        radius: 0.04,
    };
    let pinned = patch_position(&scene, start_level, &before, Patch { v: 0.0, ..at });
    let hanging = [pinned[0], pinned[1] - 0.4, pinned[2]];
    let target = [hanging[0], hanging[1] + 0.1, hanging[2] + 0.2];
    let away = dist(hanging, target);
    let grab = v1::InputRequest {
        action: Some(Action::Grab(v1::input_request::Grab {
            id: 1,
            at: Some(v1::Patch {
                u: at.u,
                v: at.v,
                radius: at.radius,
            }),
            target: crate::input::vec3(target),
            stiffness: 20.0,
            damping: 0.2,
        })),
    };
    let reply = within(5, "grab", c.input("mesh", &grab))
        .await
        .expect("the grab is accepted");
    assert_eq!(reply.grabs, vec![1]);
    tokio::time::sleep(Duration::from_millis(2500)).await;
    let left = settled(&c, &scene, start_level, at, target).await;
    eprintln!(
        "mesh grab: the target {away:.3} m from where the patch hangs at rest and {:.3} m from where it was; {left:.3} m after 2.5 s",
        dist(patch_position(&scene, start_level, &before, at), target)
    );
    assert!(
        left < 0.3 * away,
        "the patch is still {left} m from its target (was {away})"
    );

    // A switch mid-drag: the new level's vertices start on the old
    // surface (the correlation of the chain), so nothing jumps.
    let sub = c
        .session
        .declare_subscriber(lodcloth::service::keys::state(PREFIX, "mesh"))
        .await
        .expect("subscriber");
    let request = v1::SwitchRequest {
        at_once: false,
        target: Some(v1::switch_request::Target::Level(coarse.to_wire())),
        method: String::new(),
    };
    let switched = within(120, "switch", c.switch("mesh", &request, Duration::from_secs(120)))
        .await
        .expect("switch accepted");
    assert!(switched.predicted_error.is_some(), "{switched:?}");
    let (old, new) = within(10, "the transition pair", async {
        let mut previous: Option<v1::State> = None;
        loop {
            let s = sub.recv_async().await.expect("state");
            let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
            if s.transition {
                if let Some(p) = previous.take().filter(|p| level_of(p) == start_level) {
                    if level_of(&s) == coarse {
                        return (p, s);
                    }
                }
                previous = Some(s);
            }
        }
    })
    .await;
    assert_eq!(old.time, new.time, "one instant");
    let coarse_topo = topology(&scene, coarse);
    let carry = Correlation::between(&topo, &coarse_topo).expect("correlation");
    let (old_pos, new_pos) = (
        unpack_positions(&old.positions).expect("old"),
        unpack_positions(&new.positions).expect("new"),
    );
    assert_eq!(new_pos.len(), 3 * coarse_topo.n_nodes);
    let mut mapped = vec![0.0; new_pos.len()];
    carry.map(&old_pos, &mut mapped);
    let jump = mapped
        .iter()
        .zip(&new_pos)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    // Both sides went through f32 on the wire.
    assert!(jump < 1e-5, "a vertex of the new level is {jump} m off the old surface");
    eprintln!(
        "at the switch the patch is {:.4} m (old level) and {:.4} m (new level) from its target",
        dist(patch_position(&scene, start_level, &old, at), target),
        dist(patch_position(&scene, coarse, &new, at), target)
    );
    let track = within(5, "a second after", async {
        let mut out = Vec::new();
        while out.len() < 30 {
            let s = sub.recv_async().await.expect("state");
            let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
            out.push((s.time, dist(patch_position(&scene, coarse, &s, at), target)));
        }
        out
    })
    .await;
    // Nor in the steps after it: the grab holds the patch all along.
    let worst = track.iter().map(|&(_, d)| d).fold(0.0, f64::max);
    eprintln!(
        "the first {} states after the switch: the patch at most {worst:.4} m from its target",
        track.len()
    );
    assert!(
        worst < 0.3 * away,
        "after the switch the patch jerked {worst} m from its target: {track:?}"
    );
    drop(sub);
    tokio::time::sleep(Duration::from_millis(1000)).await;
    let after = latest(&c).await;
    assert_eq!(level_of(&after), coarse);
    let m = crate::clients::next_metrics(&c, "mesh").await;
    assert!(m.touched && m.inputs == 1, "touched {} inputs {}", m.touched, m.inputs);
    let still = settled(&c, &scene, coarse, at, target).await;
    assert!(
        still < 0.3 * away,
        "after the switch the patch drifted to {still} m from its target"
    );

    // The page draws the mesh and picks the material point under the
    // pointer (on the mesh's own material coordinates).
    if browser::available("a_mesh_instance_is_served_touched_and_switched_without_a_jump") {
        let (base, stop_view) = start_view(d.endpoint()).await;
        let mut page = browser::Browser::open(&format!("{base}/?instance=mesh")).await;
        page.wait_for(
            30,
            "the mesh drawn",
            &format!("(window.lodclothStats?.statesDrawn ?? 0) > 5 && window.lodclothStats.level === '{coarse}'"),
        )
        .await;
        let sub = c
            .session
            .declare_subscriber(lodcloth::service::keys::state(PREFIX, "mesh"))
            .await
            .expect("subscriber");
        let paused = within(5, "pause", c.control("mesh", v1::control_request::Action::Pause))
            .await
            .expect("paused");
        let still = within(10, "the paused state", async {
            loop {
                let s = sub.recv_async().await.expect("state");
                let s = v1::State::decode(s.payload().to_bytes().as_ref()).expect("State");
                if s.frame == paused.frame {
                    return s;
                }
            }
        })
        .await;
        page.wait_for(
            10,
            "the paused mesh drawn",
            &format!("window.lodclothStats.frame === {}", paused.frame),
        )
        .await;
        page.click("#reset-view").await;
        let camera = Camera::of(&mut page).await;
        let (u, v) = (0.3, 0.7);
        let drawn = pixel(&page.eval(&format!("window.lodclothProject({u}, {v})")).await);
        let daemon = camera.project(patch_position(&scene, coarse, &still, Patch { u, v, radius: 0.0 }));
        assert!(
            px_dist(drawn, daemon) < 2.0,
            "the page draws ({u}, {v}) at {drawn:?}, the daemon has it at {daemon:?}"
        );
        page.mouse_press(drawn[0], drawn[1]).await;
        page.wait_for(10, "the grab held", "window.lodclothInput.held === true")
            .await;
        let g = page.eval("window.lodclothInput.grab").await;
        let (gu, gv) = (g["u"].as_f64().expect("u"), g["v"].as_f64().expect("v"));
        // The page grabs the surface nearest the eye under the pointer: the
        // point pressed on, or one in front of it where the cloth folds
        // over it. Either way the daemon has the grabbed (u, v) under the
        // pointer, which only the mesh's own material coordinates give.
        let x_uv = patch_position(&scene, coarse, &still, Patch { u, v, radius: 0.0 });
        let x_grab = patch_position(
            &scene,
            coarse,
            &still,
            Patch {
                u: gu,
                v: gv,
                radius: 0.0,
            },
        );
        let under = px_dist(camera.project(x_grab), drawn);
        eprintln!(
            "pressed on ({u}, {v}) of the mesh, the page grabbed ({gu:.4}, {gv:.4}), which the daemon has {under:.2} px from the press"
        );
        assert!(under < 3.0, "the grabbed ({gu}, {gv}) is {under} px from the press");
        assert!(
            ((gu - u).abs() < 0.01 && (gv - v).abs() < 0.01) || camera.depth(x_grab) < camera.depth(x_uv),
            "pressed on ({u}, {v}), the page grabbed ({gu}, {gv}), which is not in front of it"
        );
        page.mouse_release(drawn[0], drawn[1]).await;
        let _ = stop_view.send(());
    }
    drop(c);
    d.shutdown().await.expect("clean shutdown");
}
