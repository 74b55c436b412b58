//! Where a daemon instance passes through itself: the default config's
//! cloth `NAME`, its reference and every level, on the scene's own script
//! and under each of the three standard drags of the predictions under
//! input (`lodcloth_core::estimate::touched`), over the reference's span
//! at the daemon's dt, with the scene's coefficients at each level. Prints
//! per run the frames crossing (exact check, `sim::crossings`: each
//! reference frame, every 10th level step), how many were checked and the
//! most crossing pairs in one frame; and each level's stepping cost as a
//! share of one core in real time (a run without the checks).
//!
//! `cargo run --release -p lodcloth-lab --example crossing_survey -- NAME
//! [--contact on|off] [--why]`: `--contact` overrides the config's
//! `contact` for that instance (default: as configured); `--why` prints,
//! at a level's first crossing, each crossing pair and how far apart its
//! parts are at rest.

use std::sync::Arc;
use std::time::Instant;

use lodcloth::estimate::touched::{probes, record_touched, Hand};
use lodcloth::estimate::Method;
use lodcloth::plan::{Basis, Preparer};
use lodcloth::scene::Scene;
use lodcloth::service::config::ServiceConfig;
use lodcloth::sim::{crossings, Simulation, Topology};
use lodcloth::touch::Script;

/// The config's text with instance `name`'s `contact` line set to `on`.
fn with_contact(text: &str, name: &str, on: bool) -> String {
    let mut out = String::new();
    let mut inside = false;
    for line in text.lines() {
        if line.starts_with("name = ") {
            inside = line.contains(&format!("\"{name}\""));
        }
        if inside && line.starts_with("contact") {
            continue;
        }
        out.push_str(line);
        out.push('\n');
        if inside && line.starts_with("name = ") {
            out.push_str(&format!("contact = {{ self = {on} }}\n"));
        }
    }
    out
}

/// Frames crossing, frames checked, most pairs in one frame.
type Count = (usize, usize, usize);

/// Steps `sim` over `seconds`, applying `script` (if any) as the standard
/// drags are applied (a grab too stiff for the level softened as at a
/// switch); with `check`, counts crossings every 10th step.
fn run(sim: &mut Simulation, script: Option<&Script>, scene: &Scene, seconds: f64, check: bool, why: bool) -> Count {
    let dt = sim.params().dt;
    let steps = (seconds / dt).round() as usize;
    let mut hand = script.map(|script| Hand::new(script, scene));
    let (mut frames, mut worst) = (0, 0);
    for s in 0..steps {
        if let Some(hand) = &mut hand {
            hand.apply_due("the drag", sim).expect("the drag's inputs are accepted");
        }
        if !sim.step().finite {
            println!("    diverged at step {s}");
            break;
        }
        if check && s % 10 == 9 {
            let found = crossings(sim.topology(), &sim.state().pos);
            if !found.is_empty() {
                if why && frames == 0 {
                    explain(sim, &found);
                }
                frames += 1;
                worst = worst.max(found.len());
            }
        }
    }
    (frames, if check { steps / 10 } else { 0 }, worst)
}

/// Each crossing pair and how far apart its edge and triangle are at rest
/// (sampled: a diagnosis, not a bound).
fn explain(sim: &Simulation, found: &[lodcloth::sim::Crossing]) {
    let topology: &Topology = sim.topology();
    let rest = &topology.rest_positions;
    let at = |k: u32, s: f64| rest[k as usize].map(|x| x * s);
    for x in found {
        let tri = topology.triangles[x.triangle as usize];
        let mut best = f64::INFINITY;
        for i in 0..=20 {
            let f = i as f64 / 20.0;
            let p = [0, 1, 2].map(|c| at(x.edge[0], 1.0 - f)[c] + at(x.edge[1], f)[c]);
            for j in 0..=20 {
                for k in 0..=(20 - j) {
                    let (u, v) = (j as f64 / 20.0, k as f64 / 20.0);
                    let q = [0, 1, 2].map(|c| at(tri[0], 1.0 - u - v)[c] + at(tri[1], u)[c] + at(tri[2], v)[c]);
                    best = best.min((0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>().sqrt());
                }
            }
        }
        println!(
            "    t = {:.4} s: edge {:?} meets triangle {} {tri:?}, {:.2} mm apart at rest",
            sim.state().time,
            x.edge,
            x.triangle,
            best * 1e3
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args
        .first()
        .expect("usage: crossing_survey NAME [--contact on|off] [--why]")
        .clone();
    let contact = args
        .iter()
        .position(|a| a == "--contact")
        .map(|i| args.get(i + 1).map(String::as_str) == Some("on"));
    let why = args.iter().any(|a| a == "--why");
    let text = std::fs::read_to_string("config/default.toml").expect("run from the repository's root");
    let text = match contact {
        Some(on) => with_contact(&text, &name, on),
        None => text,
    };
    let config = ServiceConfig::from_toml(&text, "default.toml").expect("a valid config");
    let plan = config
        .instances
        .iter()
        .find(|i| i.name == name)
        .expect("an instance of the default config")
        .clone();
    let preparer = Preparer::new(Arc::new(plan.clone()), config.estimation, None);
    let started = Instant::now();
    let start = preparer.prepare(plan.start, Method::Same).expect("prepares");
    let Basis::Cloth(problem) = &start.basis else {
        panic!("{name} is not a cloth")
    };
    let reference = &problem.reference;
    let span = reference.spec.frames as f64 * reference.dt;
    println!(
        "{name} (self-contact {}): reference recorded in {:.0} s, span {span:.2} s",
        problem.scene.params.self_contact.is_some(),
        started.elapsed().as_secs_f64()
    );
    let drags = probes(&problem.scene, reference).expect("the standard drags");
    let count = |frames: &[Vec<f32>]| -> Count {
        let (mut crossing, mut worst) = (0, 0);
        for f in frames {
            let pos: Vec<f64> = f.iter().map(|&x| f64::from(x)).collect();
            let k = crossings(&reference.topology, &pos).len();
            crossing += usize::from(k > 0);
            worst = worst.max(k);
        }
        (crossing, frames.len(), worst)
    };
    let mut line = format!("| reference | {:?}", count(&reference.frames));
    for p in &drags {
        let r = record_touched(&problem.scene, reference, p, &|| false).expect("records");
        line += &format!(" | {:?}", count(&r.frames));
    }
    println!(
        "| level | script | {} | cost: script, drags (cores) |",
        drags.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(" | ")
    );
    println!("{line} | |");
    for &level in &plan.levels {
        let prepared = preparer.prepare(level, Method::Same).expect("prepares");
        let Basis::Cloth(lp) = &prepared.basis else {
            panic!("a cloth level")
        };
        let fresh = || preparer.live_simulation(&prepared).expect("builds");
        let mut cost = Vec::new();
        for script in std::iter::once(None).chain(drags.iter().map(|p| Some(&p.script))) {
            let started = Instant::now();
            run(&mut fresh(), script, &lp.scene, span, false, false);
            cost.push(format!("{:.2}", started.elapsed().as_secs_f64() / span));
        }
        let mut line = format!("| {level} | {:?}", run(&mut fresh(), None, &lp.scene, span, true, why));
        for p in &drags {
            line += &format!(
                " | {:?}",
                run(&mut fresh(), Some(&p.script), &lp.scene, span, true, why)
            );
        }
        println!("{line} | {} |", cost.join(", "));
    }
}
