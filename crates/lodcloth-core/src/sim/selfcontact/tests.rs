//! Self-contact's parts on their own, judged by the exact count of
//! `sim::crossings`: the last fallback ([`hold`]), where holding the nodes
//! of the pairs that collide can make others collide with them, and those
//! are held too; and pairs closer than the thickness at rest.

use super::*;
use crate::sim::crossings;
use crate::sim::topology::{GridShape, Orientation};

/// Nodes a side of each sheet, and their spacing (m).
const M: usize = 8;
const CELL: f64 = 0.03;

/// `M × M` sheets parallel to the x–y plane, one per offset, in one
/// topology (sheet `s` holds nodes `s·M²..(s+1)·M²`, row by row).
fn sheets(offsets: &[[f64; 3]]) -> Topology {
    let side = CELL * (M - 1) as f64;
    let one = Topology::grid(
        GridShape {
            nx: M,
            ny: M,
            width: side,
            height: side,
        },
        Orientation::Vertical,
    );
    let per = one.n_nodes;
    let mut rest = Vec::new();
    let mut triangles = Vec::new();
    let mut areas = Vec::new();
    for (s, o) in offsets.iter().enumerate() {
        rest.extend(
            one.rest_positions
                .iter()
                .map(|p| [p[0] + o[0], p[1] + o[1], p[2] + o[2]]),
        );
        triangles.extend(one.triangles.iter().map(|t| t.map(|k| k + (s * per) as u32)));
        areas.extend_from_slice(&one.node_areas);
    }
    Topology {
        n_nodes: per * offsets.len(),
        rest_positions: rest,
        node_areas: areas,
        groups: Vec::new(),
        triangles,
        grid: None,
        mesh: None,
        bending: Default::default(),
    }
}

/// Structure-of-arrays positions of the rest shape, with sheet `s`'s nodes
/// in its first `cols` columns moved by `dz` for every `(s, cols, dz)`.
fn moved(topology: &Topology, moves: &[(usize, usize, f64)]) -> Vec<f64> {
    let n = topology.n_nodes;
    let mut x = vec![0.0; 3 * n];
    for (k, p) in topology.rest_positions.iter().enumerate() {
        for c in 0..3 {
            x[c * n + k] = p[c];
        }
    }
    for &(s, cols, dz) in moves {
        for k in s * M * M..(s + 1) * M * M {
            if k % M < cols {
                x[2 * n + k] += dz;
            }
        }
    }
    x
}

/// Sheet A still at z = 0; sheet B 5 cm in front moves 10 cm through it;
/// sheet C 2 cm in front of B folds its left half 4 cm back, which misses
/// B as B moves but crosses it where B is held. Impacts find B against A
/// only; holding those nodes makes C's fold collide with B, so C's nodes
/// must be held too.
#[test]
fn nodes_that_collide_with_held_ones_are_held_too() {
    let settings = SelfContact {
        thickness: 0.003,
        friction: 0.3,
    };
    let dt = 1e-3;
    let topology = sheets(&[[0.0; 3], [0.004, -0.007, 0.05], [0.009, -0.003, 0.07]]);
    let n = topology.n_nodes;
    let before = moved(&topology, &[]);
    let after = moved(&topology, &[(1, M, -0.1), (2, M / 2, -0.04)]);
    // The scene means something: with B held where it starts and C moved,
    // C crosses B.
    let b_held = moved(&topology, &[(2, M / 2, -0.04)]);
    assert!(
        !crossings(&topology, &b_held).is_empty(),
        "C's fold must cross B where B starts"
    );

    let mut ws = SelfWorkspace::new(&topology, &settings);
    assert!(load(&mut ws, &before, &after, dt));
    ws.touched.fill(false);
    let inv_mass = vec![1.0; n];
    let mut out = SelfOutcome::default();
    // A zones' pass over the moves as they are: B against A.
    let found = detect(&settings, dt, &inv_mass, &mut ws, Pass::Zones, &mut out, &Serial);
    assert!(found > 0, "B's move meets A");
    assert!(
        ws.zoned.iter().all(|&k| (k as usize) < 2 * M * M),
        "only A and B collide before anything is held"
    );
    let left = hold(&settings, dt, &inv_mass, &mut ws, &mut out, &Serial);
    assert_eq!(left, 0, "nothing is pinned, so nothing may be left colliding");
    assert!(
        ws.zoned.iter().any(|&k| (k as usize) >= 2 * M * M),
        "C's nodes that met the held B are held too"
    );
    let (mut pos, mut vel) = (after.clone(), vec![0.0; 3 * n]);
    store(&ws, dt, &before, &mut pos, &mut vel, &inv_mass);
    let crossing = crossings(&topology, &pos);
    assert!(crossing.is_empty(), "{} crossings after the fallback", crossing.len());
}

/// Two sheets half the thickness apart at rest, as a simplified mesh's
/// sliver holds a node that close to a triangle it does not share: at rest
/// nothing pushes them apart (the cloth could not rest), yet when one is
/// thrown through the other in a step the impacts stop it.
#[test]
fn pairs_closer_than_the_thickness_at_rest_are_not_pushed_apart_yet_cannot_cross() {
    let settings = SelfContact {
        thickness: 0.003,
        friction: 0.3,
    };
    let dt = 1e-3;
    let topology = sheets(&[[0.0; 3], [0.004, -0.007, 0.0015]]);
    let n = topology.n_nodes;
    let inv_mass = vec![1.0; n];
    let mut ws = SelfWorkspace::new(&topology, &settings);
    assert!(
        !ws.rest_vt.is_empty() && !ws.rest_ee.is_empty(),
        "the sheets are closer than h at rest"
    );
    let before = moved(&topology, &[]);

    // At rest: nothing moves.
    let (mut pos, mut vel) = (before.clone(), vec![0.0; 3 * n]);
    resolve(&settings, dt, &before, &mut pos, &mut vel, &inv_mass, &mut ws, &Serial);
    assert_eq!(pos, before, "a pair that close at rest is not pushed apart");

    // The upper sheet's left half thrown 1 cm down through the lower one
    // in a step.
    let after = moved(&topology, &[(1, M / 2, -0.01)]);
    assert!(!crossings(&topology, &after).is_empty(), "the move crosses");
    let (mut pos, mut vel) = (after.clone(), vec![0.0; 3 * n]);
    let out = resolve(&settings, dt, &before, &mut pos, &mut vel, &inv_mass, &mut ws, &Serial);
    assert!(out.impacts > 0 || out.zone_rounds > 0, "{out:?}");
    let crossing = crossings(&topology, &pos);
    assert!(crossing.is_empty(), "{} crossings: {out:?}", crossing.len());
}
