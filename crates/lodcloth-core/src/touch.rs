//! Live input: what clients do to a running cloth, kept in material terms so
//! that it means the same at every level of detail.
//!
//! An [`Input`] names a part of the cloth by material coordinates (u, v) ∈
//! [0, 1]² (u along the width from the left edge, v along the height from
//! the top row, as scene selectors do) and gives forces, positions and
//! velocities in SI units. A [`Touch`] records the inputs in force (grabs,
//! a wind that replaces the scene's, pin moves) and resolves them onto a
//! [`Simulation`] at its level: a grab or an impulse acts on a patch
//! through its consistent nodal weights ([`crate::scene::patch_weights`]),
//! so its total force and the material point it acts at are the same on
//! every grid. After a level switch, [`Touch::resolve`] puts the same
//! inputs on the new level's simulation: a drag survives the switch.
//!
//! Pure: no clock, no I/O. Times are the simulation's own.

use crate::scene::{patch_weights, Scene, Selector};
use std::sync::Arc;

use crate::mesh::RestSurface;
use crate::sim::{Grab, GridShape, PinShift, Profile, SimError, Simulation, Topology, Wind};

/// A part of the cloth: the square of half-side `radius` metres about the
/// material point (u, v) (a point when `radius` is 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patch {
    /// Along the width, 0 = left edge, 1 = right edge.
    pub u: f64,
    /// Along the height, 0 = top row, 1 = bottom row.
    pub v: f64,
    /// Half-side of the square (m, ≥ 0).
    pub radius: f64,
}

/// The fraction of a new level's largest stable grab stiffness a grab too
/// stiff for it is softened to at a switch.
pub const SOFTEN_AT_SWITCH: f64 = 0.9;

/// A grab softened at a level switch ([`Touch::resolve`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Softened {
    /// The grab.
    pub id: u32,
    /// Its stiffness before (N/m).
    pub from: f64,
    /// Its stiffness on the new level (N/m).
    pub to: f64,
}

/// One thing a client does to the cloth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Input {
    /// Take hold of `at` with a spring to `target` (a new `id`, or move an
    /// existing grab's patch and spring).
    Grab {
        /// The client's name for this grab.
        id: u32,
        /// The part of the cloth held.
        at: Patch,
        /// World point the patch is pulled to (m); `None`: where the patch
        /// is now, so the grab starts without a jerk (a hand closing on
        /// the cloth) and later moves drag it.
        target: Option<[f64; 3]>,
        /// Spring constant (N/m, > 0).
        stiffness: f64,
        /// Damping against the patch's velocity (N·s/m, ≥ 0).
        damping: f64,
    },
    /// Move a grab's target.
    Move {
        /// The grab.
        id: u32,
        /// Its new target (m).
        target: [f64; 3],
    },
    /// Let go of a grab.
    Release {
        /// The grab.
        id: u32,
    },
    /// Let go of every grab.
    ReleaseAll,
    /// Move one of the scene's pin sets off its scripted path.
    MovePin {
        /// Index of the set in the scene's `[[pins]]`.
        pin: u32,
        /// Where to (m, from the scripted position).
        offset: [f64; 3],
        /// Taken linearly over this much simulated time (s).
        seconds: f64,
    },
    /// Replace the scene's wind.
    Wind {
        /// Air velocity (m/s) at gust phase 0.
        velocity: [f64; 3],
        /// The velocity is scaled by 1 + gust · sin(2π·gust_hz·t); a
        /// fraction in [0, 1].
        gust: f64,
        /// Gust frequency (Hz).
        gust_hz: f64,
    },
    /// Back to the scene's own wind (none if it has none).
    SceneWind,
    /// Give a patch momentum at once.
    Impulse {
        /// The part of the cloth struck.
        at: Patch,
        /// Momentum given (N·s).
        impulse: [f64; 3],
    },
}

/// Why an input was refused: the field and what was wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TouchError {
    /// A field is out of range.
    #[error("{field} = {value}: {reason}")]
    Field {
        /// The wire's name of the field (`grab.at.u`).
        field: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        reason: String,
    },
    /// The grab's spring would make the level unstable at its time step.
    #[error(
        "stiffness = {stiffness} N/m: unstable at this level's dt ({dt:e} s; stable up to {max:.4} N/m \
         with this patch and damping; a larger radius spreads the spring over more mass)"
    )]
    Unstable {
        /// The stiffness asked for (N/m).
        stiffness: f64,
        /// The largest stable one (N/m).
        max: f64,
        /// The level's time step (s).
        dt: f64,
    },
    /// The simulation refused the change.
    #[error("{0}")]
    Sim(#[from] SimError),
}

/// At most this many grabs at once.
pub const MAX_GRABS: usize = 16;

/// Largest |coordinate| of a target or offset (m): far beyond any cloth the
/// daemon simulates, and small enough that forces stay finite.
pub const MAX_COORDINATE: f64 = 1e4;

/// Largest velocity change an impulse may give any node (m/s).
pub const MAX_IMPULSE_SPEED: f64 = 50.0;

fn field(field: &'static str, value: f64, reason: impl Into<String>) -> TouchError {
    TouchError::Field {
        field,
        value,
        reason: reason.into(),
    }
}

impl Patch {
    fn check(&self, path: [&'static str; 3]) -> Result<(), TouchError> {
        for (name, x) in [(path[0], self.u), (path[1], self.v)] {
            if !(0.0..=1.0).contains(&x) {
                return Err(field(name, x, "a material coordinate must be within [0, 1]"));
            }
        }
        if !(self.radius >= 0.0 && self.radius <= MAX_COORDINATE) {
            return Err(field(path[2], self.radius, "must be finite and ≥ 0 (m)"));
        }
        Ok(())
    }

    /// Nodes and weights of this patch on a grid of `shape`.
    pub fn weights(&self, shape: &GridShape) -> (Vec<u32>, Vec<f64>) {
        let du = self.radius / shape.width;
        let dv = self.radius / shape.height;
        patch_weights(shape, [self.u - du, self.u + du], [self.v - dv, self.v + dv])
            .into_iter()
            .unzip()
    }

    /// Nodes and weights of this patch on a mesh level: the rest surface
    /// within `radius` of the material point ([`crate::mesh::patch_weights`]).
    pub fn mesh_weights(&self, level: RestSurface<'_>) -> (Vec<u32>, Vec<f64>) {
        crate::mesh::patch_weights(level, self.u, self.v, self.radius)
            .into_iter()
            .unzip()
    }

    /// Nodes and weights of this patch on a cloth of `topology`: a grid's
    /// or a mesh level's; `None` for anything else (a point surface).
    pub fn on(&self, topology: &Topology) -> Option<(Vec<u32>, Vec<f64>)> {
        match (topology.grid, RestSurface::of(topology)) {
            (Some(shape), _) => Some(self.weights(&shape)),
            (None, Some(level)) => Some(self.mesh_weights(level)),
            (None, None) => None,
        }
    }

    fn weights_on(&self, cloth: &Cloth) -> (Vec<u32>, Vec<f64>) {
        match cloth {
            Cloth::Grid(shape) => self.weights(shape),
            Cloth::Mesh(level) => self.mesh_weights(mesh_level(level)),
        }
    }
}

fn check_point(name: [&'static str; 3], p: [f64; 3]) -> Result<(), TouchError> {
    for (n, x) in name.into_iter().zip(p) {
        if !(x.abs() <= MAX_COORDINATE) {
            return Err(field(n, x, format!("must be finite and within ±{MAX_COORDINATE} m")));
        }
    }
    Ok(())
}

impl Input {
    /// Check every field that does not depend on the cloth: coordinates in
    /// range, finite values, positive stiffness. Field names are the wire's
    /// (`grab.at.u`, `wind.gust`, …).
    pub fn check(&self) -> Result<(), TouchError> {
        match *self {
            Input::Grab {
                at,
                target,
                stiffness,
                damping,
                ..
            } => {
                at.check(["grab.at.u", "grab.at.v", "grab.at.radius"])?;
                if let Some(target) = target {
                    check_point(["grab.target.x", "grab.target.y", "grab.target.z"], target)?;
                }
                if !(stiffness > 0.0 && stiffness.is_finite()) {
                    return Err(field("grab.stiffness", stiffness, "must be positive and finite (N/m)"));
                }
                if !(damping >= 0.0 && damping.is_finite()) {
                    return Err(field("grab.damping", damping, "must be finite and ≥ 0 (N·s/m)"));
                }
            }
            Input::Move { target, .. } => check_point(["move.target.x", "move.target.y", "move.target.z"], target)?,
            Input::Release { .. } | Input::ReleaseAll | Input::SceneWind => {}
            Input::MovePin { offset, seconds, .. } => {
                check_point(["move_pin.offset.x", "move_pin.offset.y", "move_pin.offset.z"], offset)?;
                if !(0.0..=3600.0).contains(&seconds) {
                    return Err(field("move_pin.seconds", seconds, "must be within [0, 3600] s"));
                }
            }
            Input::Wind {
                velocity,
                gust,
                gust_hz,
            } => {
                for (n, x) in ["wind.velocity.x", "wind.velocity.y", "wind.velocity.z"]
                    .into_iter()
                    .zip(velocity)
                {
                    if !(x.abs() <= 100.0) {
                        return Err(field(n, x, "must be finite and within ±100 m/s"));
                    }
                }
                if !(0.0..=1.0).contains(&gust) {
                    return Err(field("wind.gust", gust, "a fraction of the velocity within [0, 1]"));
                }
                if !(0.0..=100.0).contains(&gust_hz) {
                    return Err(field("wind.gust_hz", gust_hz, "must be within [0, 100] Hz"));
                }
            }
            Input::Impulse { at, impulse } => {
                at.check(["impulse.at.u", "impulse.at.v", "impulse.at.radius"])?;
                for (n, x) in ["impulse.impulse.x", "impulse.impulse.y", "impulse.impulse.z"]
                    .into_iter()
                    .zip(impulse)
                {
                    if !(x.abs() <= 1e3) {
                        return Err(field(n, x, "must be finite and within ±1000 N·s"));
                    }
                }
            }
        }
        Ok(())
    }
}

/// A grab in material terms.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GrabSpec {
    id: u32,
    at: Patch,
    target: [f64; 3],
    stiffness: f64,
    damping: f64,
}

/// The inputs in force on one cloth, and the scene facts needed to resolve
/// them at any level (its pin sets and its own wind).
#[derive(Debug, Clone, PartialEq)]
pub struct Touch {
    pin_sets: Vec<Selector>,
    scene_wind: Option<Wind>,
    grabs: Vec<GrabSpec>,
    /// Replaces the scene's wind while set.
    wind: Option<Wind>,
    /// One per pin set once any was moved.
    pin_shifts: Vec<PinShift>,
}

impl Touch {
    /// No input yet on a cloth of `scene`.
    pub fn new(scene: &Scene) -> Touch {
        Touch {
            pin_sets: scene.pin_sets(),
            scene_wind: scene.wind(),
            grabs: Vec::new(),
            wind: None,
            pin_shifts: Vec::new(),
        }
    }

    /// True while an input acts on the cloth at simulated time `t`: a grab
    /// is held, the wind is not the scene's, or a pin is off its script.
    pub fn active(&self, t: f64) -> bool {
        !self.grabs.is_empty() || self.wind.is_some() || self.pin_shifts.iter().any(|s| !s.is_rest_from(t))
    }

    /// Ids of the grabs held.
    pub fn grab_ids(&self) -> Vec<u32> {
        self.grabs.iter().map(|g| g.id).collect()
    }

    /// Apply `input` to `sim` at its current time and record it. Nothing
    /// changes when it is refused.
    pub fn apply(&mut self, input: &Input, sim: &mut Simulation) -> Result<(), TouchError> {
        input.check()?;
        let cloth = cloth(sim)?;
        let t = sim.state().time;
        match *input {
            Input::Grab {
                id,
                at,
                target,
                stiffness,
                damping,
            } => {
                let target = match target {
                    Some(t) => t,
                    None => {
                        let (nodes, weights) = at.weights_on(&cloth);
                        let here = Grab {
                            nodes,
                            weights,
                            target: [0.0; 3],
                            stiffness: 0.0,
                            damping: 0.0,
                        };
                        here.patch(&sim.state().pos, &sim.state().vel).0
                    }
                };
                let spec = GrabSpec {
                    id,
                    at,
                    target,
                    stiffness,
                    damping,
                };
                let mut grabs = self.grabs.clone();
                let held = grabs.len();
                match grabs.iter_mut().find(|g| g.id == id) {
                    Some(g) => *g = spec,
                    None if held >= MAX_GRABS => {
                        return Err(field(
                            "grab.id",
                            f64::from(id),
                            format!("{MAX_GRABS} grabs are held already; release one first"),
                        ))
                    }
                    None => grabs.push(spec),
                }
                let resolved: Vec<Grab> = grabs.iter().map(|g| resolve_grab(g, &cloth)).collect();
                if !sim.grab_headroom(&resolved).stable() {
                    let others: Vec<Grab> = grabs
                        .iter()
                        .zip(&resolved)
                        .filter(|(g, _)| g.id != id)
                        .map(|(_, r)| r.clone())
                        .collect();
                    let mine = resolve_grab(&spec, &cloth);
                    return Err(TouchError::Unstable {
                        stiffness,
                        max: sim.max_grab_stiffness(&mine, &others),
                        dt: sim.params().dt,
                    });
                }
                sim.set_grabs(resolved)?;
                self.grabs = grabs;
            }
            Input::Move { id, target } => {
                let Some(i) = self.grabs.iter().position(|g| g.id == id) else {
                    return Err(self.no_grab("move.id", id));
                };
                let mut grabs = sim.grabs().to_vec();
                grabs[i].target = target;
                sim.set_grabs(grabs)?;
                self.grabs[i].target = target;
            }
            Input::Release { id } => {
                let Some(i) = self.grabs.iter().position(|g| g.id == id) else {
                    return Err(self.no_grab("release.id", id));
                };
                let mut grabs = sim.grabs().to_vec();
                grabs.remove(i);
                sim.set_grabs(grabs)?;
                self.grabs.remove(i);
            }
            Input::ReleaseAll => {
                sim.set_grabs(Vec::new())?;
                self.grabs.clear();
            }
            Input::MovePin { pin, offset, seconds } => {
                let Some(set) = self.pin_sets.get(pin as usize) else {
                    return Err(field(
                        "move_pin.pin",
                        f64::from(pin),
                        format!(
                            "the scene has {} pin sets (0 to {})",
                            self.pin_sets.len(),
                            self.pin_sets.len().saturating_sub(1)
                        ),
                    ));
                };
                let from = self.pin_shifts.get(pin as usize).map_or([0.0; 3], |s| s.at(t).0);
                let shift = PinShift {
                    from,
                    to: offset,
                    start: t,
                    end: t + seconds,
                };
                let on = pins_of(set, &cloth, sim);
                sim.shift_pins(&on, shift)?;
                if self.pin_shifts.len() != self.pin_sets.len() {
                    self.pin_shifts = vec![PinShift::default(); self.pin_sets.len()];
                }
                self.pin_shifts[pin as usize] = shift;
            }
            Input::Wind {
                velocity,
                gust,
                gust_hz,
            } => {
                let wind = Wind {
                    velocity,
                    profile: if gust > 0.0 && gust_hz > 0.0 {
                        Profile::Sine {
                            frequency: gust_hz,
                            phase: 0.0,
                            amplitude: gust,
                            offset: 1.0,
                        }
                    } else {
                        Profile::Constant
                    },
                    air_density: self.scene_wind.map_or(1.2, |w| w.air_density),
                    drag_coefficient: self.scene_wind.map_or(1.0, |w| w.drag_coefficient),
                };
                sim.set_wind(Some(wind))?;
                self.wind = Some(wind);
            }
            Input::SceneWind => {
                sim.set_wind(self.scene_wind)?;
                self.wind = None;
            }
            Input::Impulse { at, impulse } => {
                let (nodes, weights) = at.weights_on(&cloth);
                let masses = sim.masses();
                let pinned = sim.loads().pins.iter().map(|p| p.node).collect::<Vec<_>>();
                let speed = nodes
                    .iter()
                    .zip(&weights)
                    .filter(|(k, _)| !pinned.contains(k))
                    .map(|(&k, &w)| w / masses[k as usize])
                    .fold(0.0, f64::max)
                    * impulse.iter().map(|x| x * x).sum::<f64>().sqrt();
                if speed > MAX_IMPULSE_SPEED {
                    return Err(field(
                        "impulse.impulse",
                        impulse.iter().map(|x| x * x).sum::<f64>().sqrt(),
                        format!(
                            "would move a node at {speed:.1} m/s at this level (at most {MAX_IMPULSE_SPEED}); \
                             a smaller impulse or a larger radius"
                        ),
                    ));
                }
                sim.add_impulse(&nodes, &weights, impulse)?;
            }
        }
        Ok(())
    }

    fn no_grab(&self, name: &'static str, id: u32) -> TouchError {
        field(
            name,
            f64::from(id),
            format!("no grab with this id; held: {:?}", self.grab_ids()),
        )
    }

    /// Put the inputs in force on `sim` (a new level of the same cloth, at
    /// the time the old one reached): the same grabs on the same material
    /// patches, the same wind, the pins where their moves have them. A grab
    /// too stiff for the new level's dt (a finer grid has lighter nodes) is
    /// softened to [`SOFTEN_AT_SWITCH`] of the largest stiffness stable
    /// there, so a drag survives the switch; each softened grab is returned.
    /// One that no stiffness holds stably is let go, and the error names it.
    pub fn resolve(&mut self, sim: &mut Simulation) -> Result<Vec<Softened>, TouchError> {
        let cloth = cloth(sim)?;
        let mut kept: Vec<GrabSpec> = Vec::new();
        let mut resolved: Vec<Grab> = Vec::new();
        let mut softened = Vec::new();
        let mut refused = None;
        for g in &self.grabs {
            let mut r = resolve_grab(g, &cloth);
            resolved.push(r.clone());
            if sim.grab_headroom(&resolved).stable() {
                kept.push(*g);
                continue;
            }
            resolved.pop();
            let max = sim.max_grab_stiffness(&r, &resolved);
            r.stiffness = SOFTEN_AT_SWITCH * max;
            resolved.push(r.clone());
            if max > 0.0 && sim.grab_headroom(&resolved).stable() {
                softened.push(Softened {
                    id: g.id,
                    from: g.stiffness,
                    to: r.stiffness,
                });
                kept.push(GrabSpec {
                    stiffness: r.stiffness,
                    ..*g
                });
            } else {
                resolved.pop();
                refused = Some(TouchError::Unstable {
                    stiffness: g.stiffness,
                    max,
                    dt: sim.params().dt,
                });
            }
        }
        sim.set_grabs(resolved)?;
        self.grabs = kept;
        if self.wind.is_some() {
            sim.set_wind(self.wind)?;
        }
        for (i, shift) in self.pin_shifts.iter().enumerate() {
            if *shift != PinShift::default() {
                let on = pins_of(&self.pin_sets[i], &cloth, sim);
                sim.shift_pins(&on, *shift)?;
            }
        }
        refused.map_or(Ok(softened), Err)
    }

    /// Forget every input and take their loads off `sim` at once (the
    /// scene starts over): no grab, the scene's wind, pins on their scripts.
    pub fn reset(&mut self, sim: &mut Simulation) -> Result<(), TouchError> {
        sim.set_grabs(Vec::new())?;
        sim.set_wind(self.scene_wind)?;
        let all: Vec<usize> = (0..sim.loads().pins.len()).collect();
        if !sim.pin_shifts().is_empty() {
            sim.shift_pins(&all, PinShift::default())?;
        }
        self.grabs.clear();
        self.wind = None;
        self.pin_shifts.clear();
        Ok(())
    }

    /// The inputs that let go of everything at simulated time `t`: release
    /// every grab, the scene's wind back, moved pins back on their scripts
    /// over `seconds` (empty when nothing is in force). Applied in order,
    /// they are what [`Touch::release`] does, so a log of them replays it.
    pub fn letting_go(&self, t: f64, seconds: f64) -> Vec<Input> {
        let mut out = Vec::new();
        if !self.grabs.is_empty() {
            out.push(Input::ReleaseAll);
        }
        if self.wind.is_some() {
            out.push(Input::SceneWind);
        }
        for (pin, shift) in self.pin_shifts.iter().enumerate() {
            if !shift.is_rest_from(t) {
                out.push(Input::MovePin {
                    pin: pin as u32,
                    offset: [0.0; 3],
                    seconds,
                });
            }
        }
        out
    }

    /// Let go of everything now: the inputs of [`Touch::letting_go`].
    pub fn release(&mut self, sim: &mut Simulation, seconds: f64) -> Result<(), TouchError> {
        for input in self.letting_go(sim.state().time, seconds) {
            self.apply(&input, sim)?;
        }
        Ok(())
    }
}

/// What input resolves on: a grid's shape or a mesh level's topology
/// (one with its mesh nodes: [`cloth`] makes no other).
enum Cloth {
    Grid(GridShape),
    Mesh(Arc<Topology>),
}

fn cloth(sim: &Simulation) -> Result<Cloth, TouchError> {
    let topology = sim.topology();
    match (topology.grid, &topology.mesh) {
        (Some(shape), _) => Ok(Cloth::Grid(shape)),
        (None, Some(_)) => Ok(Cloth::Mesh(topology.clone())),
        (None, None) => Err(TouchError::Field {
            field: "instance",
            value: f64::NAN,
            reason: "live input acts on grid and mesh cloths; this instance is neither".into(),
        }),
    }
}

/// The rest surface of a [`Cloth::Mesh`] level.
fn mesh_level(topology: &Topology) -> RestSurface<'_> {
    RestSurface::of(topology).expect("cloth() makes Cloth::Mesh only of a topology with mesh nodes")
}

fn resolve_grab(g: &GrabSpec, cloth: &Cloth) -> Grab {
    let (nodes, weights) = g.at.weights_on(cloth);
    Grab {
        nodes,
        weights,
        target: g.target,
        stiffness: g.stiffness,
        damping: g.damping,
    }
}

/// Indices into the simulation's pins of the nodes `set` selects.
fn pins_of(set: &Selector, cloth: &Cloth, sim: &Simulation) -> Vec<usize> {
    let nodes = match cloth {
        Cloth::Grid(shape) => crate::scene::select_nodes(set, shape),
        Cloth::Mesh(level) => crate::scene::select_mesh(set, mesh_level(level)),
    };
    sim.loads()
        .pins
        .iter()
        .enumerate()
        .filter(|(_, p)| nodes.binary_search(&p.node).is_ok())
        .map(|(i, _)| i)
        .collect()
}

/// Inputs at simulated times: a session to replay on any level (the
/// reference and each coarse level get the same touches at the same
/// moments, to the nearest step).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Script {
    events: Vec<(f64, Input)>,
}

impl Script {
    /// A script of `events` (time in s, input), each checked; ordered by
    /// time, events at the same time in the order given.
    pub fn new(mut events: Vec<(f64, Input)>) -> Result<Script, TouchError> {
        for (t, input) in &events {
            if !(t.is_finite() && *t >= 0.0) {
                return Err(field("script.time", *t, "must be finite and ≥ 0 (s)"));
            }
            input.check()?;
        }
        events.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(Script { events })
    }

    /// The events, in time order.
    pub fn events(&self) -> &[(f64, Input)] {
        &self.events
    }

    /// Apply to `sim` every event from `*next` on that is due at its
    /// current time (within half a step), advancing `*next` past them.
    pub fn apply_due(&self, next: &mut usize, touch: &mut Touch, sim: &mut Simulation) -> Result<(), TouchError> {
        let due = sim.state().time + 0.5 * sim.params().dt;
        while let Some((t, input)) = self.events.get(*next) {
            if *t > due {
                break;
            }
            touch.apply(input, sim)?;
            *next += 1;
        }
        Ok(())
    }
}
