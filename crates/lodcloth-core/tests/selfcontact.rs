//! Self-contact against an exact count of crossings (`sim::crossings`,
//! exact predicates, written apart from the solver): a cloth that would
//! pass through itself does not, with self-contact on, after any step; and
//! each scene does pass through itself with it off, so every test here can
//! fail.

use std::sync::Arc;

use crate::common::{build, fixed_pins, grid, lumped_masses, material, params};
use lodcloth::sim::{
    crossings, Collider, Grab, Integrator, Lender, Loads, Orientation, PinPath, SelfContact, Shape, SimParams,
    StabilityCheck, State, Topology, SELF_SPLIT_MIN_CANDIDATES,
};

const CONTACT: SelfContact = SelfContact {
    thickness: 0.003,
    friction: 0.3,
};

fn with_contact(mut p: SimParams, on: bool) -> SimParams {
    p.self_contact = on.then_some(CONTACT);
    p
}

/// A 12 × 30 cloth folded in three layers 2 cm apart (an accordion, 3 cm
/// cells), 10 cm above a floor.
fn accordion() -> (Arc<Topology>, State) {
    accordion_of(1)
}

/// The accordion with `per` times the nodes a side.
fn accordion_of(per: usize) -> (Arc<Topology>, State) {
    let (nx, ny, cell) = (12 * per, 30 * per, 0.03 / per as f64);
    let topology = grid(
        nx,
        ny,
        cell * (nx - 1) as f64,
        cell * (ny - 1) as f64,
        Orientation::Horizontal,
    );
    let mut state = State::at_rest(&topology);
    let n = topology.n_nodes;
    let rows = ny / 3;
    for j in 0..ny {
        let (layer, r) = (j / rows, j % rows);
        let z = if layer % 2 == 0 { r } else { rows - 1 - r } as f64 * cell;
        for i in 0..nx {
            let k = j * nx + i;
            state.pos[k] = i as f64 * cell;
            state.pos[n + k] = 0.1 + 0.02 * layer as f64;
            state.pos[2 * n + k] = z;
        }
    }
    (topology, state)
}

fn floor() -> Collider {
    Collider {
        shape: Shape::Plane {
            normal: [0.0, 1.0, 0.0],
        },
        position: [0.0; 3],
        path: PinPath::Fixed,
        friction: 0.5,
        clearance: 0.002,
    }
}

fn accordion_sim(on: bool) -> lodcloth::sim::Simulation {
    accordion_sim_of(on, 1)
}

fn accordion_sim_of(on: bool, per: usize) -> lodcloth::sim::Simulation {
    let (topology, state) = accordion_of(per);
    let mut p = with_contact(
        params(
            // Within symplectic Euler's limit, which falls with the cell.
            5e-4 / (per * per) as f64,
            Integrator::SymplecticEuler,
            material((200.0, 0.02), (30.0, 0.003), (2.0, 0.0002)),
        ),
        on,
    );
    p.gravity = [0.0, -9.81, 0.0];
    p.drag = 0.5;
    let loads = Loads {
        colliders: vec![floor()],
        ..Loads::default()
    };
    let masses = lumped_masses(&topology, 0.2);
    build(topology, masses, p, loads, state, StabilityCheck::Enforce)
}

/// Steps `sim` `steps` times; the most crossings after any step, and the
/// step it was first seen at.
fn worst_crossings(
    sim: &mut lodcloth::sim::Simulation,
    steps: usize,
    mut each: impl FnMut(&mut lodcloth::sim::Simulation),
) -> (usize, Option<u64>, u32, usize) {
    let mut worst = 0;
    let mut first = None;
    let mut unresolved = 0;
    let mut flat = 0;
    for _ in 0..steps {
        each(sim);
        let r = sim.step();
        assert!(r.finite, "diverged at step {}", r.step);
        unresolved = unresolved.max(r.self_contact.unresolved);
        flat += usize::from(r.self_contact.flat);
        let c = crossings(sim.topology(), &sim.state().pos).len();
        if c > 0 && first.is_none() {
            first = Some(r.step);
        }
        worst = worst.max(c);
    }
    (worst, first, unresolved, flat)
}

/// Three layers dropped onto a floor pile up without crossing, over 1.5 s:
/// with self-contact off the upper layers fall onto the lowest and through
/// it (the floor holds every node at its clearance, so the layers end in
/// one plane, crossing).
#[test]
fn an_accordion_dropped_onto_a_floor_piles_up_without_crossing() {
    let mut off = accordion_sim(false);
    let (worst_off, first_off, _, _) = worst_crossings(&mut off, 3000, |_| ());
    println!("self-contact off: up to {worst_off} crossings, first at step {first_off:?}");
    assert!(
        worst_off > 0,
        "the layers never crossed without self-contact: the test shows nothing"
    );
    let mut on = accordion_sim(true);
    let (worst, first, unresolved, _) = worst_crossings(&mut on, 3000, |_| ());
    println!("self-contact on: up to {worst} crossings (first at step {first:?}), {unresolved} unresolved pairs");
    assert_eq!(worst, 0, "crossings with self-contact, first at step {first:?}");
    // The layers rest on each other about a thickness apart.
    let n = on.topology().n_nodes;
    let top = (0..n).map(|k| on.state().pos[n + k]).fold(0.0, f64::max);
    println!("pile height {top:.4} m");
    assert!(top > 0.002 + 2.0 * 0.9 * CONTACT.thickness, "the pile is {top} m high");
}

/// A long candidate list's checks run in two halves at once when the step
/// has a second thread: the accordion at twice the nodes a side, piled up,
/// steps to the same bits on one thread and on two.
#[test]
fn self_contact_on_two_threads_steps_to_the_same_bits_as_on_one() {
    use std::sync::atomic::{AtomicBool, Ordering};
    let lender = Arc::new(Lender::new());
    let stop = Arc::new(AtomicBool::new(false));
    let helper = {
        let (lender, stop) = (lender.clone(), stop.clone());
        std::thread::spawn(move || lender.serve_until(&stop))
    };
    let (mut one, mut two) = (accordion_sim_of(true, 2), accordion_sim_of(true, 2));
    let mut long = 0;
    // 0.5 s: the layers fall onto the floor and onto each other.
    for _ in 0..4000 {
        let r = one.step();
        two.step_on(&*lender);
        assert!(r.finite);
        let bits = |s: &State| s.pos.iter().chain(&s.vel).map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(
            bits(one.state()) == bits(two.state()),
            "the states differ after step {}",
            r.step
        );
        long += usize::from(r.self_contact.candidates as usize >= SELF_SPLIT_MIN_CANDIDATES);
    }
    stop.store(true, Ordering::Release);
    let ran = helper.join().expect("the helper ends");
    println!("{long} of 4000 steps with a candidate list long enough to split; the helper ran {ran} halves");
    // Whether the helper took a half depends on the machine's load (the
    // stepping thread takes it back rather than wait); the splits do not.
    assert!(long > 0, "no step split its checks: the test shows nothing");
}

/// A cloth resting in layers on itself does not gain energy: settled for
/// 2 s with air drag, then left for 10 s with none (the springs' own
/// damping and the contacts' friction and inelastic impulses are all that
/// take energy out), its total energy never rises above where it started
/// by more than a millionth of a joule (its elastic energy is some 5 mJ).
#[test]
fn a_cloth_at_rest_on_itself_gains_no_energy() {
    let mut settling = accordion_sim(true);
    for _ in 0..4000 {
        assert!(settling.step().finite);
    }
    let (topology, _) = accordion();
    let mut p = *settling.params();
    p.drag = 0.0;
    let mut sim = build(
        topology.clone(),
        lumped_masses(&topology, 0.2),
        p,
        settling.loads().clone(),
        settling.state().clone(),
        StabilityCheck::Enforce,
    );
    let start = sim.step();
    let e0 = start.total_energy();
    let mut highest = e0;
    let mut touching = 0u32;
    for _ in 0..20_000 {
        let r = sim.step();
        assert!(r.finite);
        highest = highest.max(r.total_energy());
        touching = touching.max(r.self_contact.proximities);
    }
    println!(
        "energy after settling {e0:.6e} J, highest over the next 10 s without drag {highest:.6e} J \
         (elastic {:.3e} J), up to {touching} pairs in contact",
        start.elastic_energy
    );
    assert!(touching > 0, "the layers do not rest on each other");
    assert!(highest - e0 <= 1e-6, "the energy rose by {:.3e} J", highest - e0);
}

/// A corner of a hanging cloth dragged up and across in front of it, then
/// back through it (a grab, as a client's drag is), pushes the sheet back
/// instead of passing through it.
#[test]
fn a_corner_dragged_across_the_hanging_cloth_never_crosses_it() {
    let run = |on: bool| {
        let topology = grid(16, 16, 0.5, 0.5, Orientation::Vertical);
        let pins = fixed_pins(&topology, &(0..16).collect::<Vec<_>>());
        let mut p = with_contact(
            params(
                2e-4,
                Integrator::SymplecticEuler,
                material((400.0, 0.04), (60.0, 0.006), (8.0, 0.0008)),
            ),
            on,
        );
        p.gravity = [0.0, -9.81, 0.0];
        p.drag = 1.0;
        let masses = lumped_masses(&topology, 0.2);
        let state = State::at_rest(&topology);
        let corner = (15 * 16) as u32;
        let start = topology.rest_positions[corner as usize];
        let mut sim = build(
            topology,
            masses,
            p,
            Loads {
                pins,
                ..Loads::default()
            },
            state,
            StabilityCheck::Enforce,
        );
        // Over 0.8 s the target goes from the corner up and across, 5 cm in
        // front of the sheet, to over its middle; over the next 0.8 s it
        // goes 13 cm back, to 8 cm behind where the sheet hangs.
        let steps = 10_000;
        let mut step = 0usize;
        worst_crossings(&mut sim, steps, |sim| {
            let t = step as f64 / steps as f64;
            step += 1;
            let up = (t / 0.4).min(1.0);
            let back = ((t - 0.4) / 0.4).clamp(0.0, 1.0);
            let target = [start[0] + 0.3 * up, start[1] + 0.3 * up, start[2] + 0.05 - 0.13 * back];
            sim.set_grabs(vec![Grab {
                nodes: vec![corner],
                weights: vec![1.0],
                target,
                stiffness: 20.0,
                damping: 0.2,
            }])
            .expect("a valid grab");
        })
    };
    let (worst_off, first_off, _, _) = run(false);
    println!("self-contact off: up to {worst_off} crossings, first at step {first_off:?}");
    assert!(worst_off > 0, "the drag never crossed the sheet without self-contact");
    let (worst, first, unresolved, flat) = run(true);
    println!(
        "self-contact on: up to {worst} crossings (first at step {first:?}), {unresolved} unresolved; \
         {flat} of 10000 steps certified flat"
    );
    assert_eq!(worst, 0, "crossings with self-contact, first at step {first:?}");
    // Both ways were taken: flat steps skipped (the sheet hanging, the
    // corner lifted in front of it) and the fold checked pair by pair.
    assert!((500..9500).contains(&flat), "{flat} of 10000 steps certified flat");
}

/// A sheet thrown at another at 90 m/s, 9 cm a step, far past its
/// thickness, its top row held: the impacts are found within the step
/// (continuous detection), not after it, so the sheet is stopped in front
/// of the other (pinned at its rim) rather than stretched through it.
#[test]
fn a_sheet_thrown_through_another_in_one_step_is_stopped() {
    let run = |on: bool| {
        // Two 8 × 8 sheets of 0.21 m, 5 cm apart along z, in one topology.
        let a = lodcloth::sim::Topology::grid(
            lodcloth::sim::GridShape {
                nx: 8,
                ny: 8,
                width: 0.21,
                height: 0.21,
            },
            Orientation::Vertical,
        );
        let n1 = a.n_nodes;
        let mut rest = a.rest_positions.clone();
        rest.extend(a.rest_positions.iter().map(|p| [p[0] + 0.01, p[1] - 0.01, p[2] + 0.05]));
        let mut triangles = a.triangles.clone();
        triangles.extend(a.triangles.iter().map(|t| t.map(|k| k + n1 as u32)));
        let mut groups = a.groups.clone();
        for g in &a.groups {
            let pairs: Vec<(u32, u32)> =
                g.a.iter()
                    .zip(&g.b)
                    .map(|(&x, &y)| (x + n1 as u32, y + n1 as u32))
                    .collect();
            groups.push(lodcloth::sim::SpringGroup::from_pairs(g.class, &pairs, g.rest.clone()));
        }
        let mut areas = a.node_areas.clone();
        areas.extend_from_slice(&a.node_areas);
        let topology = Arc::new(Topology {
            n_nodes: 2 * n1,
            rest_positions: rest,
            node_areas: areas,
            groups,
            triangles,
            grid: None,
            mesh: None,
            bending: Default::default(),
        });
        let rim = |k: usize| !(8..56).contains(&k) || matches!(k % 8, 0 | 7);
        // The target's rim and the thrown sheet's top row.
        let held: Vec<usize> = (0..n1).filter(|&k| rim(k)).chain(n1..n1 + 8).collect();
        let pins = fixed_pins(&topology, &held);
        let mut state = State::at_rest(&topology);
        let n = topology.n_nodes;
        for k in n1 + 8..n {
            state.vel[2 * n + k] = -90.0;
        }
        let p = with_contact(
            params(
                1e-3,
                Integrator::SymplecticEuler,
                material((5.0, 0.0), (1.0, 0.0), (0.1, 0.0)),
            ),
            on,
        );
        let masses = lumped_masses(&topology, 0.2);
        let mut sim = build(
            topology,
            masses,
            p,
            Loads {
                pins,
                ..Loads::default()
            },
            state,
            StabilityCheck::Enforce,
        );
        worst_crossings(&mut sim, 20, |_| ())
    };
    let (worst_off, _, _, _) = run(false);
    println!("self-contact off: up to {worst_off} crossings");
    assert!(worst_off > 0, "the thrown sheet never crossed without self-contact");
    let (worst, first, unresolved, _) = run(true);
    println!("self-contact on: up to {worst} crossings (first at step {first:?}), {unresolved} unresolved");
    assert_eq!(worst, 0, "crossings with self-contact, first at step {first:?}");
}
