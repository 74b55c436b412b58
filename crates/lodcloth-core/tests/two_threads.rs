//! A cloth large enough to split its step (`SPLIT_MIN_NODES`) gives the
//! same bits whether the halves run on one thread or on two, for every
//! integrator and both spring precisions, with wind (normals), strain
//! limiting and moving pins in play;
//! and the split changes nothing a cloth can tell from the whole evaluation
//! beyond rounding (the spring sums are compared in the kernel's own test,
//! `a_split_evaluation_adds_every_spring_once`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use lodcloth::scene::Scene;
use lodcloth::sim::{Integrator, Lender, Serial, Simulation, SpringPrecision, StabilityCheck, SPLIT_MIN_NODES};

const FLAG: &str = include_str!("../../../config/scenes/flag-2to1-wind.toml");
const CURTAIN: &str = include_str!("../../../config/scenes/curtain-shaken.toml");

/// A helper thread serving `lender` until the returned guard is dropped.
struct Helper {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<usize>>,
}

impl Helper {
    fn start(lender: Arc<Lender>) -> Helper {
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || lender.serve_until(&s));
        Helper {
            stop,
            thread: Some(thread),
        }
    }

    fn finish(mut self) -> usize {
        self.stop.store(true, Ordering::Relaxed);
        let t = self.thread.take().expect("running");
        t.thread().unpark();
        t.join().expect("helper")
    }
}

fn bits(sim: &Simulation) -> Vec<u64> {
    let s = sim.state();
    s.pos.iter().chain(&s.vel).map(|x| x.to_bits()).collect()
}

#[test]
fn a_split_step_is_bit_identical_on_one_thread_or_two() {
    let lender = Arc::new(Lender::new());
    let helper = Helper::start(lender.clone());
    for (text, name) in [(FLAG, "flag-2to1-wind.toml"), (CURTAIN, "curtain-shaken.toml")] {
        let base = Scene::from_toml(text, name).expect("shipped scene");
        for integrator in Integrator::ALL {
            let mut scene = base.clone();
            scene.params.integrator = integrator;
            scene.stability = StabilityCheck::Force;
            // 128×64 = 8192 nodes: the smallest cloth that splits.
            let (nx, ny) = (128, SPLIT_MIN_NODES / 128);
            let probe = scene.build_at(nx, ny).expect("builds");
            scene.params.dt = 0.3
                * probe
                    .dt_limit()
                    .min(probe.modal().dt_limit(Integrator::SymplecticEuler));
            for precision in SpringPrecision::ALL {
                let mut one = scene.build_at(nx, ny).expect("builds");
                one.set_spring_precision(precision);
                assert!(one.split().is_some(), "{name} {nx}x{ny} does not split");
                let mut two = one.clone();
                let steps = if integrator == Integrator::ImplicitEuler {
                    10
                } else {
                    60
                };
                for step in 0..steps {
                    let (r1, r2) = (one.step_on(&Serial), two.step_on(&*lender));
                    assert!(r1.finite, "{name} {integrator} diverged");
                    assert_eq!(r1.kinetic_energy.to_bits(), r2.kinetic_energy.to_bits());
                    assert_eq!(r1.elastic_energy.to_bits(), r2.elastic_energy.to_bits());
                    assert!(
                        bits(&one) == bits(&two),
                        "{name} {integrator} {precision}: states differ after step {step}"
                    );
                }
                // Plain `step` is the serial split.
                let mut three = scene.build_at(nx, ny).expect("builds");
                three.set_spring_precision(precision);
                for _ in 0..steps {
                    three.step();
                }
                assert!(
                    bits(&three) == bits(&one),
                    "{name} {integrator} {precision}: step() differs from step_on(Serial)"
                );
            }
        }
    }
    let ran = helper.finish();
    eprintln!("the helper ran {ran} halves");
    assert!(
        ran > 0,
        "the helper never took a half: the test compared serial with serial"
    );
}

#[test]
fn smaller_cloths_do_not_split() {
    let base = Scene::from_toml(FLAG, "flag-2to1-wind.toml").expect("shipped scene");
    let sim = base.build_at(64, 32).expect("builds");
    assert_eq!(sim.split(), None);
    let sim = base.build_at(128, 64).expect("builds");
    assert_eq!(sim.split(), Some(4096));
}
