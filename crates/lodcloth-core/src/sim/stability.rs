//! Where each integrator goes unstable: the highest natural frequency of a
//! cloth (Gershgorin bound and power iteration) and the largest stable time
//! step of each integrator for that mode (`REFERENCE.md`, last section).

use super::params::{Integrator, Material, SpringClass};
use super::topology::Topology;

/// Modal estimate of a cloth about its rest shape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModalEstimate {
    /// Upper bound on ω_max from Gershgorin's theorem: max_i √(2 Σ_j k_ij / m_i) (rad/s).
    pub omega_gershgorin: f64,
    /// ω_max from power iteration on M^{-1/2} K M^{-1/2} (rad/s); a lower bound
    /// that converges to the truth.
    pub omega_max: f64,
    /// Damping rate 2ζω of the highest mode (1/s): the Rayleigh quotient of
    /// the damping matrix (spring C plus drag) with that mode.
    pub damping_rate: f64,
    /// ω of the most damped mode (the top mode of the damping matrix; rad/s):
    /// the stiffest mode's twin when damping is proportional to stiffness,
    /// another mode when it is not.
    pub damped_omega: f64,
    /// Damping rate of that mode about the rest shape (1/s).
    pub damped_rate: f64,
    /// Upper bound on the damping rate of any mode in *any* configuration
    /// (1/s): Gershgorin on M^{-1/2} D M^{-1/2} with every spring's damper
    /// counted in full, `max_i Σ_s C_s (1/m_i + 1/√(m_i m_j)) + drag`.
    /// Dampers act along their springs, and springs rotate: where a cloth
    /// folds or bunches, springs of both directions line up and the rate
    /// of the rest shape's most damped mode can nearly double (measured:
    /// BCD estimates on paper scene 2 diverged at 0.79 of the rest-shape
    /// limit).
    pub damped_rate_bound: f64,
    /// Power iterations used.
    pub iterations: u32,
}

impl ModalEstimate {
    /// Predicted largest stable dt of `integrator`: the smaller of its limits
    /// on the highest mode and on the most damped mode (∞ for implicit Euler,
    /// 0 for undamped explicit Euler). Where damping is not proportional to
    /// stiffness (the most damped mode is not the stiffest), the damped
    /// mode's limit takes [`ModalEstimate::damped_rate_bound`], which holds
    /// in every configuration the cloth can reach.
    pub fn dt_limit(&self, integrator: Integrator) -> f64 {
        let stiffest = dt_limit(integrator, self.omega_max, self.damping_rate);
        if self.damped_rate > self.damping_rate {
            stiffest.min(dt_limit(integrator, self.damped_omega, self.damped_rate_bound))
        } else {
            stiffest
        }
    }

    /// [`ModalEstimate::dt_limit`] in the rest shape only (the damped mode at
    /// its rest-shape rate): exact there, optimistic once the cloth folds.
    pub fn rest_shape_dt_limit(&self, integrator: Integrator) -> f64 {
        let stiffest = dt_limit(integrator, self.omega_max, self.damping_rate);
        if self.damped_rate > self.damping_rate {
            stiffest.min(dt_limit(integrator, self.damped_omega, self.damped_rate))
        } else {
            stiffest
        }
    }
}

/// Estimate ω_max and its damping for `topology` with `material`, node
/// `masses` and global `drag` (1/s). Pinned nodes (`pinned[k]`) are held
/// fixed and excluded. `ground[k] = [k, c]` is a spring (and damper) from
/// node k to a fixed point (a tether); empty when there is none. Deterministic: the start vector comes from a fixed
/// pseudo-random sequence.
pub fn modal_estimate(
    topology: &Topology,
    material: &Material,
    masses: &[f64],
    pinned: &[bool],
    ground: &[[f64; 2]],
    drag: f64,
) -> ModalEstimate {
    let n = topology.n_nodes;
    assert!(
        ground.is_empty() || ground.len() == n,
        "one ground spring entry per node"
    );
    let ground_of = |i: usize, which: usize| if ground.is_empty() { 0.0 } else { ground[i][which] };
    // Gershgorin: row i of M^{-1}K has |diag| + Σ|offdiag| ≤ 2 Σ_j k_ij / m_i.
    let mut ksum = vec![0.0; n];
    for g in &topology.groups {
        let k = material.get(g.class).k;
        for s in 0..g.len() {
            ksum[g.a[s] as usize] += k;
            ksum[g.b[s] as usize] += k;
        }
    }
    // Gershgorin on M^{-1/2} D M^{-1/2} with every damper in full (any
    // orientation): row i sums C_s/m_i on the diagonal and C_s/√(m_i m_j)
    // off it.
    let mut csum = vec![0.0; n];
    for g in &topology.groups {
        let c = material.get(g.class).c;
        for s in 0..g.len() {
            let (a, b) = (g.a[s] as usize, g.b[s] as usize);
            let cross = c / (masses[a] * masses[b]).sqrt();
            csum[a] += c / masses[a] + if pinned[b] { 0.0 } else { cross };
            csum[b] += c / masses[b] + if pinned[a] { 0.0 } else { cross };
        }
    }
    // Bending stencils (a mesh cloth with a bending rigidity): row i of M^{-1}·D·WᵀW is bounded by
    // D·Σ_s |w_si|·Σ_j |w_sj| / m_i, and the same for its damping (M^{-1}C
    // has the eigenvalues of M^{-1/2} C M^{-1/2}).
    let bend = material.get(SpringClass::BendU);
    let bend_rows = topology.bending.row_bounds(n);
    for i in 0..n {
        ksum[i] += 0.5 * bend.k * bend_rows[i];
        csum[i] += bend.c * bend_rows[i] / masses[i];
    }
    let damped_rate_bound = (0..n)
        .filter(|&i| !pinned[i])
        .map(|i| csum[i] + ground_of(i, 1) / masses[i])
        .fold(0.0, f64::max)
        + drag;
    let omega_gershgorin = (0..n)
        .filter(|&i| !pinned[i])
        .map(|i| (2.0 * ksum[i] + ground_of(i, 0)) / masses[i])
        .fold(0.0, f64::max)
        .sqrt();

    // Unit spring directions at rest.
    let dirs: Vec<Vec<[f64; 3]>> = topology
        .groups
        .iter()
        .map(|g| {
            (0..g.len())
                .map(|s| {
                    let (pa, pb) = (
                        topology.rest_positions[g.a[s] as usize],
                        topology.rest_positions[g.b[s] as usize],
                    );
                    let d = [pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]];
                    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    d.map(|x| x / l)
                })
                .collect()
        })
        .collect();
    let inv_sqrt_m: Vec<f64> = (0..n)
        .map(|i| if pinned[i] { 0.0 } else { 1.0 / masses[i].sqrt() })
        .collect();

    // y = M^{-1/2} L M^{-1/2} w, with L the spring Laplacian of coefficient `coef`.
    let apply = |w: &[[f64; 3]], y: &mut [[f64; 3]], coef: &dyn Fn(usize) -> f64, which: usize| {
        for (i, v) in y.iter_mut().enumerate() {
            let g = ground_of(i, which) * inv_sqrt_m[i] * inv_sqrt_m[i];
            *v = w[i].map(|x| g * x);
        }
        let bending = &topology.bending;
        let kb = if which == 0 { bend.k } else { bend.c };
        for st in 0..bending.len() {
            let (nodes, weights) = bending.row(st);
            let mut r = [0.0; 3];
            for (&i, &wt) in nodes.iter().zip(weights) {
                let ww = wt * inv_sqrt_m[i as usize];
                for c in 0..3 {
                    r[c] += ww * w[i as usize][c];
                }
            }
            for (&i, &wt) in nodes.iter().zip(weights) {
                let ww = kb * wt * inv_sqrt_m[i as usize];
                for c in 0..3 {
                    y[i as usize][c] += ww * r[c];
                }
            }
        }
        for (gi, g) in topology.groups.iter().enumerate() {
            let k = coef(gi);
            for s in 0..g.len() {
                let (a, b) = (g.a[s] as usize, g.b[s] as usize);
                let u = dirs[gi][s];
                let (sa, sb) = (inv_sqrt_m[a], inv_sqrt_m[b]);
                let d = [
                    w[a][0] * sa - w[b][0] * sb,
                    w[a][1] * sa - w[b][1] * sb,
                    w[a][2] * sa - w[b][2] * sb,
                ];
                let f = k * (u[0] * d[0] + u[1] * d[1] + u[2] * d[2]);
                for c in 0..3 {
                    y[a][c] += f * u[c] * sa;
                    y[b][c] -= f * u[c] * sb;
                }
            }
        }
    };
    let stiff = |gi: usize| material.get(topology.groups[gi].class).k;
    let damp = |gi: usize| material.get(topology.groups[gi].class).c;

    let norm = |v: &[[f64; 3]]| {
        v.iter()
            .map(|p| p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
            .sum::<f64>()
            .sqrt()
    };
    let rayleigh = |w: &[[f64; 3]], y: &mut [[f64; 3]], coef: &dyn Fn(usize) -> f64, which: usize| -> f64 {
        apply(w, y, coef, which);
        w.iter()
            .zip(y.iter())
            .map(|(a, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .sum()
    };
    // The top eigenpair of M^{-1/2} L M^{-1/2} for `coef` by power iteration
    // (normalised vector, Rayleigh quotient, iterations).
    let top = |coef: &dyn Fn(usize) -> f64, which: usize| -> (Vec<[f64; 3]>, f64, u32) {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut w: Vec<[f64; 3]> = (0..n)
            .map(|i| if pinned[i] { [0.0; 3] } else { [rnd(), rnd(), rnd()] })
            .collect();
        let mut y = vec![[0.0; 3]; n];
        let mut lambda = 0.0;
        let mut iterations = 0;
        // Near-degenerate top modes make the vector converge slowly, but the
        // Rayleigh quotient is then an average of almost-equal eigenvalues.
        let max_iter = 600;
        while iterations < max_iter {
            iterations += 1;
            let nw = norm(&w);
            if nw == 0.0 {
                break;
            }
            for v in w.iter_mut() {
                *v = v.map(|x| x / nw);
            }
            let rq = rayleigh(&w, &mut y, coef, which);
            std::mem::swap(&mut w, &mut y);
            let converged = (rq - lambda).abs() <= 1e-7 * rq.abs();
            lambda = rq;
            if converged && iterations > 20 {
                break;
            }
        }
        let nw = norm(&w);
        if nw > 0.0 {
            for v in w.iter_mut() {
                *v = v.map(|x| x / nw);
            }
        }
        (w, lambda, iterations)
    };
    let mut y = vec![[0.0; 3]; n];
    // The stiffest mode, and the damping it feels (Rayleigh quotient of C).
    let (w, lambda, iterations) = top(&stiff, 0);
    let damping_rate = if norm(&w) > 0.0 {
        rayleigh(&w, &mut y, &damp, 1) + drag
    } else {
        drag
    };
    // The most damped mode, and its stiffness: where damping is not
    // proportional to stiffness (estimates that raise C of one spring class
    // far more than its K) it is another mode, and an explicit integrator
    // can go unstable on it first (RK4's real-axis bound 2.785/dt).
    let (wc, rate, _) = top(&damp, 1);
    let (damped_omega, damped_rate) = if norm(&wc) > 0.0 {
        (rayleigh(&wc, &mut y, &stiff, 0).max(0.0).sqrt(), rate + drag)
    } else {
        (0.0, drag)
    };
    ModalEstimate {
        omega_gershgorin,
        omega_max: lambda.max(0.0).sqrt(),
        damping_rate,
        damped_omega,
        damped_rate,
        damped_rate_bound,
        iterations,
    }
}

/// Spectral radius of the one-step matrix of `integrator` applied to the
/// damped oscillator x'' = −ω² x − c x' with step `h`.
pub fn amplification(integrator: Integrator, omega: f64, c: f64, h: f64) -> f64 {
    let w2 = omega * omega;
    let m: [[f64; 2]; 2] = match integrator {
        Integrator::ExplicitEuler => [[1.0, h], [-h * w2, 1.0 - h * c]],
        Integrator::SymplecticEuler => [[1.0 - h * h * w2, h * (1.0 - h * c)], [-h * w2, 1.0 - h * c]],
        Integrator::Rk4 => {
            let a = [[0.0, h], [-h * w2, -h * c]];
            let mul = |x: [[f64; 2]; 2], y: [[f64; 2]; 2]| {
                [
                    [
                        x[0][0] * y[0][0] + x[0][1] * y[1][0],
                        x[0][0] * y[0][1] + x[0][1] * y[1][1],
                    ],
                    [
                        x[1][0] * y[0][0] + x[1][1] * y[1][0],
                        x[1][0] * y[0][1] + x[1][1] * y[1][1],
                    ],
                ]
            };
            // Horner: I + A(I + A/2 (I + A/3 (I + A/4))).
            let add_id_scaled =
                |x: [[f64; 2]; 2], s: f64| [[1.0 + s * x[0][0], s * x[0][1]], [s * x[1][0], 1.0 + s * x[1][1]]];
            let mut p = add_id_scaled(a, 0.25);
            p = add_id_scaled(mul(a, p), 1.0 / 3.0);
            p = add_id_scaled(mul(a, p), 0.5);
            p = add_id_scaled(mul(a, p), 1.0);
            p
        }
        // XPBD is backward Euler in the positions: one spring alone is
        // solved exactly by its one correction.
        Integrator::ImplicitEuler | Integrator::Xpbd => {
            // (I − hA)^{-1} with A = [[0, 1], [−ω², −c]].
            let (a, b, cc, d) = (1.0, -h, h * w2, 1.0 + h * c);
            let det = a * d - b * cc;
            [[d / det, -b / det], [-cc / det, a / det]]
        }
    };
    spectral_radius(m)
}

fn spectral_radius(m: [[f64; 2]; 2]) -> f64 {
    let tr = m[0][0] + m[1][1];
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    // tr²/4 − det without its cancellation: near a double eigenvalue (a
    // neutral mode of dampers alone has eigenvalues 1 and R(−ch)) the
    // rounding of tr²/4 − det, square-rooted, would read as growth.
    let disc = 0.25 * (m[0][0] - m[1][1]).powi(2) + m[0][1] * m[1][0];
    if disc >= 0.0 {
        let s = disc.sqrt();
        (0.5 * tr + s).abs().max((0.5 * tr - s).abs())
    } else {
        det.abs().sqrt()
    }
}

/// Largest h with spectral radius ≤ 1 for the damped oscillator (ω, c = 2ζω).
/// ∞ when no limit exists (implicit Euler, or neither stiffness nor
/// damping), 0 when no h > 0 is stable. A mode of dampers alone (ω = 0)
/// has one: explicit methods step the decay −c·v, stable for c·h up to 2
/// (Euler) or 2.785 (RK4).
pub fn dt_limit(integrator: Integrator, omega: f64, damping_rate: f64) -> f64 {
    // The mode's fastest rate sets the scale of h.
    let scale = omega.max(0.0).max(damping_rate.max(0.0));
    if integrator.unconditionally_stable() || scale <= 0.0 {
        return f64::INFINITY;
    }
    let omega = omega.max(0.0);
    let stable = |h: f64| amplification(integrator, omega, damping_rate, h) <= 1.0 + 1e-14;
    // Smallest meaningful step: below it, call the method unconditionally unstable.
    let h_min = 1e-6 / scale;
    if !stable(h_min) {
        return 0.0;
    }
    let mut hi = h_min;
    while stable(hi) {
        hi *= 2.0;
        if hi > 1e6 / scale {
            return f64::INFINITY;
        }
    }
    let mut lo = hi / 2.0;
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if stable(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undamped_limits_match_the_textbook_values() {
        let w = 3.0;
        assert!((dt_limit(Integrator::SymplecticEuler, w, 0.0) * w - 2.0).abs() < 1e-9);
        assert!((dt_limit(Integrator::Rk4, w, 0.0) * w - 2.0 * 2f64.sqrt()).abs() < 1e-6);
        assert_eq!(dt_limit(Integrator::ExplicitEuler, w, 0.0), 0.0);
        assert_eq!(dt_limit(Integrator::ImplicitEuler, w, 0.0), f64::INFINITY);
    }

    #[test]
    fn damped_explicit_euler_limit_is_two_zeta_over_omega() {
        // |1 + λh| ≤ 1 with λ = −ζω ± iω√(1−ζ²) gives h ≤ 2ζ/ω = c/ω².
        let (w, c) = (10.0, 0.4);
        assert!((dt_limit(Integrator::ExplicitEuler, w, c) - c / (w * w)).abs() < 1e-9);
    }

    #[test]
    fn a_mode_of_dampers_alone_has_the_methods_real_axis_limit() {
        // v' = −c v: explicit and symplectic Euler |1 − ch| ≤ 1, so h ≤ 2/c;
        // RK4 |1 + z + z²/2 + z³/6 + z⁴/24| ≤ 1 down to z = −2.785293563…
        // (the real root of z³ + 4z² + 12z + 24). Before the fix this was ∞.
        let c = 2000.0;
        for (integrator, bound) in [
            (Integrator::ExplicitEuler, 2.0),
            (Integrator::SymplecticEuler, 2.0),
            (Integrator::Rk4, 2.785_293_563_405_282),
        ] {
            let h = dt_limit(integrator, 0.0, c);
            assert!((h * c / bound - 1.0).abs() < 1e-9, "{integrator}: {h}");
        }
        assert_eq!(dt_limit(Integrator::Rk4, 0.0, 0.0), f64::INFINITY);
    }
}
