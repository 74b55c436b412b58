//! Levels of detail: barycentric correlation between two resolutions of the
//! same cloth, and transfer of a state from one resolution to another.
//!
//! # Correlation (Sung 2018 §3.2)
//! Both grids cover the same W×H cloth, so a node is identified by its
//! material coordinates (u, v) ∈ \[0,1\]² (`u = i/(nx−1)`, `v = j/(ny−1)`). A
//! target node is located in the source grid's cell `(i, j) = ⌊(u·(nx−1),
//! v·(ny−1))⌋` and, inside it, in one of the two triangles of the source's
//! documented triangulation ([`Topology::grid`]: each quad split along its
//! (i,j)–(i+1,j+1) diagonal). With `(s, t)` the node's offsets inside the
//! cell:
//!
//! - `s ≥ t`: triangle (i,j) (i+1,j+1) (i+1,j), weights (1−s, t, s−t);
//! - `s < t`: triangle (i,j) (i,j+1) (i+1,j+1), weights (1−t, t−s, s).
//!
//! Weights are non-negative and sum to one, so the mapped position of a node
//! is a convex combination: rigid motions, uniform velocities and, within a
//! triangle, every affine deformation are reproduced exactly. A target node
//! that coincides with a source node gets weight 1 on it (offsets within
//! 1e-9 of a grid line are snapped), so correlating a grid with itself is
//! the identity.
//!
//! # Transfer
//! [`transfer_state`] maps positions *and* velocities through the
//! correlation (target ← source), so the moving cloth carries its momentum
//! over a level switch; pinned nodes are then put back on their prescribed
//! path by [`Simulation::set_state`](crate::sim::Simulation::set_state).
//! Mapping a fine state to a coarse one gives coarse positions equal to the
//! "coherent positions" of the error metric: the switch causes no jump there.
//!
//! # Settling
//! A coarse level samples a fine shape at its own nodes, and reads more in
//! it than the fine cloth holds: folds finer than its spacing shorten its
//! chords (its stretch springs go into compression where the fine cloth is
//! in tension) and land in its short bending modes. Left there, the level
//! springs out of the sampled shape within milliseconds. [`settle`] takes
//! one backward-Euler step of length `h` from rest at the transferred
//! positions, with the level's own forces: a mode of angular frequency ω
//! moves `ω²h²/(1 + ω²h²)` of the way to its equilibrium, so the stiff ones
//! (the compressed chords, the aliased short folds) settle and the slow ones
//! (the drape, its folds at the level's scale) stay; velocities, time and
//! step are kept. A slow mode still moves by about h²·a where the cloth
//! accelerates ((1/60 s)²·g is 2.7 mm).

use std::sync::Arc;

use crate::sim::{GridShape, Integrator, SimError, Simulation, StabilityCheck, State, Topology};

/// Errors of correlating two cloths.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LodError {
    /// A grid can only be correlated with a grid, and a mesh needs a
    /// source with triangles.
    #[error("{which} cloth cannot be correlated: a grid needs a grid, a mesh needs triangles to lie on")]
    NotAGrid {
        /// Which side: "source" or "target".
        which: &'static str,
    },
    /// The two grids do not describe the same cloth.
    #[error("the grids cover different cloths: {source_w}×{source_h} m vs {target_w}×{target_h} m")]
    DifferentCloth {
        /// The source cloth's width (m).
        source_w: f64,
        /// The source cloth's height (m).
        source_h: f64,
        /// The target cloth's width (m).
        target_w: f64,
        /// The target cloth's height (m).
        target_h: f64,
    },
    /// A state does not have the node count the correlation expects.
    #[error("state has {got} nodes, the correlation expects {expected}")]
    SizeMismatch {
        /// Nodes in the state given.
        got: usize,
        /// Nodes the correlation maps from.
        expected: usize,
    },
}

/// Where one target node lies in the source mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bary {
    /// Source nodes of the containing triangle.
    pub nodes: [u32; 3],
    /// Barycentric weights, ≥ 0, summing to 1.
    pub weights: [f64; 3],
}

/// Barycentric correlation: every node of a target grid expressed in a
/// triangle of a source grid. Direction matters: `Correlation::between(fine,
/// coarse)` maps fine states onto coarse nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Correlation {
    /// Grid shapes when both cloths are grids (None for a subset map).
    grids: Option<(GridShape, GridShape)>,
    /// Nodes of the source.
    n_source: usize,
    entries: Vec<Bary>,
}

impl Correlation {
    /// Correlate every node of `target` with a triangle of `source`: by
    /// material coordinates when both are grids ([`Correlation::grids`]), by
    /// the closest point on the rest surface when both are meshes
    /// ([`Correlation::surfaces`]).
    pub fn between(source: &Topology, target: &Topology) -> Result<Correlation, LodError> {
        match (source.grid, target.grid) {
            (Some(s), Some(t)) => Correlation::grids(&s, &t),
            (Some(_), None) => Err(LodError::NotAGrid { which: "target" }),
            (None, Some(_)) => Err(LodError::NotAGrid { which: "source" }),
            (None, None) if source.triangles.is_empty() => Err(LodError::NotAGrid { which: "source" }),
            (None, None) => Ok(Correlation::surfaces(source, target)),
        }
    }

    /// Correlate two meshes of one cloth (issue 23): every target node at
    /// the closest point of the source's rest surface, as barycentric
    /// weights on that triangle ([`crate::mesh::SurfaceIndex`]). A node that
    /// is a source vertex gets weight 1 on it, so a mesh with itself, and a
    /// simplified level against its reference, is exact; any other node
    /// moves with the triangle it lies on, as a grid node does.
    ///
    /// # Panics
    /// When `source` has no triangle ([`Correlation::between`] checks).
    pub fn surfaces(source: &Topology, target: &Topology) -> Correlation {
        let index = crate::mesh::SurfaceIndex::new(&source.rest_positions, &source.triangles);
        let entries = target
            .rest_positions
            .iter()
            .map(|&p| {
                let hit = index.closest(p);
                // A node on a source vertex is that vertex, whichever
                // triangle around it the search met first.
                match hit.weights.iter().position(|&w| w == 1.0) {
                    Some(k) => Bary {
                        nodes: [hit.nodes[k]; 3],
                        weights: [1.0, 0.0, 0.0],
                    },
                    None => Bary {
                        nodes: hit.nodes,
                        weights: hit.weights,
                    },
                }
            })
            .collect();
        Correlation {
            grids: None,
            n_source: source.n_nodes,
            entries,
        }
    }

    /// Correlate two grid shapes of the same cloth.
    pub fn grids(source: &GridShape, target: &GridShape) -> Result<Correlation, LodError> {
        let same = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
        if !same(source.width, target.width) || !same(source.height, target.height) {
            return Err(LodError::DifferentCloth {
                source_w: source.width,
                source_h: source.height,
                target_w: target.width,
                target_h: target.height,
            });
        }
        let mut entries = Vec::with_capacity(target.nx * target.ny);
        for j in 0..target.ny {
            for i in 0..target.nx {
                let (u, v) = target.uv(i, j);
                entries.push(locate(source, u, v));
            }
        }
        Ok(Correlation {
            grids: Some((*source, *target)),
            n_source: source.nx * source.ny,
            entries,
        })
    }

    /// The correlation of a point-sampled surface's simulated points with
    /// its reference cloud: target node k *is* source node `nodes[k]` (the
    /// simplified points are points of the cloud), so it lies on a vertex of
    /// every local triangle around that node: barycentric weight 1 on it.
    ///
    /// # Panics
    /// When a node is not below `n_source`.
    pub fn subset(n_source: usize, nodes: &[u32]) -> Correlation {
        assert!(
            nodes.iter().all(|&k| (k as usize) < n_source),
            "subset node out of range"
        );
        Correlation {
            grids: None,
            n_source,
            entries: nodes
                .iter()
                .map(|&k| Bary {
                    nodes: [k, k, k],
                    weights: [1.0, 0.0, 0.0],
                })
                .collect(),
        }
    }

    /// Source and target grid shapes (None for a subset map).
    pub fn grid_shapes(&self) -> Option<&(GridShape, GridShape)> {
        self.grids.as_ref()
    }

    /// One entry per target node, in node order.
    pub fn entries(&self) -> &[Bary] {
        &self.entries
    }

    /// Map a source field (SoA `[x…, y…, z…]`, positions or velocities;
    /// f64, or f32 as recorded trajectories store it) onto the target nodes,
    /// into `out` (SoA, target size).
    ///
    /// # Panics
    /// When the slices do not have the sizes of the correlated grids.
    pub fn map<T: Copy + Into<f64>>(&self, source: &[T], out: &mut [f64]) {
        let (ns, nt) = (self.n_source, self.entries.len());
        assert_eq!(source.len(), 3 * ns, "source field size");
        assert_eq!(out.len(), 3 * nt, "target field size");
        for c in 0..3 {
            let src = &source[c * ns..(c + 1) * ns];
            for (o, e) in out[c * nt..(c + 1) * nt].iter_mut().zip(&self.entries) {
                *o = e.weights[0] * src[e.nodes[0] as usize].into()
                    + e.weights[1] * src[e.nodes[1] as usize].into()
                    + e.weights[2] * src[e.nodes[2] as usize].into();
            }
        }
    }
}

/// Locate material point (u, v) in the triangulation of `grid`.
fn locate(grid: &GridShape, u: f64, v: f64) -> Bary {
    let snap = |x: f64| {
        let r = x.round();
        if (x - r).abs() < 1e-9 {
            r
        } else {
            x
        }
    };
    let x = snap(u * (grid.nx - 1) as f64);
    let y = snap(v * (grid.ny - 1) as f64);
    let i = (x.floor() as usize).min(grid.nx - 2);
    let j = (y.floor() as usize).min(grid.ny - 2);
    let (s, t) = (x - i as f64, y - j as f64);
    let n = |i: usize, j: usize| grid.node(i, j) as u32;
    let (p00, p10, p11, p01) = (n(i, j), n(i + 1, j), n(i + 1, j + 1), n(i, j + 1));
    if s >= t {
        Bary {
            nodes: [p00, p11, p10],
            weights: [1.0 - s, t, s - t],
        }
    } else {
        Bary {
            nodes: [p00, p01, p11],
            weights: [1.0 - t, t - s, s],
        }
    }
}

/// A state of `source` resampled onto `target`: positions and velocities
/// interpolated barycentrically, same time and step count. Pins are *not*
/// applied here (the target simulation's `set_state` does that).
pub fn transfer_state(source: &Topology, state: &State, target: &Topology) -> Result<State, LodError> {
    if state.n_nodes() != source.n_nodes {
        return Err(LodError::SizeMismatch {
            got: state.n_nodes(),
            expected: source.n_nodes,
        });
    }
    let corr = Correlation::between(source, target)?;
    let n = target.n_nodes;
    let mut pos = vec![0.0; 3 * n];
    let mut vel = vec![0.0; 3 * n];
    corr.map(&state.pos, &mut pos);
    corr.map(&state.vel, &mut vel);
    Ok(State {
        pos,
        vel,
        time: state.time,
        step: state.step,
    })
}

/// How far [`settle`] moved the nodes (m; pins stay where they are).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settled {
    /// Root mean square over the nodes.
    pub rms: f64,
    /// The largest move.
    pub max: f64,
}

/// The relative residual a settling's linear solve stops at (when the
/// level's own solver asks no looser). The settling moves the nodes by
/// millimetres (the skirt's 915 v level 2.7 mm rms at 1/60 s), so 1e-4
/// leaves a fraction of a micrometre unsolved; at the solver's default
/// 1e-8 the skirt's settling took 383 CG iterations and 11.9 ms on the
/// stepping thread. Measured on the metric and the cost: the lab's NOTEBOOK.md,
/// "Settling what a level cannot hold".
pub const SETTLE_TOLERANCE: f64 = 1e-4;

/// Settle `sim`'s state in place: its positions replaced by one backward
/// Euler step of `h` (s) taken from rest there, with the level's own
/// springs, bending, loads and contact (see the module docs); velocities,
/// time and step kept, pins put back where they are at that time.
/// [`settler`] then [`settle_with`]: it builds the settling twin, so it
/// allocates (and estimates the twin's stability, tens of milliseconds on
/// a thousand nodes): for a switch or a restart, not a step.
///
/// # Errors
/// A `h` that is not a positive finite step, or a step that diverged.
pub fn settle(sim: &mut Simulation, h: f64) -> Result<Settled, SimError> {
    let mut twin = settler(sim, h)?;
    settle_with(sim, &mut twin)
}

/// The twin [`settle_with`] settles `sim`'s states with: the same cloth,
/// masses, material and loads, stepped by backward Euler at `h`. Build it
/// where time is cheap (a level's twin before a switch reaches its
/// stepping thread).
///
/// # Errors
/// A `h` that is not a positive finite step.
pub fn settler(sim: &Simulation, h: f64) -> Result<Simulation, SimError> {
    if !(h.is_finite() && h > 0.0) {
        return Err(SimError::InvalidParameter {
            name: "settling step".into(),
            value: h,
            reason: "must be a positive, finite time (s)",
        });
    }
    let mut params = *sim.params();
    params.integrator = Integrator::ImplicitEuler;
    params.dt = h;
    params.cg.tolerance = params.cg.tolerance.max(SETTLE_TOLERANCE);
    Simulation::new(
        Arc::clone(sim.topology()),
        sim.masses().to_vec(),
        params,
        sim.loads().clone(),
        sim.state().clone(),
        StabilityCheck::Force,
    )
}

/// [`settle`] with a twin made by [`settler`] for `sim`'s cloth (its
/// state is overwritten): one set state and one implicit step.
///
/// # Errors
/// A twin of another cloth, or a step that diverged.
pub fn settle_with(sim: &mut Simulation, twin: &mut Simulation) -> Result<Settled, SimError> {
    let n = sim.topology().n_nodes;
    if twin.topology().n_nodes != n {
        return Err(SimError::SizeMismatch {
            what: "settling twin",
            got: twin.topology().n_nodes,
            expected: n,
        });
    }
    let mut rest = sim.state().clone();
    rest.vel.fill(0.0);
    twin.set_state(rest)?;
    if !twin.step().finite {
        return Err(SimError::InvalidParameter {
            name: "settling step".into(),
            value: twin.params().dt,
            reason: "its backward-Euler step diverged",
        });
    }
    let before = sim.state().pos.clone();
    let mut state = sim.state().clone();
    state.pos.copy_from_slice(&twin.state().pos);
    sim.set_state(state)?;
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for k in 0..n {
        let d2: f64 = (0..3)
            .map(|c| (sim.state().pos[c * n + k] - before[c * n + k]).powi(2))
            .sum();
        sum += d2;
        max = max.max(d2.sqrt());
    }
    Ok(Settled {
        rms: (sum / n.max(1) as f64).sqrt(),
        max,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Orientation;

    fn shape(nx: usize, ny: usize) -> GridShape {
        GridShape {
            nx,
            ny,
            width: 2.0,
            height: 1.0,
        }
    }

    #[test]
    fn a_grid_correlated_with_itself_is_the_identity() {
        let g = shape(7, 5);
        let c = Correlation::grids(&g, &g).unwrap();
        for (k, e) in c.entries().iter().enumerate() {
            let w: f64 = e
                .nodes
                .iter()
                .zip(e.weights)
                .filter(|(&n, _)| n as usize == k)
                .map(|(_, w)| w)
                .sum();
            assert_eq!(w, 1.0, "node {k}: {e:?}");
        }
    }

    #[test]
    fn hand_built_case_3x3_onto_2x2_cell_centre_and_thirds() {
        // Source: 2×2 nodes (one quad, two triangles). Target 3×3: its centre
        // (u,v) = (½,½) lies on the diagonal, s = t = ½ → triangle
        // (0,0)(1,1)(1,0) with weights (½, ½, 0).
        let src = shape(2, 2);
        let c = Correlation::grids(&src, &shape(3, 3)).unwrap();
        let centre = c.entries()[4];
        assert_eq!(centre.nodes, [0, 3, 1]);
        assert_eq!(centre.weights, [0.5, 0.5, 0.0]);
        // Target (1, 0): (u, v) = (½, 0) → s = ½, t = 0 → weights (½, 0, ½) on (0, 3, 1).
        assert_eq!(c.entries()[1].weights, [0.5, 0.0, 0.5]);
        // Target (0, 1): (0, ½) → s = 0 < t = ½ → triangle (0,0)(0,1)(1,1) = (0, 2, 3), weights (½, ½, 0).
        assert_eq!(c.entries()[3].nodes, [0, 2, 3]);
        assert_eq!(c.entries()[3].weights, [0.5, 0.5, 0.0]);
        // A point at (u,v) = (2/3, 1/3) of a 4×4 target on a 2×2 source:
        // s = 2/3 ≥ t = 1/3 → weights (1/3, 1/3, 1/3).
        let c4 = Correlation::grids(&src, &shape(4, 4)).unwrap();
        let e = c4.entries()[shape(4, 4).node(2, 1)];
        for (w, want) in e.weights.iter().zip([1.0 / 3.0; 3]) {
            assert!((w - want).abs() < 1e-15);
        }
    }

    #[test]
    fn weights_reproduce_rest_positions_for_uneven_resolutions() {
        for (fine, coarse) in [
            ((64, 64), (40, 40)),
            ((64, 64), (44, 44)),
            ((100, 37), (50, 20)),
            ((9, 5), (13, 11)),
        ] {
            let f = Topology::grid(shape(fine.0, fine.1), Orientation::Horizontal);
            let c = Topology::grid(shape(coarse.0, coarse.1), Orientation::Horizontal);
            let corr = Correlation::between(&f, &c).unwrap();
            let rest = State::at_rest(&f);
            let mut out = vec![0.0; 3 * c.n_nodes];
            corr.map(&rest.pos, &mut out);
            let want = State::at_rest(&c);
            for (a, b) in out.iter().zip(&want.pos) {
                assert!((a - b).abs() < 1e-12, "{fine:?}→{coarse:?}: {a} vs {b}");
            }
            for e in corr.entries() {
                assert!(e.weights.iter().all(|&w| (0.0..=1.0).contains(&w)));
                assert!((e.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            }
        }
    }

    /// The centre of a 3×3 grid of 1 m cells, every other node pinned, moved δ along
    /// x: linearised it feels its two x springs (2·K_s) and its four
    /// diagonals at 45° (4·K_h/2), damped likewise, so one backward-Euler
    /// step of h from rest takes it `h²·k·δ / (m + h·c + h²·k)` back,
    /// whatever h: a mode settles by `ω²h² / (1 + ω²h²)` of its way.
    #[test]
    fn settling_moves_a_mode_by_its_backward_euler_share() {
        use crate::sim::{CgSettings, Loads, Material, Pin, PinPath, SimParams, SpringCoeffs};
        let square = GridShape {
            nx: 3,
            ny: 3,
            width: 2.0,
            height: 2.0,
        };
        let topology = Arc::new(Topology::grid(square, Orientation::Horizontal));
        let (ks, cs, kh, ch, m) = (50.0, 0.3, 20.0, 0.1, 0.01);
        let material = Material::isotropic([
            SpringCoeffs { k: ks, c: cs },
            SpringCoeffs { k: kh, c: ch },
            SpringCoeffs { k: 5.0, c: 0.0 },
        ]);
        let params = SimParams {
            dt: 1e-4,
            integrator: Integrator::Rk4,
            material,
            gravity: [0.0; 3],
            drag: 0.0,
            stiffness_adjustment: None,
            strain_limit: None,
            cg: CgSettings {
                tolerance: 1e-13,
                max_iterations: 100,
            },
            self_contact: None,
        };
        let pins = (0..9u32)
            .filter(|&k| k != 4)
            .map(|k| Pin {
                node: k,
                anchor: topology.rest_positions[k as usize],
                path: PinPath::Fixed,
            })
            .collect();
        let loads = Loads {
            pins,
            ..Loads::default()
        };
        let (delta, v) = (1e-5, 0.3);
        let (k, c) = (2.0 * ks + 2.0 * kh, 2.0 * cs + 2.0 * ch);
        for h in [1e-3, 1e-2, 1e-1] {
            let mut state = State::at_rest(&topology);
            let x0 = state.pos[4];
            state.pos[4] += delta;
            state.vel[4] = v;
            state.time = 0.7;
            state.step = 7000;
            let mut sim = Simulation::new(
                topology.clone(),
                vec![m; 9],
                params,
                loads.clone(),
                state,
                StabilityCheck::Enforce,
            )
            .unwrap();
            let out = settle(&mut sim, h).unwrap();
            let want = delta * (1.0 - h * h * k / (m + h * c + h * h * k));
            let s = sim.state();
            assert!(
                (s.pos[4] - x0 - want).abs() < 1e-4 * delta,
                "h {h}: {} against {want}",
                s.pos[4] - x0
            );
            let rest = State::at_rest(&topology);
            for (i, (a, b)) in s.pos.iter().zip(&rest.pos).enumerate().filter(|(i, _)| *i != 4) {
                assert!((a - b).abs() < 1e-6 * delta, "h {h}: coordinate {i} moved {}", a - b);
            }
            assert_eq!(
                (s.vel[4], s.time, s.step),
                (v, 0.7, 7000),
                "h {h}: velocity, time and step kept"
            );
            assert!((out.max - (delta - want)).abs() < 1e-4 * delta, "h {h}: {out:?}");
            assert!((out.rms - out.max / 3.0).abs() < 1e-4 * delta, "h {h}: {out:?}");
        }
        let mut sim = Simulation::new(
            topology.clone(),
            vec![m; 9],
            params,
            loads,
            State::at_rest(&topology),
            StabilityCheck::Enforce,
        )
        .unwrap();
        let err = settle(&mut sim, 0.0).unwrap_err().to_string();
        assert!(err.contains("settling step"), "{err}");
    }

    #[test]
    fn different_cloths_are_refused() {
        let a = shape(4, 4);
        let mut b = shape(3, 3);
        b.width = 1.0;
        assert!(matches!(
            Correlation::grids(&a, &b),
            Err(LodError::DifferentCloth { .. })
        ));
    }
}
