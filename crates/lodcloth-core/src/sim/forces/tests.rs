//! The kernel against itself: every instruction set gives the same bits,
//! in both precisions, and a split evaluation adds every spring once.

use super::super::params::SpringCoeffs;
use super::super::simd::{self, Isa};
use super::super::topology::{GridShape, Orientation};
use super::*;

/// Rest shape moved by up to ±`amp` per coordinate, velocities up to ±1,
/// from a fixed-seed generator.
fn random_state(topology: &Topology, seed: u64, amp: f64) -> (Vec<f64>, Vec<f64>) {
    let mut x = seed;
    let mut next = move || {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let n = topology.n_nodes;
    let mut pos = vec![0.0; 3 * n];
    let mut vel = vec![0.0; 3 * n];
    for k in 0..n {
        for c in 0..3 {
            pos[c * n + k] = topology.rest_positions[k][c] + amp * next();
            vel[c * n + k] = next();
        }
    }
    // Two coincident nodes: the MIN_LENGTH guard.
    for c in 0..3 {
        pos[c * n + 1] = pos[c * n];
    }
    (pos, vel)
}

/// Different K and C per spring class, so a spring counted in the wrong
/// class shows.
fn test_material() -> Material {
    Material {
        springs: [
            SpringCoeffs { k: 40.0, c: 0.3 },
            SpringCoeffs { k: 31.0, c: 0.2 },
            SpringCoeffs { k: 9.0, c: 0.07 },
            SpringCoeffs { k: 2.5, c: 0.02 },
            SpringCoeffs { k: 1.5, c: 0.03 },
        ],
    }
}

fn gathered(topology: &Topology) -> Topology {
    let mut t = topology.clone();
    t.grid = None;
    for g in &mut t.groups {
        g.stencil_offset = None;
        g.runs.clear();
    }
    t
}

/// Every instruction set gives the same bits, in both precisions.
#[test]
fn dispatch_paths_are_bit_identical() {
    dispatch_identical::<f64>();
    dispatch_identical::<f32>();
}

fn dispatch_identical<R: KernelReal>() {
    let material = test_material();
    let isas: Vec<Isa> = Isa::supported().collect();
    eprintln!("{}: instruction sets compared: {isas:?}", R::NAME);
    for (nx, ny) in [(2, 2), (3, 7), (9, 4), (17, 6), (64, 64), (63, 5)] {
        let shape = GridShape {
            nx,
            ny,
            width: 0.4,
            height: 0.3,
        };
        let grid = Topology::grid(shape, Orientation::Horizontal);
        for topology in [grid.clone(), gathered(&grid)] {
            let (pos, vel) = random_state(&topology, (nx * 100 + ny) as u64, 0.02);
            let (pos, vel): (Vec<R>, Vec<R>) = (
                pos.iter().map(|&x| R::from_f64(x)).collect(),
                vel.iter().map(|&x| R::from_f64(x)).collect(),
            );
            // The forces with the figures, per adjustment, for the runs
            // without them.
            let mut full: Vec<(u64, Vec<u64>)> = Vec::new();
            for (adjust_ratio, stats) in [
                (f64::INFINITY, true),
                (1.05, true),
                (f64::INFINITY, false),
                (1.05, false),
            ] {
                let results: Vec<(Vec<u64>, SpringTotals)> = isas
                    .iter()
                    .map(|&isa| {
                        let mut scratch = KernelScratch::<R>::new(&topology);
                        let mut force = vec![R::ZERO; pos.len()];
                        let totals = simd::run(
                            isa,
                            // Inlined, so it is compiled for `isa`.
                            #[inline(always)]
                            || {
                                spring_forces_impl(
                                    &topology,
                                    &material,
                                    adjust_ratio,
                                    &pos,
                                    &vel,
                                    &mut force,
                                    &mut scratch,
                                    stats,
                                )
                            },
                        );
                        assert!(force.iter().all(|f| f.to_f64().is_finite()));
                        (force.iter().map(|f| f.to_f64().to_bits()).collect(), totals)
                    })
                    .collect();
                for (isa, r) in isas.iter().zip(&results) {
                    assert!(
                        r.0 == results[0].0,
                        "{} {nx}x{ny}: {isa:?} forces differ from {:?}",
                        R::NAME,
                        isas[0]
                    );
                    assert_eq!(r.1.elastic_energy.to_bits(), results[0].1.elastic_energy.to_bits());
                    assert_eq!(
                        r.1.max_strain.map(f64::to_bits),
                        results[0].1.max_strain.map(f64::to_bits)
                    );
                    // Without the figures: the same forces, and NaN for them.
                    if !stats {
                        assert!(r.1.elastic_energy.is_nan() && r.1.max_strain.iter().all(|m| m.is_nan()));
                    }
                }
                let key = adjust_ratio.to_bits();
                match full.iter().find(|(k, _)| *k == key) {
                    Some((_, forces)) => assert!(
                        *forces == results[0].0,
                        "{} {nx}x{ny}: forces without the figures differ",
                        R::NAME
                    ),
                    None => full.push((key, results[0].0.clone())),
                }
            }
        }
    }
}

/// The split evaluation adds the same springs as the whole one, in
/// another order: forces equal to rounding, every spring counted once
/// (energy), the same largest strain; and the same bits whether the
/// halves ran on one thread or two.
#[test]
fn a_split_evaluation_adds_every_spring_once() {
    use super::super::pair::{Lender, Serial};
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let material = test_material();
    let lender = Arc::new(Lender::new());
    let stop = Arc::new(AtomicBool::new(false));
    let helper = {
        let (lender, stop) = (lender.clone(), stop.clone());
        std::thread::spawn(move || lender.serve_until(&stop))
    };
    for (nx, ny, orientation) in [
        (12, 9, Orientation::Horizontal),
        (33, 20, Orientation::Vertical),
        (64, 64, Orientation::Horizontal),
    ] {
        let shape = GridShape {
            nx,
            ny,
            width: 0.4,
            height: 0.3,
        };
        let topology = Topology::grid(shape, orientation);
        let (pos, vel) = random_state(&topology, (nx * 7 + ny) as u64, 0.02);
        let isa = Isa::best();
        for adjust_ratio in [f64::INFINITY, 1.05] {
            let mut whole = vec![0.0; pos.len()];
            let mut scratch = KernelScratch::new(&topology);
            let t = spring_forces(
                &topology,
                &material,
                adjust_ratio,
                &pos,
                &vel,
                &mut whole,
                &mut scratch,
                true,
            );
            // Splits at a row boundary, mid-row, and one row from each end.
            let n = topology.n_nodes;
            for split in [n / 2, n / 2 + 3, 2 * nx + 1, n - 2 * nx - 1] {
                assert!(can_split(&topology, split), "{nx}x{ny} at {split}");
                let mut serial = vec![0.0; pos.len()];
                let ts = spring_forces_split(
                    &topology,
                    &scratch.rest,
                    &material,
                    adjust_ratio,
                    &pos,
                    &vel,
                    &mut serial,
                    split,
                    &Serial,
                    isa,
                    true,
                );
                let mut lent = vec![0.0; pos.len()];
                let tl = spring_forces_split(
                    &topology,
                    &scratch.rest,
                    &material,
                    adjust_ratio,
                    &pos,
                    &vel,
                    &mut lent,
                    split,
                    &*lender,
                    isa,
                    false,
                );
                // (Lent and without the figures: the same forces.)
                assert!(serial.iter().zip(&lent).all(|(a, b)| a.to_bits() == b.to_bits()));
                assert!(tl.elastic_energy.is_nan());
                let tl = spring_forces_split(
                    &topology,
                    &scratch.rest,
                    &material,
                    adjust_ratio,
                    &pos,
                    &vel,
                    &mut vec![0.0; pos.len()],
                    split,
                    &*lender,
                    isa,
                    true,
                );
                assert_eq!(ts.elastic_energy.to_bits(), tl.elastic_energy.to_bits());
                let scale = whole.iter().fold(0.0f64, |m, f| m.max(f.abs()));
                for (k, (a, b)) in whole.iter().zip(&serial).enumerate() {
                    assert!(
                        (a - b).abs() <= 1e-13 * scale,
                        "{nx}x{ny} split {split}: force {k} {a} against {b}"
                    );
                }
                let rel = (ts.elastic_energy - t.elastic_energy).abs() / t.elastic_energy;
                assert!(rel < 1e-13, "{nx}x{ny} split {split}: energy off by {rel:e}");
                assert_eq!(ts.max_strain, t.max_strain);
            }
        }
    }
    stop.store(true, Ordering::Relaxed);
    helper.join().expect("helper");
}

/// Which padded groups of a regular grid the kernel runs with one shared
/// rest length (`GroupRest::uniform`): in f32 every one (the rest lengths,
/// which differ in their last f64 bits, round to one f32), so the f32 step
/// streams no rest arrays; and the shared value is the arrays' own.
#[test]
fn a_regular_grid_shares_its_rest_lengths_in_f32() {
    for (nx, ny) in [(64, 64), (63, 17), (24, 20)] {
        let shape = GridShape {
            nx,
            ny,
            width: 0.4,
            height: 0.3,
        };
        let topology = Topology::grid(shape, Orientation::Horizontal);
        let table = RestTable::<f32>::new(&topology);
        let f64_table = RestTable::<f64>::new(&topology);
        let mut shared64 = 0;
        for ((group, own), own64) in topology.groups.iter().zip(&table.groups).zip(&f64_table.groups) {
            let Some(pd) = group.padded.as_ref() else { continue };
            let (l0, il0) = own
                .uniform
                .unwrap_or_else(|| panic!("{nx}x{ny} {:?}: no shared f32 rest length", group.class));
            for (k, &live) in pd.live.iter().enumerate() {
                if live != 0.0 {
                    assert_eq!((pd.rest[k] as f32, pd.inv_rest[k] as f32), (l0, il0));
                }
            }
            shared64 += usize::from(own64.uniform.is_some());
        }
        eprintln!("{nx}x{ny}: padded groups with one f64 rest length: {shared64}");
    }
}
