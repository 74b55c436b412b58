//! Predictions under input: each level's error while a hand drags the
//! cloth.
//!
//! A level's predicted error is calibrated on the scene's script. A user's
//! touch takes the cloth where the script never does (folds, stretches),
//! and there a level's error can be several times that prediction
//! (docs/results.md, "Five drags"). So each level also gets a *prediction
//! under input*: its eq. 9 error, over the whole recorded span, while the
//! reference and the level both take the same standard drags, the largest
//! over [`PROBES`] of them. It is normalised by the *recorded* reference's
//! largest displacement, like the predicted and the live error, so the
//! three read on one scale.
//!
//! The drags ([`probes`]) are fixed by rule, from the scene alone, and were
//! fixed before any was run (none was changed after):
//! - **Where.** Candidates are the nine material points u, v ∈ {0, ½, 1}.
//!   They are taken farthest first from the pinned nodes and from the
//!   probes already taken, in metres on the rest shape; ties go to the
//!   first in row order. A candidate within a quarter of the cloth's
//!   shorter side of a pin is never taken. The hand holds a square patch
//!   of half-side 5 % of that side.
//! - **When.** The hand closes on the patch at the recorded frame nearest
//!   a fifth of the span, where the reference has it then.
//! - **How far.** It carries the patch out of the rest plane (against
//!   gravity, or along the normal when gravity lies in the plane), then
//!   across it towards the cloth's middle in u. Each leg is 0.3 √(W·H) long
//!   and takes a fifth of the span, cosine-eased, with 60 target updates a
//!   second. It holds a tenth of the span after each leg, then lets go, and
//!   the cloth swings free for the last fifth.
//! - **How stiffly.** The hand's spring holds the cloth's weight at a
//!   stretch of 5 % of √(W·H); its damping is critical for the patch's
//!   mass. A level (or the reference) whose step cannot hold that spring
//!   takes it softened to [`SOFTEN_AT_SWITCH`] of its largest stable
//!   stiffness, as the daemon softens a grab at a switch.
//!
//! - **On a mesh cloth** the same rule, read on its surface: a material
//!   point is located on the triangles in (u, v) (one outside the material,
//!   a disc's corner, is the nearest point of its border); distances are
//!   straight lines between rest positions; the cloth's side and √(W·H)
//!   are both √A (its area); the hand holds a disc of radius 5 % of √A;
//!   "out of the rest plane" is the rest surface's normal at the point and
//!   "across towards the middle in u" is the way to (½, v) on the tangent
//!   plane (at u = ½, against the surface's u direction, as on a grid).
//!   On a flat sheet it takes the points and legs the grid does.
//!
//! Pure: no I/O, no clock. The daemon runs it in the background after a
//! level is live; it is never on a switch's path.

use crate::mesh::RestSurface;
use crate::scene::Scene;
use crate::sim::{Material, Simulation, Topology};
use crate::touch::{Input, Patch, Script, Touch, TouchError, SOFTEN_AT_SWITCH};

use super::{ErrorAccumulator, ErrorReport, LodProblem, Reference};

/// How many standard drags a level's prediction under input takes the
/// largest error over.
pub const PROBES: usize = 3;

/// Why a level's error under a standard drag could not be measured.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TouchedError {
    /// The scene would not build.
    #[error("building the cloth: {0}")]
    Build(String),
    /// The scene has no free material point to take.
    #[error("every candidate material point is within a quarter of the cloth's side of a pin")]
    NoFreePoint,
    /// A drag's input was refused.
    #[error("probe '{probe}': the input at t = {time:.4} s was refused: {reason}")]
    Input {
        /// The probe's name.
        probe: String,
        /// When (s).
        time: f64,
        /// Why.
        reason: String,
    },
    /// The caller asked it to stop.
    #[error("stopped")]
    Stopped,
    /// The reference came out non-finite under the drag.
    #[error("probe '{probe}': the reference diverged at t = {time:.4} s")]
    Diverged {
        /// The probe's name.
        probe: String,
        /// When (s).
        time: f64,
    },
}

/// One standard drag.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Where the hand takes the cloth and how stiffly, e.g.
    /// `"u=0 v=1, 20 N/m"`.
    pub name: String,
    /// The inputs, in simulated time.
    pub script: Script,
}

/// The reference under one probe: metric frames at the recording's frame
/// steps.
#[derive(Debug, Clone)]
pub struct TouchedReference {
    /// The drag.
    pub probe: Probe,
    /// Positions (SoA, f32) at the recording's metric frames.
    pub frames: Vec<Vec<f32>>,
    /// Largest displacement from rest under the drag (m).
    pub o_max: f64,
    /// The stiffness the reference took the hand at, when softened (N/m).
    pub softened: Option<f64>,
}

/// A level's error under one probe.
#[derive(Debug, Clone)]
pub struct TouchedScore {
    /// The probe's name.
    pub probe: String,
    /// Eq. 9 over the span, normalised by the recorded reference's largest
    /// displacement.
    pub report: ErrorReport,
    /// The stiffness the level took the hand at, when softened (N/m).
    pub softened: Option<f64>,
}

/// The standard drags of `scene` (its reference resolution) against the
/// recorded `reference` (rule: the module's docs).
pub fn probes(scene: &Scene, reference: &Reference) -> Result<Vec<Probe>, TouchedError> {
    let sim = reference
        .scene_as_run(scene)
        .build()
        .map_err(|e| TouchedError::Build(e.to_string()))?;
    let layout = match (reference.topology.grid, RestSurface::of(&reference.topology)) {
        (Some(shape), _) => grid_layout(scene, reference, &shape, &sim),
        (None, Some(mesh)) => mesh_layout(scene, mesh, &sim),
        (None, None) => return Err(TouchedError::Build("the reference is neither a grid nor a mesh".into())),
    }?;

    // Timing, on the recording's frames.
    let span = *reference
        .frame_times
        .last()
        .ok_or_else(|| TouchedError::Build("an empty recording".into()))?;
    let f0 = nearest(&reference.frame_times, 0.2 * span);
    let t0 = reference.frame_times[f0];
    let (leg, hold, hz) = (0.2 * span, 0.1 * span, 60.0);
    let reach = 0.3 * layout.size;

    // The hand.
    let g = scene.params.gravity;
    let g_norm = dot(g, g).sqrt();
    let weight = layout.mass * if g_norm > 0.0 { g_norm } else { 9.81 };
    let stiffness = weight / (0.05 * layout.size);
    let radius = layout.radius;
    let damping = 2.0 * (stiffness * layout.patch_mass).sqrt();

    let mut out = Vec::with_capacity(layout.drags.len());
    for Drag {
        at: (u, v),
        out_of_plane,
        across,
    } in layout.drags
    {
        let patch = Patch { u, v, radius };
        let start = patch_position(&reference.topology, &patch, &reference.frames[f0])?;
        let grab = Input::Grab {
            id: 1,
            at: patch,
            target: None,
            stiffness,
            damping,
        };
        let legs = [out_of_plane, across].map(|d| d.map(|x| reach * x));
        let events = eased_drag(grab, t0, start, &legs, leg, hold, hz);
        let name = format!("u={u} v={v}, {stiffness:.3} N/m");
        let script = Script::new(events).map_err(|e| TouchedError::Input {
            probe: name.clone(),
            time: t0,
            reason: e.to_string(),
        })?;
        out.push(Probe { name, script });
    }
    Ok(out)
}

/// Where the standard drags take a cloth and how big its hand is.
struct Layout {
    /// Where each drag takes the cloth and which ways it carries it.
    drags: Vec<Drag>,
    /// The cloth's size √(area) (m): the legs' and the hand's stretch scale.
    size: f64,
    /// The cloth's mass (kg).
    mass: f64,
    /// The hand's patch radius (m) and the mass under it (kg).
    radius: f64,
    patch_mass: f64,
}

/// One standard drag: its material point, the unit direction of its first
/// leg (out of the rest surface) and of its second (across it, towards the
/// middle in u).
struct Drag {
    at: (f64, f64),
    out_of_plane: [f64; 3],
    across: [f64; 3],
}

/// The candidates u, v ∈ {0, ½, 1}, farthest first from the pins and from
/// those taken (`distance` between material points, `from_pins` of one, in
/// metres on the rest shape); none within `exclusion` of a pin.
fn take_candidates(
    distance: impl Fn((f64, f64), (f64, f64)) -> f64,
    from_pins: impl Fn((f64, f64)) -> f64,
    exclusion: f64,
) -> Result<Vec<(f64, f64)>, TouchedError> {
    let candidates: Vec<(f64, f64)> = [0.0, 0.5, 1.0]
        .iter()
        .flat_map(|&v| [0.0, 0.5, 1.0].map(|u| (u, v)))
        .collect();
    let mut taken: Vec<(f64, f64)> = Vec::new();
    while taken.len() < PROBES {
        let mut best: Option<((f64, f64), f64)> = None;
        for &c in &candidates {
            if taken.contains(&c) || from_pins(c) < exclusion {
                continue;
            }
            let d = taken.iter().map(|&t| distance(c, t)).fold(from_pins(c), f64::min);
            if best.is_none_or(|(_, b)| d > b) {
                best = Some((c, d));
            }
        }
        match best {
            Some((c, _)) => taken.push(c),
            None if taken.is_empty() => return Err(TouchedError::NoFreePoint),
            None => break,
        }
    }
    Ok(taken)
}

/// A grid: distances in material metres (u·W, v·H); the rest plane's
/// tangents through the middle; a square hand of half-side 5 % of the
/// shorter side.
fn grid_layout(
    scene: &Scene,
    reference: &Reference,
    shape: &crate::sim::GridShape,
    sim: &Simulation,
) -> Result<Layout, TouchedError> {
    let (w, h) = (scene.width, scene.height);
    let side = w.min(h);
    let pins: Vec<(f64, f64)> = sim
        .loads()
        .pins
        .iter()
        .map(|p| {
            let k = p.node as usize;
            let (u, v) = shape.uv(k % shape.nx, k / shape.nx);
            (u * w, v * h)
        })
        .collect();
    let distance = |a: (f64, f64), b: (f64, f64)| ((a.0 - b.0) * w).hypot((a.1 - b.1) * h);
    let from_pins = |c: (f64, f64)| {
        pins.iter()
            .map(|&p| (c.0 * w - p.0).hypot(c.1 * h - p.1))
            .fold(f64::INFINITY, f64::min)
    };
    let taken = take_candidates(distance, from_pins, 0.25 * side)?;

    // The rest frame: tangents along u and v through the middle, the normal.
    let rest = &reference.rest;
    let n = shape.nx * shape.ny;
    let at = |i: usize, j: usize| {
        let k = shape.node(i, j);
        [rest[k], rest[n + k], rest[2 * n + k]]
    };
    let e_u = unit(sub(at(shape.nx - 1, shape.ny / 2), at(0, shape.ny / 2)));
    let e_v = unit(sub(at(shape.nx / 2, shape.ny - 1), at(shape.nx / 2, 0)));
    let normal = against_gravity(unit(cross(e_u, e_v)), scene.params.gravity);
    let radius = 0.05 * side;
    Ok(Layout {
        drags: taken
            .into_iter()
            .map(|(u, v)| Drag {
                at: (u, v),
                out_of_plane: normal,
                across: if u >= 0.5 { e_u.map(|x| -x) } else { e_u },
            })
            .collect(),
        size: (w * h).sqrt(),
        mass: w * h * scene.areal_density,
        radius,
        patch_mass: scene.areal_density * (2.0 * radius).powi(2),
    })
}

/// A mesh: material points located on its triangles in (u, v)
/// ([`crate::mesh::material_point`]; one outside the material, such as a
/// disc's corner, is the nearest point of its border), distances straight
/// lines between their rest positions; at each drag's point the rest
/// surface's normal and, across it, the way towards (½, v) (or against
/// the surface's u direction where that way is not defined); the cloth's
/// size √A; a round hand of radius 5 % of √A.
fn mesh_layout(scene: &Scene, mesh: RestSurface<'_>, sim: &Simulation) -> Result<Layout, TouchedError> {
    let rest = mesh.positions;
    let located = |(u, v): (f64, f64)| crate::mesh::material_point(mesh, u, v);
    let rest_at = |c: (f64, f64)| {
        let (nodes, w) = located(c);
        (0..3).fold([0.0; 3], |x, k| {
            let p = rest[nodes[k] as usize];
            [x[0] + w[k] * p[0], x[1] + w[k] * p[1], x[2] + w[k] * p[2]]
        })
    };
    let length = |a: [f64; 3]| dot(a, a).sqrt();
    let area = mesh.area();
    let size = area.sqrt();
    let pins: Vec<[f64; 3]> = sim.loads().pins.iter().map(|p| rest[p.node as usize]).collect();
    let distance = |a: (f64, f64), b: (f64, f64)| length(sub(rest_at(a), rest_at(b)));
    let from_pins = |c: (f64, f64)| {
        let x = rest_at(c);
        pins.iter().map(|&p| length(sub(x, p))).fold(f64::INFINITY, f64::min)
    };
    let taken = take_candidates(distance, from_pins, 0.25 * size)?;
    let drags = taken
        .into_iter()
        .map(|c| {
            let (nodes, _) = located(c);
            let [a, b, d] = nodes.map(|k| rest[k as usize]);
            let normal = against_gravity(unit(cross(sub(b, a), sub(d, a))), scene.params.gravity);
            let tangential = |x: [f64; 3]| {
                let along = dot(x, normal);
                [
                    x[0] - along * normal[0],
                    x[1] - along * normal[1],
                    x[2] - along * normal[2],
                ]
            };
            let towards = tangential(sub(rest_at((0.5, c.1)), rest_at(c)));
            let across = if length(towards) > 1e-6 * size {
                unit(towards)
            } else {
                // ∂x/∂u on the triangle, against it (towards smaller u
                // from the middle, as the grid's −e_u at u = ½).
                let [ua, ub, ud] = nodes.map(|k| mesh.uv[k as usize]);
                let (du1, dv1, du2, dv2) = (ub[0] - ua[0], ub[1] - ua[1], ud[0] - ua[0], ud[1] - ua[1]);
                let det = du1 * dv2 - du2 * dv1;
                let (e1, e2) = (sub(b, a), sub(d, a));
                let x_u = [0, 1, 2].map(|i| (dv2 * e1[i] - dv1 * e2[i]) / det);
                unit(tangential(x_u)).map(|x| -x)
            };
            Drag {
                at: c,
                out_of_plane: normal,
                across,
            }
        })
        .collect();
    let radius = 0.05 * size;
    Ok(Layout {
        drags,
        size,
        mass: area * scene.areal_density,
        radius,
        patch_mass: scene.areal_density * std::f64::consts::PI * radius * radius,
    })
}

/// `normal` turned to point against gravity `g` (kept when it lies in the
/// plane).
fn against_gravity(normal: [f64; 3], g: [f64; 3]) -> [f64; 3] {
    if dot(normal, g) > 1e-9 * dot(g, g).sqrt() {
        normal.map(|x| -x)
    } else {
        normal
    }
}

/// A hand closing on a patch at `t0` (`grab`, which names the patch, the
/// grab's id and its spring; its target is where the patch is then,
/// `start`) and carrying it along `legs` (displacements, m), each over
/// `leg` seconds, cosine-eased, with `hz` target updates a second, holding
/// `hold` seconds after each, then letting go.
pub fn eased_drag(
    grab: Input,
    t0: f64,
    start: [f64; 3],
    legs: &[[f64; 3]],
    leg: f64,
    hold: f64,
    hz: f64,
) -> Vec<(f64, Input)> {
    let id = match grab {
        Input::Grab { id, .. } => id,
        _ => 0,
    };
    let mut events = vec![(t0, grab)];
    let mut t = t0;
    let mut from = start;
    let moves = (leg * hz).round().max(1.0) as usize;
    for d in legs {
        let to = [0, 1, 2].map(|c| from[c] + d[c]);
        for i in 1..=moves {
            let s = 0.5 - 0.5 * (std::f64::consts::PI * i as f64 / moves as f64).cos();
            let target = [0, 1, 2].map(|c| from[c] + s * (to[c] - from[c]));
            events.push((t + leg * i as f64 / moves as f64, Input::Move { id, target }));
        }
        t += leg + hold;
        from = to;
    }
    events.push((t, Input::Release { id }));
    events
}

/// Run the reference of `scene` (its own resolution, integrator and step,
/// as `reference` was recorded) under `probe`, keeping the metric frames.
/// `stop` is asked every 256 steps.
pub fn record_touched(
    scene: &Scene,
    reference: &Reference,
    probe: &Probe,
    stop: &dyn Fn() -> bool,
) -> Result<TouchedReference, TouchedError> {
    let scene = &reference.scene_as_run(scene);
    let mut sim = scene.build().map_err(|e| TouchedError::Build(e.to_string()))?;
    let n = sim.topology().n_nodes;
    let rest = sim.state().pos.clone();
    let stride = reference.spec.metric_stride;
    let mut hand = Hand::new(&probe.script, scene);
    let mut frames = Vec::with_capacity(reference.frames.len());
    let mut o_max2: f64 = 0.0;
    for step in 1..=reference.spec.frames {
        hand.apply_due(&probe.name, &mut sim)?;
        if !sim.step().finite {
            return Err(TouchedError::Diverged {
                probe: probe.name.clone(),
                time: sim.state().time,
            });
        }
        let pos = &sim.state().pos;
        for k in 0..n {
            o_max2 = o_max2.max((0..3).map(|c| (pos[c * n + k] - rest[c * n + k]).powi(2)).sum::<f64>());
        }
        if step % stride == 0 {
            frames.push(pos.iter().map(|&x| x as f32).collect());
        }
        if step.is_multiple_of(256) && stop() {
            return Err(TouchedError::Stopped);
        }
    }
    Ok(TouchedReference {
        probe: probe.clone(),
        frames,
        o_max: o_max2.sqrt(),
        softened: hand.softened,
    })
}

impl LodProblem {
    /// Eq. 9 of this level with `material` against `touched` (the reference
    /// under the same probe), over every metric frame, normalised by the
    /// recorded reference's largest displacement. A level that diverges
    /// under the drag scores as diverged (an error of 1 per frame lost).
    /// `stop` is asked every metric frame.
    pub fn score_touched(
        &self,
        material: Material,
        touched: &TouchedReference,
        stop: &dyn Fn() -> bool,
    ) -> Result<TouchedScore, TouchedError> {
        let mut sim = self
            .simulation(material)
            .map_err(|e| TouchedError::Build(e.to_string()))?;
        let n = self.topology().n_nodes;
        let frames = touched.frames.len();
        let mut acc = ErrorAccumulator::new(self.reference.o_max, n, frames);
        let mut mapped = vec![0.0; 3 * n];
        let mut hand = Hand::new(&touched.probe.script, &self.scene);
        for (f, frame) in touched.frames.iter().enumerate() {
            self.turns.checkpoint();
            for _ in 0..self.steps_per_frame {
                hand.apply_due(&touched.probe.name, &mut sim)?;
                sim.step();
            }
            if sim.diverged() {
                acc.mark_diverged();
                break;
            }
            if stop() {
                return Err(TouchedError::Stopped);
            }
            self.correlation().map(frame, &mut mapped);
            acc.push(self.reference.frame_times[f], &mapped, &sim.state().pos);
        }
        Ok(TouchedScore {
            probe: touched.probe.name.clone(),
            report: acc.report(),
            softened: hand.softened,
        })
    }
}

/// A script applied to one simulation, softening a grab its step cannot
/// hold (as the daemon does at a switch): how the standard drags are put on
/// the reference and on each level.
#[derive(Debug)]
pub struct Hand<'a> {
    script: &'a Script,
    touch: Touch,
    next: usize,
    softened: Option<f64>,
}

impl<'a> Hand<'a> {
    /// `script` on a cloth of `scene`, nothing applied yet.
    pub fn new(script: &'a Script, scene: &Scene) -> Hand<'a> {
        Hand {
            script,
            touch: Touch::new(scene),
            next: 0,
            softened: None,
        }
    }

    /// The stiffness a grab was softened to, if one was (N/m).
    pub fn softened(&self) -> Option<f64> {
        self.softened
    }

    /// Apply every event due at `sim`'s current time (within half a step);
    /// `probe` names the drag in an error.
    pub fn apply_due(&mut self, probe: &str, sim: &mut Simulation) -> Result<(), TouchedError> {
        let due = sim.state().time + 0.5 * sim.params().dt;
        while let Some((t, input)) = self.script.events().get(self.next) {
            if *t > due {
                break;
            }
            let refused = |e: TouchError| TouchedError::Input {
                probe: probe.to_string(),
                time: *t,
                reason: e.to_string(),
            };
            match self.touch.apply(input, sim) {
                Ok(()) => {}
                Err(TouchError::Unstable { max, .. }) if max > 0.0 => {
                    let Input::Grab {
                        id,
                        at,
                        target,
                        damping,
                        ..
                    } = *input
                    else {
                        unreachable!("only a grab can be unstable")
                    };
                    let stiffness = SOFTEN_AT_SWITCH * max;
                    let softer = Input::Grab {
                        id,
                        at,
                        target,
                        stiffness,
                        damping,
                    };
                    self.touch.apply(&softer, sim).map_err(refused)?;
                    self.softened = Some(stiffness);
                }
                Err(e) => return Err(refused(e)),
            }
            self.next += 1;
        }
        Ok(())
    }
}

/// Σ wᵢ xᵢ over `patch` on the cloth of `topology`, from SoA f32 positions.
fn patch_position(topology: &Topology, patch: &Patch, pos: &[f32]) -> Result<[f64; 3], TouchedError> {
    let (nodes, weights) = patch
        .on(topology)
        .ok_or_else(|| TouchedError::Build("the reference is neither a grid nor a mesh".into()))?;
    let n = pos.len() / 3;
    let mut x = [0.0; 3];
    for (&k, &wk) in nodes.iter().zip(&weights) {
        for (c, xc) in x.iter_mut().enumerate() {
            *xc += wk * f64::from(pos[c * n + k as usize]);
        }
    }
    Ok(x)
}

fn nearest(times: &[f64], t: f64) -> usize {
    (0..times.len())
        .min_by(|&a, &b| (times[a] - t).abs().total_cmp(&(times[b] - t).abs()))
        .unwrap_or(0)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    if l > 0.0 {
        a.map(|x| x / l)
    } else {
        a
    }
}
