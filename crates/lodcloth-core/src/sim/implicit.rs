//! Backward Euler, linearised once per step (Baraff & Witkin 1998), solved by
//! Jacobi-preconditioned conjugate gradients without forming the matrix.
//!
//! With f(x, v) the total force, J = ∂f/∂x and D = ∂f/∂v at the start of the
//! step, the velocity change Δv solves
//!
//! `(M − dt·D − dt²·J) Δv = dt·(f₀ + dt·J·v₀)`, then `v₁ = v₀ + Δv`, `x₁ = x₀ + dt·v₁`.
//!
//! Per spring (u the unit direction, L its length), the force on `a` is
//! `F = K(L − L0)u + C((v_b − v_a)·u)u`, so ∂F/∂x_b = J_s and ∂F/∂v_b = C uuᵀ with
//! `J_s = K[uuᵀ + (1 − L0/L)(I − uuᵀ)]`. The transverse term is clamped at 0
//! for compressed springs (L < L0), which keeps the matrix symmetric positive
//! definite so CG applies (the usual Baraff–Witkin/Choi–Ko choice). Drag −γMv
//! adds dt·γ·M to the diagonal. Pinned nodes are filtered out of the solve
//! (their Δv is 0; their motion is prescribed).

use super::params::{CgSettings, Material, SpringClass};
use super::topology::Topology;

/// Per-spring linearisation data and CG vectors, sized once.
#[derive(Debug, Clone)]
pub(crate) struct ImplicitWorkspace {
    /// Unit direction per spring (all groups concatenated), SoA.
    ux: Vec<f64>,
    uy: Vec<f64>,
    uz: Vec<f64>,
    /// Coefficient of uuᵀ in J_s.
    j_axial: Vec<f64>,
    /// Coefficient of I in J_s.
    j_iso: Vec<f64>,
    /// Damping C per spring.
    damp: Vec<f64>,
    rhs: Vec<f64>,
    dv: Vec<f64>,
    r: Vec<f64>,
    z: Vec<f64>,
    p: Vec<f64>,
    q: Vec<f64>,
    diag: Vec<f64>,
}

impl ImplicitWorkspace {
    pub(crate) fn new(topology: &Topology) -> ImplicitWorkspace {
        let s = topology.spring_count();
        let n3 = 3 * topology.n_nodes;
        ImplicitWorkspace {
            ux: vec![0.0; s],
            uy: vec![0.0; s],
            uz: vec![0.0; s],
            j_axial: vec![0.0; s],
            j_iso: vec![0.0; s],
            damp: vec![0.0; s],
            rhs: vec![0.0; n3],
            dv: vec![0.0; n3],
            r: vec![0.0; n3],
            z: vec![0.0; n3],
            p: vec![0.0; n3],
            q: vec![0.0; n3],
            diag: vec![0.0; n3],
        }
    }
}

/// Inputs of one implicit step that do not change during it.
pub(crate) struct ImplicitInputs<'a> {
    pub topology: &'a Topology,
    pub material: &'a Material,
    /// `1 + allowed` of the stiffness adjustment, or ∞.
    pub adjust_ratio: f64,
    pub masses: &'a [f64],
    /// 1 for free nodes, 0 for pinned ones.
    pub free: &'a [f64],
    pub drag: f64,
    pub dt: f64,
    pub cg: CgSettings,
}

/// Outcome of the linear solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CgOutcome {
    pub iterations: u32,
    /// ‖r‖ / ‖b‖ at exit.
    pub relative_residual: f64,
}

/// One backward-Euler step in place. `acc` is the acceleration at the start
/// state (gravity, drag, loads and springs included; zero for pins).
pub(crate) fn step(
    inp: &ImplicitInputs<'_>,
    pos: &mut [f64],
    vel: &mut [f64],
    acc: &[f64],
    ws: &mut ImplicitWorkspace,
) -> CgOutcome {
    let topo = inp.topology;
    let n = topo.n_nodes;
    let dt = inp.dt;

    // Linearise every spring at x₀.
    let mut s = 0;
    for g in &topo.groups {
        let co = inp.material.get(g.class);
        for i in 0..g.len() {
            let (a, b) = (g.a[i] as usize, g.b[i] as usize);
            let d = [
                pos[b] - pos[a],
                pos[n + b] - pos[n + a],
                pos[2 * n + b] - pos[2 * n + a],
            ];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let inv = if l > 1e-12 { 1.0 / l } else { 0.0 };
            let ratio = l * g.inv_rest[i];
            let k = if ratio > inp.adjust_ratio { co.k * ratio } else { co.k };
            let t = (1.0 - g.rest[i] * inv).max(0.0);
            ws.ux[s] = d[0] * inv;
            ws.uy[s] = d[1] * inv;
            ws.uz[s] = d[2] * inv;
            ws.j_axial[s] = k * (1.0 - t);
            ws.j_iso[s] = k * t;
            ws.damp[s] = co.c;
            s += 1;
        }
    }

    // b = dt·M·a₀ + dt²·J·v₀ (free nodes only).
    for c in 0..3 {
        for k in 0..n {
            ws.rhs[c * n + k] = dt * inp.masses[k] * acc[c * n + k];
        }
    }
    add_scaled_stiffness_product(topo, ws, vel, dt * dt);
    // Bending stencils: their Jacobian is the constant −D·WᵀW.
    let bend = inp.material.get(SpringClass::BendU);
    topo.bending.add_product(-dt * dt * bend.k, vel, &mut ws.rhs);
    // Diagonal of A for the preconditioner.
    for c in 0..3 {
        for k in 0..n {
            ws.diag[c * n + k] = inp.masses[k] * (1.0 + dt * inp.drag);
        }
    }
    spring_diag(topo, ws, dt);
    if !topo.bending.is_empty() {
        let (lo, rest) = ws.diag.split_at_mut(n);
        let (mid, hi) = rest.split_at_mut(n);
        for part in [lo, mid, hi] {
            topo.bending.add_diagonal(dt * bend.c + dt * dt * bend.k, part);
        }
    }
    for c in 0..3 {
        for k in 0..n {
            let i = c * n + k;
            ws.rhs[i] *= inp.free[k];
            ws.diag[i] = if inp.free[k] > 0.0 { 1.0 / ws.diag[i] } else { 0.0 };
        }
    }

    // Preconditioned CG on A Δv = b, starting from Δv = 0.
    ws.dv.fill(0.0);
    ws.r.copy_from_slice(&ws.rhs);
    let b_norm = dot(&ws.rhs, &ws.rhs).sqrt();
    if b_norm == 0.0 {
        return CgOutcome {
            iterations: 0,
            relative_residual: 0.0,
        };
    }
    for i in 0..3 * n {
        ws.z[i] = ws.diag[i] * ws.r[i];
    }
    ws.p.copy_from_slice(&ws.z);
    let mut rz = dot(&ws.r, &ws.z);
    let mut iterations = 0;
    let mut rel = 1.0;
    while iterations < inp.cg.max_iterations {
        iterations += 1;
        system_apply(inp, ws);
        let pq = dot(&ws.p, &ws.q);
        if pq <= 0.0 || !pq.is_finite() {
            break;
        }
        let alpha = rz / pq;
        for i in 0..3 * n {
            ws.dv[i] += alpha * ws.p[i];
            ws.r[i] -= alpha * ws.q[i];
        }
        rel = dot(&ws.r, &ws.r).sqrt() / b_norm;
        if rel <= inp.cg.tolerance {
            break;
        }
        for i in 0..3 * n {
            ws.z[i] = ws.diag[i] * ws.r[i];
        }
        let rz_new = dot(&ws.r, &ws.z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..3 * n {
            ws.p[i] = ws.z[i] + beta * ws.p[i];
        }
    }

    for c in 0..3 {
        for k in 0..n {
            let i = c * n + k;
            vel[i] += ws.dv[i];
            pos[i] += dt * vel[i];
        }
    }
    CgOutcome {
        iterations,
        relative_residual: rel,
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    // Four partial sums: a fixed order (deterministic) that still pipelines.
    let mut s = [0.0; 4];
    let (ca, ta) = a.as_chunks::<4>();
    let (cb, tb) = b.as_chunks::<4>();
    for (x, y) in ca.iter().zip(cb) {
        for j in 0..4 {
            s[j] += x[j] * y[j];
        }
    }
    let tail: f64 = ta.iter().zip(tb).map(|(x, y)| x * y).sum();
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// rhs += scale · J·v, where (J·v)_a = J_s (v_b − v_a) and (J·v)_b = −J_s (v_b − v_a).
fn add_scaled_stiffness_product(topo: &Topology, ws: &mut ImplicitWorkspace, v: &[f64], scale: f64) {
    let n = topo.n_nodes;
    let mut s = 0;
    for g in &topo.groups {
        for i in 0..g.len() {
            let (a, b) = (g.a[i] as usize, g.b[i] as usize);
            let d = [v[b] - v[a], v[n + b] - v[n + a], v[2 * n + b] - v[2 * n + a]];
            let u = [ws.ux[s], ws.uy[s], ws.uz[s]];
            let ud = u[0] * d[0] + u[1] * d[1] + u[2] * d[2];
            for c in 0..3 {
                let f = scale * (ws.j_axial[s] * ud * u[c] + ws.j_iso[s] * d[c]);
                ws.rhs[c * n + a] += f;
                ws.rhs[c * n + b] -= f;
            }
            s += 1;
        }
    }
}

fn spring_diag(topo: &Topology, ws: &mut ImplicitWorkspace, dt: f64) {
    let n = topo.n_nodes;
    let mut s = 0;
    for g in &topo.groups {
        for i in 0..g.len() {
            let (a, b) = (g.a[i] as usize, g.b[i] as usize);
            let u = [ws.ux[s], ws.uy[s], ws.uz[s]];
            let axial = dt * ws.damp[s] + dt * dt * ws.j_axial[s];
            let iso = dt * dt * ws.j_iso[s];
            for c in 0..3 {
                let d = axial * u[c] * u[c] + iso;
                ws.diag[c * n + a] += d;
                ws.diag[c * n + b] += d;
            }
            s += 1;
        }
    }
}

/// q = A p with A = M(1 + dt γ) + Σ_s S_s-Laplacian, S_s = (dt C + dt² j_axial) uuᵀ + dt² j_iso I;
/// pinned rows and columns filtered out.
fn system_apply(inp: &ImplicitInputs<'_>, ws: &mut ImplicitWorkspace) {
    let topo = inp.topology;
    let n = topo.n_nodes;
    let dt = inp.dt;
    for c in 0..3 {
        for k in 0..n {
            ws.q[c * n + k] = inp.masses[k] * (1.0 + dt * inp.drag) * ws.p[c * n + k];
        }
    }
    let mut s = 0;
    for g in &topo.groups {
        for i in 0..g.len() {
            let (a, b) = (g.a[i] as usize, g.b[i] as usize);
            let p = &ws.p;
            let w = [p[a] - p[b], p[n + a] - p[n + b], p[2 * n + a] - p[2 * n + b]];
            let u = [ws.ux[s], ws.uy[s], ws.uz[s]];
            let uw = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
            let axial = (dt * ws.damp[s] + dt * dt * ws.j_axial[s]) * uw;
            let iso = dt * dt * ws.j_iso[s];
            for c in 0..3 {
                let f = axial * u[c] + iso * w[c];
                ws.q[c * n + a] += f;
                ws.q[c * n + b] -= f;
            }
            s += 1;
        }
    }
    let bend = inp.material.get(SpringClass::BendU);
    topo.bending
        .add_product(dt * bend.c + dt * dt * bend.k, &ws.p, &mut ws.q);
    for c in 0..3 {
        for k in 0..n {
            ws.q[c * n + k] *= inp.free[k];
        }
    }
}
