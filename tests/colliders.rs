//! Colliders through the daemon, on loopback: `info` describes the scene's
//! body with the triangles clients draw, every state says where the moving
//! body is at its time and has no node inside it, the cloth rides up on it,
//! a level switch keeps the cloth out of it, and the page draws it there.

use crate::browser;
use crate::daemon;

use daemon::*;
use lodcloth::plan::Level;
use lodcloth::proto::{unpack_positions, v1, WireLevel};
use lodcloth::scene::Scene;
use serde_json::json;
use std::time::Duration;

/// A 0.6 m cloth falling 5 cm onto a ball that rises 0.2 m from t = 0.4 s
/// to 1.4 s; levels 6² and 8², reference 12².
const SCENE: &str = r#"
name = "ball-lift"
description = "A cloth falling on a ball that rises"
[cloth]
width = 0.6
height = 0.6
nx = 12
ny = 12
areal_density = 0.2
[springs]
structural = { k = 60.0, c = 0.006 }
shear = { k = 10.0, c = 0.001 }
bend = { k = 1.0, c = 0.0001 }
[simulation]
integrator = "symplectic_euler"
dt = 5e-4
duration = 2.0
drag = 1.0
[[colliders]]
shape = "sphere"
center = [0.3, -0.2, 0.3]
radius = 0.15
friction = 0.5
clearance = 0.004
path = { kind = "linear", velocity = [0.0, 0.2, 0.0], start = 0.4, end = 1.4 }
"#;

fn start(dir: tempfile::TempDir) -> (Daemon, Scene) {
    let scene_file = dir.path().join("ball-lift.toml");
    std::fs::write(&scene_file, SCENE).expect("scene written");
    let port = free_port();
    let text = config_header(port, dir.path())
        + &format!(
            r#"
[estimation]
reference_steps = 2000
[[instances]]
name = "ball"
scene = "{}"
reference = "12x12"
levels = ["6x6", "8x8"]
start = "8x8"
method = "same"
"#,
            scene_file.display()
        );
    let scene = Scene::from_toml(SCENE, "ball-lift").expect("the scene");
    (Daemon::run(port, &text, dir), scene)
}

/// Nodes of a state (xyz each).
fn nodes(s: &v1::State) -> Vec<[f64; 3]> {
    let soa = unpack_positions(&s.positions).expect("positions");
    let n = soa.len() / 3;
    (0..n).map(|k| [soa[k], soa[n + k], soa[2 * n + k]]).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_moving_body_is_described_placed_in_every_state_and_never_entered_at_any_level() {
    let _serial = daemon::serial().await;
    let (d, scene) = start(tempfile::tempdir().expect("temp dir"));
    let body = scene.colliders()[0];
    let c = client(&[d.endpoint()]).await;
    let info = wait_info(&c, "ball").await;
    assert_eq!(info.colliders.len(), 1);
    let wire = &info.colliders[0];
    assert_eq!((wire.shape.as_str(), wire.radius), ("sphere", 0.15));
    assert_eq!((wire.friction, wire.clearance), (0.5, 0.004));
    let p = wire.position.as_ref().expect("a position");
    assert_eq!([p.x, p.y, p.z], [0.3, -0.2, 0.3]);
    assert_eq!(
        unpack_positions(&wire.triangles).expect("triangles").len() / 3,
        body.shape.triangles(4.0).len(),
        "the drawing the core makes"
    );

    // Over most of a loop, through the lift, then after a switch.
    let mut checked = (0, 0);
    let mut lifted = false;
    for (seconds, level) in [(1.6, Level::new(8, 8)), (0.6, Level::new(6, 6))] {
        if level == Level::new(6, 6) {
            let request = v1::SwitchRequest {
                at_once: false,
                target: Some(v1::switch_request::Target::Level(level.to_wire())),
                method: String::new(),
            };
            let r = within(60, "switch", c.switch("ball", &request, Duration::from_secs(60))).await;
            assert!(r.is_ok(), "switch: {r:?}");
        }
        for s in collect_states(&c, "ball", seconds).await {
            if level_of(&s) != level {
                continue;
            }
            let at = unpack_positions(&s.collider_positions).expect("collider positions");
            let (centre, _) = body.at(s.time);
            for axis in 0..3 {
                assert!(
                    (at[axis] - centre[axis]).abs() < 1e-6,
                    "t = {}: body at {at:?}, its path says {centre:?}",
                    s.time
                );
            }
            for (k, x) in nodes(&s).iter().enumerate() {
                let gap = body.distance(*x, s.time);
                assert!(
                    gap > body.clearance - 1e-5,
                    "t = {}, {level}: node {k} is {gap} m from the ball",
                    s.time
                );
            }
            // Riding up on the ball once the lift is over: lying on it,
            // its nearest nodes at the clearance from its risen surface.
            if s.time > 1.5 && level == Level::new(8, 8) {
                let nearest = nodes(&s)
                    .iter()
                    .map(|x| body.distance(*x, s.time))
                    .fold(f64::MAX, f64::min);
                assert!(
                    (nearest - body.clearance).abs() < 1e-4,
                    "t = {}: the cloth's nearest node is {nearest} m from the risen ball",
                    s.time
                );
                lifted = true;
            }
            if level == Level::new(8, 8) {
                checked.0 += 1;
            } else {
                checked.1 += 1;
            }
        }
    }
    eprintln!("states checked: {} at 8x8, {} at 6x6", checked.0, checked.1);
    assert!(checked.0 > 20 && checked.1 > 10, "{checked:?}");
    assert!(lifted, "no state after the lift");

    // The page draws the ball where the states put it.
    if browser::available("a_moving_body_is_described_placed_in_every_state_and_never_entered_at_any_level") {
        let (base, stop_view) = crate::clients::start_view(d.endpoint()).await;
        let mut page = browser::Browser::open(&format!("{base}/?instance=ball")).await;
        page.wait_for(
            30,
            "the ball drawn",
            "(window.lodclothStats?.collidersDrawn ?? 0) === 1",
        )
        .await;
        let stats = page.eval("window.lodclothStats").await;
        assert_eq!(stats["colliders"][0][0], json!(0.30000001192092896), "{stats}");
        let lit = page.eval("window.lodclothCanvasDigest()").await["lit"]
            .as_f64()
            .expect("lit");
        assert!(lit > 0.005, "the canvas is drawn: {lit}");
        let _ = stop_view.send(());
    }
    drop(c);
    d.shutdown().await.expect("clean shutdown");
}
