//! The response: impulses on a pair's moves, and impact zones moved as
//! rigid bodies (module docs, "The model").

use super::{unit, Pair, Pass, SelfOutcome, SelfWorkspace, REPULSION_TIME};
use crate::sim::vec3::{add, cross, dot, norm, scale, sub, V3};

/// A proximity's impulse: the pair separates at `(h − d)/max(τ, dt)`
/// along its normal, with friction. True when it changed a move.
pub(super) fn repel(ws: &mut SelfWorkspace, inv_mass: &[f64], p: &Pair, dt: f64, h: f64, friction: f64) -> bool {
    let target = (h - p.gap0).max(0.0) / REPULSION_TIME.max(dt);
    push(ws, inv_mass, p, target, friction)
}

/// An impact's response: impulses, or (in the zones' passes) the pair's
/// nodes merged into one zone.
#[allow(clippy::too_many_arguments)]
pub(super) fn respond(
    ws: &mut SelfWorkspace,
    inv_mass: &[f64],
    p: &Pair,
    pass: Pass,
    dt: f64,
    h: f64,
    friction: f64,
    out: &mut SelfOutcome,
) {
    if pass == Pass::Zones {
        for i in 1..4 {
            ws.union(p.nodes[0], p.nodes[i]);
        }
        return;
    }
    // Leave a tenth of the starting gap (up to h) at the step's end.
    let keep = 0.1 * p.gap0.min(h);
    let target = (keep - p.gap0) / dt;
    if push(ws, inv_mass, p, target, friction) {
        out.impacts += 1;
    }
}

/// Changes the pair's moves so that its relative normal velocity is at
/// least `target`, by one impulse along the normal shared by mass
/// (pinned nodes take none), and friction along the relative tangential
/// velocity of at most `friction` times the normal change. True when it
/// changed a move.
fn push(ws: &mut SelfWorkspace, inv_mass: &[f64], p: &Pair, target: f64, friction: f64) -> bool {
    let im = p.nodes.map(|k| inv_mass[k as usize]);
    let denom: f64 = (0..4).map(|i| p.w[i] * p.w[i] * im[i]).sum();
    if !(denom > 0.0) {
        return false;
    }
    let rel = (0..4).fold([0.0; 3], |r, i| add(r, scale(ws.vbar[p.nodes[i] as usize], p.w[i])));
    let vn = dot(rel, p.normal);
    if !(vn < target) {
        return false;
    }
    let dvn = target - vn;
    let j = dvn / denom;
    let tangential = sub(rel, scale(p.normal, vn));
    let vt = norm(tangential);
    let jt = if friction > 0.0 && vt > 0.0 {
        (friction * dvn).min(vt) / (vt * denom)
    } else {
        0.0
    };
    for i in 0..4 {
        let k = p.nodes[i] as usize;
        if im[i] == 0.0 {
            continue;
        }
        let s = p.w[i] * im[i];
        ws.vbar[k] = add(ws.vbar[k], add(scale(p.normal, s * j), scale(tangential, -s * jt)));
        ws.touched[k] = true;
        ws.changed[k] = ws.epoch;
    }
    true
}

/// Each impact zone's moves made rigid: its free nodes with the zone's
/// linear and angular momentum (the rotation exact, so the zone keeps its
/// shape), or, in a zone with pinned nodes, with their mean move.
pub(super) fn move_zones(dt: f64, inv_mass: &[f64], ws: &mut SelfWorkspace) {
    // Group the zoned nodes by zone.
    let mut zoned = std::mem::take(&mut ws.zoned);
    for i in 0..zoned.len() {
        let root = ws.find(zoned[i]);
        ws.parent[zoned[i] as usize] = root;
    }
    zoned.sort_unstable_by_key(|&k| (ws.parent[k as usize], k));
    let mut start = 0;
    while start < zoned.len() {
        let root = ws.parent[zoned[start] as usize];
        let end = start
            + zoned[start..]
                .iter()
                .take_while(|&&k| ws.parent[k as usize] == root)
                .count();
        let members = &zoned[start..end];
        start = end;
        let pinned = members.iter().filter(|&&k| inv_mass[k as usize] == 0.0).count();
        if pinned > 0 {
            let mean = members
                .iter()
                .filter(|&&k| inv_mass[k as usize] == 0.0)
                .fold([0.0; 3], |s, &k| add(s, ws.vbar[k as usize]));
            let mean = scale(mean, 1.0 / pinned as f64);
            for &k in members.iter().filter(|&&k| inv_mass[k as usize] > 0.0) {
                ws.vbar[k as usize] = mean;
                ws.changed[k as usize] = ws.epoch;
            }
            continue;
        }
        let mass = |k: u32| 1.0 / inv_mass[k as usize];
        let total: f64 = members.iter().map(|&k| mass(k)).sum();
        let centre = scale(
            members
                .iter()
                .fold([0.0; 3], |s, &k| add(s, scale(ws.x0[k as usize], mass(k)))),
            1.0 / total,
        );
        let velocity = scale(
            members
                .iter()
                .fold([0.0; 3], |s, &k| add(s, scale(ws.vbar[k as usize], mass(k)))),
            1.0 / total,
        );
        let mut momentum = [0.0; 3];
        let mut inertia = [[0.0; 3]; 3];
        for &k in members {
            let r = sub(ws.x0[k as usize], centre);
            let v = sub(ws.vbar[k as usize], velocity);
            momentum = add(momentum, scale(cross(r, v), mass(k)));
            let rr = dot(r, r);
            for a in 0..3 {
                for b in 0..3 {
                    inertia[a][b] += mass(k) * (if a == b { rr } else { 0.0 } - r[a] * r[b]);
                }
            }
        }
        let omega = solve3(inertia, momentum);
        let angle = norm(omega) * dt;
        let axis = unit(omega);
        for &k in members {
            let r = sub(ws.x0[k as usize], centre);
            let turned = match axis {
                Some(u) if angle > 0.0 => rotate(r, u, angle),
                _ => r,
            };
            let x1 = add(add(centre, scale(velocity, dt)), turned);
            ws.vbar[k as usize] = scale(sub(x1, ws.x0[k as usize]), 1.0 / dt);
            ws.changed[k as usize] = ws.epoch;
        }
    }
    ws.zoned = zoned;
}

/// `r` turned by `angle` about the unit `axis` (Rodrigues).
fn rotate(r: V3, axis: V3, angle: f64) -> V3 {
    let (s, c) = angle.sin_cos();
    add(
        add(scale(r, c), scale(cross(axis, r), s)),
        scale(axis, dot(axis, r) * (1.0 - c)),
    )
}

/// `A⁻¹·b` for a symmetric positive semi-definite 3×3 `A` (an inertia
/// tensor); a zone whose nodes lie on a line has no inertia about it, so a
/// whisper of the trace is added to the diagonal. Zero when `A` is zero.
fn solve3(a: [[f64; 3]; 3], b: V3) -> V3 {
    let trace = a[0][0] + a[1][1] + a[2][2];
    if !(trace > 0.0) {
        return [0.0; 3];
    }
    let m = nalgebra::Matrix3::from_fn(|i, j| a[i][j] + if i == j { 1e-12 * trace } else { 0.0 });
    match m.try_inverse() {
        Some(inv) => {
            let x = inv * nalgebra::Vector3::new(b[0], b[1], b[2]);
            [x[0], x[1], x[2]]
        }
        None => [0.0; 3],
    }
}
