//! `lodcloth-lab touched` on a recording made here: a 16² paper-1 cloth
//! dragged by a grab, its states and its input log written as the daemon's
//! recorder writes them. The binary's figures are the library's
//! (`estimate::score_session`) on the same states, and its CSV has a row
//! per scored state.

use std::path::{Path, PathBuf};

use lodcloth::estimate::{eased_drag, score_session};
use lodcloth::level::Level;
use lodcloth::output::{Precision, TrajectoryWriter};
use lodcloth::proto::{input_request, v1, WireLevel};
use lodcloth::scene::Scene;
use lodcloth::touch::{Input, Patch, Script, Touch};

fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/paper-1-top-edge.toml")
}

#[test]
fn a_recorded_session_is_scored_by_the_binary_as_by_the_library() {
    let scene = Scene::load(&scene_path()).expect("scene");
    let (nx, ny) = (16, 16);
    let mut sim = scene.build_at(nx, ny).expect("builds");
    let at = Patch {
        u: 0.5,
        v: 0.9,
        radius: 0.05,
    };
    // Where the patch is when the hand closes on it (nothing touched before).
    let t0 = 0.2;
    let start = {
        let mut free = scene.build_at(nx, ny).expect("builds");
        while free.state().time < t0 - 0.5 * free.params().dt {
            free.step();
        }
        let (nodes, weights) = at.weights(&free.topology().grid.expect("a grid"));
        let pos = &free.state().pos;
        let n = nx * ny;
        let mut p = [0.0; 3];
        for (&k, &w) in nodes.iter().zip(&weights) {
            for c in 0..3 {
                p[c] += w * pos[c * n + k as usize];
            }
        }
        p
    };
    let grab = Input::Grab {
        id: 1,
        at,
        target: None,
        stiffness: 20.0,
        damping: 0.1,
    };
    let script = Script::new(eased_drag(
        grab,
        t0,
        start,
        &[[start[0] + 0.1, start[1] + 0.2, start[2] + 0.1]],
        0.6,
        0.3,
        60.0,
    ))
    .expect("a valid drag");
    let dir = tempfile::tempdir().expect("temp dir");
    let lct = dir.path().join("session.lct");
    let dt = sim.params().dt;
    let every = ((1.0 / 60.0) / dt).round().max(1.0) as u64;
    let mut writer = TrajectoryWriter::create(&lct, nx * ny, Some((nx, ny)), dt, every as u32, Precision::F32, false)
        .expect("a trajectory");
    let mut touch = Touch::new(&scene);
    let mut next = 0;
    let mut logged = Vec::new();
    let mut recorded: Vec<(f64, Vec<f64>)> = Vec::new();
    while sim.state().time < 1.2 {
        let before = next;
        script.apply_due(&mut next, &mut touch, &mut sim).expect("applied");
        for (time, input) in &script.events()[before..next] {
            logged.push(v1::InputEvent {
                instance: "session".into(),
                frame: sim.state().step,
                time: *time,
                episode: 1,
                level: Some(Level::Grid { nx, ny }.to_wire()),
                input: Some(input_request(input)),
                idle: false,
                seq: logged.len() as u64 + 1,
            });
        }
        assert!(sim.step().finite);
        if sim.state().step.is_multiple_of(every) {
            writer.write(sim.state()).expect("a frame");
            // What the file holds: f32 positions.
            let pos = sim.state().pos.iter().map(|&x| f64::from(x as f32)).collect();
            recorded.push((sim.state().time, pos));
        }
    }
    writer.finish_with_inputs(Some(&logged)).expect("the input log");
    assert!(!logged.is_empty());

    let library = score_session(&scene, (24, 24), (nx, ny), &recorded, &script, &mut |_| {}).expect("scored");
    let out = dir.path().join("touched");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_lodcloth-lab"))
        .args(["touched", "--scene", scene_path().to_str().unwrap()])
        .args(["--recording", lct.to_str().unwrap(), "--reference", "24x24"])
        .args(["--out", out.to_str().unwrap()])
        .output()
        .expect("the lodcloth-lab binary runs");
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success() && text.contains(&format!("mean {:.3} %", 100.0 * library.report.mean)),
        "library mean {:.3} %\n{text}{}",
        100.0 * library.report.mean,
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        library.report.mean > 1e-4,
        "the 24² reference scores the 16² level's error under the drag"
    );
    assert!(out.join("touched.svg").exists());
    let rows = std::fs::read_to_string(out.join("touched.csv")).expect("the CSV");
    assert_eq!(rows.lines().count(), library.frames.len() + 1);
}
