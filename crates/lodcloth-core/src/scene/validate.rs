//! Validation: a [`RawScene`] becomes a [`Scene`], or every problem is
//! reported at once, each with its field path (`springs.shear.k: …`).
//!
//! Sections are checked in a fixed order — cloth, springs, simulation,
//! strain, pins, forces, wind, colliders — and within a section field by field, so the
//! list of problems reads like the file. Each check records a problem and
//! carries on with the value as given, so one mistake never hides another.

use super::raw::{
    RawCloth, RawCoeffs, RawCollider, RawContact, RawForce, RawLimit, RawMaterial, RawModuli, RawOrientation, RawPin,
    RawPinPath, RawProfile, RawScene, RawSelector, RawShape, RawSimulation, RawSprings, RawStrain, RawWind,
    DEFAULT_SELF_FRICTION, DEFAULT_THICKNESS,
};
use super::selector::{Edge, Selector};
use super::{Scene, SceneError, SceneForce, ScenePin};
use crate::mesh::TriMesh;
use crate::problems::Problems;
use crate::sim::{
    CgSettings, Collider, GridShape, Material, Membrane, Moduli, Orientation, PinPath, Profile, SelfContact, Shape,
    SimParams, SpringCoeffs, SpringKind, StabilityCheck, StiffnessAdjustment, StrainLimit, Wind,
};
use std::path::{Path, PathBuf};

/// A `[contact]` table (a scene's, or a daemon instance's `contact` at
/// `path`): self-contact when `self = true`, else None; a thickness or
/// friction without `self = true` is refused rather than ignored.
pub fn self_contact(r: &RawContact, path: &str, p: &mut Problems) -> Option<SelfContact> {
    let thickness = r.thickness.unwrap_or(DEFAULT_THICKNESS);
    let friction = r.friction.unwrap_or(DEFAULT_SELF_FRICTION);
    p.positive(&format!("{path}.thickness"), thickness);
    p.non_negative(&format!("{path}.friction"), friction);
    if !r.self_contact {
        if r.thickness.is_some() || r.friction.is_some() {
            p.push(format!(
                "{path}: thickness and friction describe self-contact; add `self = true`"
            ));
        }
        return None;
    }
    Some(SelfContact { thickness, friction })
}

impl Scene {
    /// Validate a parsed scene, listing every problem with its path.
    pub fn validate(raw: RawScene, origin: &str) -> Result<Scene, SceneError> {
        let mut p = Problems::default();
        let c = &raw.cloth;
        let mesh = p.cloth(c, origin);
        let grid = reference_shape(c);
        let reference = match &mesh {
            Some((m, _)) => Reference::Mesh(m),
            None => Reference::Grid(grid),
        };
        let bending = p.bending(&raw, mesh.as_ref().map(|(m, _)| m));
        let (material, membrane) = match &mesh {
            Some(_) => {
                let membrane = p.mesh_membrane(&raw);
                (
                    Material::isotropic([SpringCoeffs { k: 0.0, c: 0.0 }; 3]),
                    Some(membrane),
                )
            }
            None => (p.material(&raw, grid), None),
        };
        let s = &raw.simulation;
        let cg = p.simulation(s);
        let (stiffness_adjustment, strain_limit) = p.strain(&raw.strain);
        let pins = p.pins(&raw.pins, &reference);
        let forces = p.forces(&raw.forces, &reference);
        let wind = raw.wind.as_ref().map(|w| p.wind(w));
        let colliders = p.colliders(&raw.colliders);
        let self_contact = p.contact(&raw.contact);

        if let Err(problems) = p.finish() {
            return Err(SceneError::Invalid {
                origin: origin.to_string(),
                problems,
            });
        }
        let mut scene = Scene {
            origin: origin.to_string(),
            name: raw.name,
            description: raw.description,
            width: grid.width,
            height: grid.height,
            nx: grid.nx,
            ny: grid.ny,
            orientation: match c.orientation {
                Some(RawOrientation::Vertical) => Orientation::Vertical,
                _ => Orientation::Horizontal,
            },
            areal_density: c.areal_density,
            mass: c.mass,
            params: SimParams {
                dt: s.dt,
                integrator: s.integrator,
                material,
                gravity: s.gravity,
                drag: s.drag,
                stiffness_adjustment,
                strain_limit,
                cg,
                self_contact,
            },
            duration: s.duration,
            stability: if s.force_unstable {
                StabilityCheck::Force
            } else {
                StabilityCheck::Enforce
            },
            source_hash: 0,
            mesh: None,
            pins,
            forces,
            wind,
            colliders,
        };
        if let (Some((reference, (file, hash))), Some(membrane)) = (mesh, membrane) {
            scene.attach_mesh(reference, file, hash, membrane, bending);
        }
        Ok(scene)
    }
}

/// What selectors are validated against: the scene's own grid, or its mesh.
enum Reference<'a> {
    Grid(GridShape),
    Mesh(&'a TriMesh),
}

/// The grid that `nodes = [[i, j], …]` selectors index: the scene's own
/// resolution, at least 2 × 2 so a too-small `cloth.nx`/`ny` (already a
/// problem of its own) does not also break every node list.
/// Largest stiffness (N/m) or damping (N·s/m) a scene may give: far beyond
/// any fabric (the stiffest shipped scene is 2e3 N/m), far below overflow.
const MAX_COEFFICIENT: f64 = 1e12;

fn reference_shape(c: &RawCloth) -> GridShape {
    GridShape {
        nx: c.nx.unwrap_or(2).max(2),
        ny: c.ny.unwrap_or(2).max(2),
        width: c.width.unwrap_or(1.0),
        height: c.height.unwrap_or(1.0),
    }
}

// Sections of the file, in the order `Scene::validate` checks them.
impl Problems {
    /// `[cloth]`: a grid's size and reference resolution, or a mesh read
    /// from its file (with the file's path and a hash of its bytes); then
    /// the areal density.
    fn cloth(&mut self, c: &RawCloth, origin: &str) -> Option<(TriMesh, (PathBuf, u64))> {
        let mesh = match &c.mesh {
            Some(file) => {
                for (field, given) in [
                    ("width", c.width.is_some()),
                    ("height", c.height.is_some()),
                    ("nx", c.nx.is_some()),
                    ("ny", c.ny.is_some()),
                    ("orientation", c.orientation.is_some()),
                ] {
                    if given {
                        self.push(format!(
                            "cloth.{field}: a mesh cloth has no {field} (its file gives its shape and vertices)"
                        ));
                    }
                }
                self.mesh_file(file, origin)
            }
            None => {
                self.grid_cloth(c);
                None
            }
        };
        self.positive("cloth.areal_density", c.areal_density);
        mesh
    }

    /// `cloth.mesh`: the file, relative to the scene's directory, read and
    /// validated as a cloth mesh.
    fn mesh_file(&mut self, file: &str, origin: &str) -> Option<(TriMesh, (PathBuf, u64))> {
        let base = Path::new(origin).parent().unwrap_or(Path::new(""));
        let path = base.join(file);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) => {
                self.push(format!("cloth.mesh: cannot read {}: {e}", path.display()));
                return None;
            }
        };
        match crate::mesh::load(&path) {
            Ok(m) => Some((m, (path, crate::hash::fnv1a64(&bytes)))),
            Err(e) => {
                self.push(format!("cloth.mesh: {e}"));
                None
            }
        }
    }

    /// A grid cloth's `[cloth]`: size and reference resolution.
    fn grid_cloth(&mut self, c: &RawCloth) {
        for (field, given) in [
            ("width", c.width.is_some()),
            ("height", c.height.is_some()),
            ("nx", c.nx.is_some()),
            ("ny", c.ny.is_some()),
        ] {
            if !given {
                self.push(format!(
                    "cloth.{field}: missing; a grid cloth needs width, height, nx and ny (or give a mesh file as cloth.mesh)"
                ));
            }
        }
        let (Some(width), Some(height)) = (c.width, c.height) else {
            return;
        };
        self.positive("cloth.width", width);
        self.positive("cloth.height", height);
        // Springs at other levels are made from squared cell sizes: a size
        // whose square underflows or overflows gives NaN springs.
        for (path, size) in [("cloth.width", width), ("cloth.height", height)] {
            if size.is_finite() && size > 0.0 && !(1e-4..=1e4).contains(&size) {
                self.push(format!("{path}: must be within 1e-4 and 1e4 m, got {size} m"));
            }
        }
        // Springs are made from the material at every level's spacing, scaled
        // by the cells' aspect ratio (squared for the diagonals): keep it sane.
        let aspect = width / height;
        if width > 0.0 && height > 0.0 && !(1e-3..=1e3).contains(&aspect) {
            self.push(format!(
                "cloth.width: width / height must be within 1:1000 and 1000:1, got {width} m wide and {height} m high"
            ));
        }
        if let (Some(nx), Some(ny)) = (c.nx, c.ny) {
            self.grid_size("cloth", nx, ny);
        }
    }

    /// `material.bending_rigidity` and `bending_damping`: a mesh cloth's
    /// bending stencils' D and C (None without them). Only for a mesh, whose
    /// rest shape is flat, and without bend springs' shares.
    fn bending(&mut self, raw: &RawScene, mesh: Option<&TriMesh>) -> Option<SpringCoeffs> {
        let m = raw.material.as_ref()?;
        let Some(d) = m.bending_rigidity else {
            if m.bending_damping.is_some() {
                self.push("material.bending_damping: given without bending_rigidity".into());
            }
            return None;
        };
        self.coefficient("material.bending_rigidity", d, "N·m");
        let Some(mesh) = mesh else {
            self.push(
                "material.bending_rigidity: only a mesh cloth bends with stencils; a grid's bend springs \
                 are given as bend_u, bend_v"
                    .into(),
            );
            return None;
        };
        for (name, share) in [("bend_u", m.stiffness.bend_u), ("bend_v", m.stiffness.bend_v)] {
            if share != 0.0 {
                self.push(format!(
                    "material.stiffness.{name}: a cloth with bending_rigidity has no bend springs; \
                     give {name} = 0 (got {share})"
                ));
            }
        }
        let c = match (m.bending_damping, m.damping_time) {
            (Some(c), _) => {
                self.coefficient("material.bending_damping", c, "N·m·s");
                c
            }
            (None, Some(t)) => t * d,
            (None, None) => {
                self.push(
                    "material.bending_damping: needed with damping moduli (N·m·s); with damping_time it is τ·D".into(),
                );
                0.0
            }
        };
        if let Err(e) = crate::mesh::bending_stencils(mesh, &[]) {
            self.push(format!("material.bending_rigidity: {e}"));
        }
        Some(SpringCoeffs { k: d, c })
    }

    /// A mesh cloth's material: `[material]` only (per-spring `[springs]`
    /// describe a grid's cells).
    fn mesh_membrane(&mut self, raw: &RawScene) -> Membrane {
        match (&raw.springs, &raw.material) {
            (None, Some(m)) => self.membrane(m),
            (Some(_), _) => {
                self.push(
                    "springs: a mesh cloth's material is given as [material] (membrane moduli); \
                     [springs] are per-spring coefficients of a grid's cells"
                        .into(),
                );
                self.membrane_or_zero(raw)
            }
            (None, None) => {
                self.push("material: missing; a mesh cloth needs [material] (membrane moduli)".into());
                self.membrane_or_zero(raw)
            }
        }
    }

    fn membrane_or_zero(&mut self, raw: &RawScene) -> Membrane {
        match &raw.material {
            Some(m) => self.membrane(m),
            None => {
                let zero = Moduli {
                    stretch_u: 0.0,
                    stretch_v: 0.0,
                    shear: 0.0,
                    bend_u: 0.0,
                    bend_v: 0.0,
                };
                Membrane {
                    stiffness: zero,
                    damping: zero,
                }
            }
        }
    }

    /// `[springs]` (K and C of each kind at the reference resolution) or
    /// `[material]` (membrane moduli, made into springs at `shape`).
    fn material(&mut self, raw: &RawScene, shape: GridShape) -> Material {
        match (&raw.springs, &raw.material) {
            (Some(s), None) => self.springs(s),
            (None, Some(m)) => self.membrane(m).springs(shape.hx(), shape.hy()),
            (Some(_), Some(_)) => {
                self.push("springs, material: give the cloth's material once, as [springs] or as [material]".into());
                Material::isotropic([SpringCoeffs { k: 0.0, c: 0.0 }; 3])
            }
            (None, None) => {
                self.push(
                    "springs: missing; give [springs] (per-spring K and C) or [material] (membrane moduli)".into(),
                );
                Material::isotropic([SpringCoeffs { k: 0.0, c: 0.0 }; 3])
            }
        }
    }

    /// `[material]`: every modulus finite and ≥ 0, bend shares within the
    /// stretch, one damping form.
    fn membrane(&mut self, m: &RawMaterial) -> Membrane {
        let mut moduli = |at: &str, unit: &str, r: &RawModuli| {
            for (name, v) in [
                ("stretch_u", r.stretch_u),
                ("stretch_v", r.stretch_v),
                ("shear", r.shear),
                ("bend_u", r.bend_u),
                ("bend_v", r.bend_v),
            ] {
                self.coefficient(&format!("material.{at}.{name}"), v, unit);
            }
            for (bend, stretch, axis) in [(r.bend_u, r.stretch_u, "u"), (r.bend_v, r.stretch_v, "v")] {
                if bend > stretch {
                    self.push(format!(
                        "material.{at}.bend_{axis}: the bend springs' share of the stretch cannot exceed \
                         stretch_{axis} = {stretch}, got {bend}"
                    ));
                }
            }
            Moduli {
                stretch_u: r.stretch_u,
                stretch_v: r.stretch_v,
                shear: r.shear,
                bend_u: r.bend_u,
                bend_v: r.bend_v,
            }
        };
        let stiffness = moduli("stiffness", "N/m", &m.stiffness);
        let damping = match (&m.damping, m.damping_time) {
            (Some(d), None) => moduli("damping", "N·s/m", d),
            (None, Some(t)) => {
                self.in_closed("material.damping_time", t, 0.0, 1.0, "s");
                let s = stiffness;
                Moduli {
                    stretch_u: t * s.stretch_u,
                    stretch_v: t * s.stretch_v,
                    shear: t * s.shear,
                    bend_u: t * s.bend_u,
                    bend_v: t * s.bend_v,
                }
            }
            _ => {
                self.push("material: give damping once, as damping = { … } (N·s/m) or damping_time (s)".into());
                stiffness
            }
        };
        Membrane { stiffness, damping }
    }

    /// A stiffness or damping value: finite, ≥ 0, and at most
    /// [`MAX_COEFFICIENT`], so that the springs made from it at any other
    /// spacing (scaled by cell aspect ratios up to 4095) stay finite.
    fn coefficient(&mut self, path: &str, x: f64, unit: &str) {
        self.non_negative(path, x);
        if x.is_finite() && x > MAX_COEFFICIENT {
            self.push(format!(
                "{path}: must be at most {MAX_COEFFICIENT:e} {unit} (every level's springs are made from it), got {x}"
            ));
        }
    }

    /// `[springs]`: K and C of each kind, structural, shear, bend.
    fn springs(&mut self, r: &RawSprings) -> Material {
        let mut coeffs = |name: &str, r: RawCoeffs| {
            self.coefficient(&format!("springs.{name}.k"), r.k, "N/m");
            self.coefficient(&format!("springs.{name}.c"), r.c, "N·s/m");
            SpringCoeffs { k: r.k, c: r.c }
        };
        Material::isotropic([
            coeffs("structural", r.structural),
            coeffs("shear", r.shear),
            coeffs("bend", r.bend),
        ])
    }

    /// `[simulation]`: dt against the run length, gravity, drag and the CG
    /// settings (the only derived value; the rest is used as given).
    fn simulation(&mut self, s: &RawSimulation) -> CgSettings {
        self.positive("simulation.dt", s.dt);
        self.positive("simulation.duration", s.duration);
        if s.dt.is_finite() && s.duration.is_finite() && s.dt > s.duration {
            self.push(format!(
                "simulation.dt: {} s is longer than the whole run ({} s)",
                s.dt, s.duration
            ));
        }
        for (i, g) in s.gravity.iter().enumerate() {
            self.finite(&format!("simulation.gravity[{i}]"), *g);
        }
        self.non_negative("simulation.drag", s.drag);
        let mut cg = CgSettings::default();
        if let Some(t) = s.cg_tolerance {
            self.positive("simulation.cg_tolerance", t);
            cg.tolerance = t;
        }
        if let Some(m) = s.cg_max_iterations {
            if m == 0 {
                self.push("simulation.cg_max_iterations: must be at least 1".into());
            }
            cg.max_iterations = m;
        }
        cg
    }

    /// `[strain]`: the stiffness adjustment, then the strain limit.
    fn strain(&mut self, r: &RawStrain) -> (Option<StiffnessAdjustment>, Option<StrainLimit>) {
        let stiffness_adjustment = r.stiffness_adjustment.as_ref().map(|a| {
            self.non_negative("strain.stiffness_adjustment.allowed", a.allowed);
            StiffnessAdjustment { allowed: a.allowed }
        });
        let strain_limit = r.limit.as_ref().map(|l| self.strain_limit(l));
        (stiffness_adjustment, strain_limit)
    }

    /// `[contact]` (see [`self_contact`]).
    fn contact(&mut self, r: &RawContact) -> Option<SelfContact> {
        self_contact(r, "contact", self)
    }

    /// `[strain.limit]`, with [`StrainLimit::default`] for what is not given.
    fn strain_limit(&mut self, l: &RawLimit) -> StrainLimit {
        let mut out = StrainLimit {
            max_strain: l.max_strain,
            ..StrainLimit::default()
        };
        self.non_negative("strain.limit.max_strain", l.max_strain);
        if let Some(t) = l.tolerance {
            self.non_negative("strain.limit.tolerance", t);
            out.tolerance = t;
        }
        if let Some(m) = l.max_iterations {
            if m == 0 {
                self.push("strain.limit.max_iterations: must be at least 1 (0 sweeps never limit)".into());
            }
            out.max_iterations = m;
        }
        if let Some(kinds) = &l.kinds {
            if kinds.is_empty() {
                self.push("strain.limit.kinds: an empty list limits no spring; remove [strain.limit] instead".into());
            }
            out.kinds = [false; 3];
            for (i, k) in kinds.iter().enumerate() {
                match SpringKind::ALL.iter().find(|s| s.name() == k) {
                    Some(s) => out.kinds[s.index()] = true,
                    None => self.push(format!(
                        "strain.limit.kinds[{i}]: unknown spring kind {k:?} (expected structural, shear or bend)"
                    )),
                }
            }
        }
        out
    }

    /// `[[pins]]`: each pin's node set, then its path.
    fn pins(&mut self, pins: &[RawPin], reference: &Reference) -> Vec<ScenePin> {
        pins.iter()
            .enumerate()
            .map(|(i, pin)| {
                let path = format!("pins[{i}]");
                let sel = self.selector(&format!("{path}.nodes"), &pin.nodes, reference);
                let pp = self.pin_path(&format!("{path}.path"), pin.path);
                (sel, pp, path)
            })
            .collect()
    }

    /// `[[forces]]`: each force's node set, total, then profile.
    fn forces(&mut self, forces: &[RawForce], reference: &Reference) -> Vec<SceneForce> {
        forces
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let path = format!("forces[{i}]");
                let sel = self.selector(&format!("{path}.nodes"), &f.nodes, reference);
                for (c, x) in f.total.iter().enumerate() {
                    self.finite(&format!("{path}.total[{c}]"), *x);
                }
                let prof = self.profile(&format!("{path}.profile"), f.profile);
                (sel, f.total, prof, path)
            })
            .collect()
    }

    /// `[wind]`: velocity, air density, drag coefficient, then profile.
    fn wind(&mut self, w: &RawWind) -> Wind {
        for (c, x) in w.velocity.iter().enumerate() {
            self.finite(&format!("wind.velocity[{c}]"), *x);
        }
        self.non_negative("wind.air_density", w.air_density);
        self.non_negative("wind.drag_coefficient", w.drag_coefficient);
        Wind {
            velocity: w.velocity,
            profile: self.profile("wind.profile", w.profile),
            air_density: w.air_density,
            drag_coefficient: w.drag_coefficient,
        }
    }
}

impl Problems {
    /// `[[colliders]]`: each body's shape and the fields it needs (and no
    /// other), then friction, clearance and path.
    fn colliders(&mut self, bodies: &[RawCollider]) -> Vec<Collider> {
        bodies
            .iter()
            .enumerate()
            .map(|(i, b)| self.collider(&format!("colliders[{i}]"), b))
            .collect()
    }

    fn collider(&mut self, path: &str, b: &RawCollider) -> Collider {
        let kind = match b.shape {
            RawShape::Plane => "plane",
            RawShape::Sphere => "sphere",
            RawShape::Capsule => "capsule",
            RawShape::Box => "box",
            RawShape::Cylinder => "cylinder",
        };
        let needs: &[&str] = match b.shape {
            RawShape::Plane => &["point", "normal"],
            RawShape::Sphere => &["center", "radius"],
            RawShape::Capsule => &["ends", "radius"],
            RawShape::Box => &["center", "size"],
            RawShape::Cylinder => &["center", "radius", "height"],
        };
        let given = [
            ("point", b.point.is_some()),
            ("normal", b.normal.is_some()),
            ("center", b.center.is_some()),
            ("radius", b.radius.is_some()),
            ("ends", b.ends.is_some()),
            ("size", b.size.is_some()),
            ("height", b.height.is_some()),
        ];
        for (field, present) in given {
            match (needs.contains(&field), present) {
                (true, false) => self.push(format!("{path}.{field}: a {kind} needs it")),
                (false, true) => self.push(format!("{path}.{field}: a {kind} has no {field}")),
                _ => {}
            }
        }
        let mut vector = |field: &str, v: Option<[f64; 3]>| {
            let v = v.unwrap_or_default();
            for (c, x) in v.iter().enumerate() {
                self.finite(&format!("{path}.{field}[{c}]"), *x);
            }
            v
        };
        let (position, shape) = match b.shape {
            RawShape::Plane => {
                let point = vector("point", b.point);
                let normal = vector("normal", b.normal);
                let len = crate::sim::vec3::norm(normal);
                if b.normal.is_some() && !(len > 0.0) {
                    self.push(format!("{path}.normal: must not be zero"));
                }
                let normal = if len > 0.0 {
                    normal.map(|x| x / len)
                } else {
                    [0.0, 1.0, 0.0]
                };
                (point, Shape::Plane { normal })
            }
            RawShape::Sphere => (
                vector("center", b.center),
                Shape::Sphere {
                    radius: b.radius.unwrap_or(1.0),
                },
            ),
            RawShape::Capsule => {
                let [a, e] = b.ends.unwrap_or_default();
                let (a, e) = (vector("ends[0]", Some(a)), vector("ends[1]", Some(e)));
                (
                    [0, 1, 2].map(|c| 0.5 * (a[c] + e[c])),
                    Shape::Capsule {
                        half_axis: [0, 1, 2].map(|c| 0.5 * (e[c] - a[c])),
                        radius: b.radius.unwrap_or(1.0),
                    },
                )
            }
            RawShape::Box => {
                let center = vector("center", b.center);
                let size = b.size.unwrap_or([1.0; 3]);
                for (c, x) in size.iter().enumerate() {
                    if b.size.is_some() {
                        self.positive(&format!("{path}.size[{c}]"), *x);
                    }
                }
                (
                    center,
                    Shape::Cuboid {
                        half_extents: size.map(|x| 0.5 * x),
                    },
                )
            }
            RawShape::Cylinder => (
                vector("center", b.center),
                Shape::Cylinder {
                    radius: b.radius.unwrap_or(1.0),
                    half_height: 0.5 * b.height.unwrap_or(1.0),
                },
            ),
        };
        if let Some(h) = b.height {
            self.positive(&format!("{path}.height"), h);
        }
        if let Some(r) = b.radius {
            self.positive(&format!("{path}.radius"), r);
        }
        self.non_negative(&format!("{path}.friction"), b.friction);
        self.non_negative(&format!("{path}.clearance"), b.clearance);
        let motion = self.pin_path(&format!("{path}.path"), b.path);
        Collider {
            shape,
            position,
            path: motion,
            friction: b.friction,
            clearance: b.clearance,
        }
    }
}

// Checks of the nested forms (profiles, pin paths, selectors) the
// sections share; single values are checked by `Problems` itself.
impl Problems {
    /// Nodes per side in 2..=4096; also checks a resolution to build at.
    pub(super) fn grid_size(&mut self, path: &str, nx: usize, ny: usize) {
        for (name, n) in [("nx", nx), ("ny", ny)] {
            if n < 2 {
                self.push(format!("{path}.{name}: {n} nodes per side is below the minimum of 2"));
            } else if n > 4096 {
                self.push(format!(
                    "{path}.{name}: {n} nodes per side is above the maximum of 4096"
                ));
            }
        }
    }
    /// A time profile: every time finite, a ramp's end after its start.
    fn profile(&mut self, path: &str, r: RawProfile) -> Profile {
        match r {
            RawProfile::Constant => Profile::Constant,
            RawProfile::Ramp { start, end } => {
                self.finite(&format!("{path}.start"), start);
                // An infinite end would hold the profile at 0 for ever.
                if !end.is_finite() {
                    self.finite(&format!("{path}.end"), end);
                } else if !(end > start) {
                    self.push(format!("{path}.end: must be after start ({start}), got {end}"));
                }
                Profile::Ramp { start, end }
            }
            RawProfile::Pulse { start, duration } => {
                self.finite(&format!("{path}.start"), start);
                self.positive(&format!("{path}.duration"), duration);
                Profile::Pulse { start, duration }
            }
            RawProfile::Sine {
                frequency,
                phase,
                amplitude,
                offset,
            } => {
                self.non_negative(&format!("{path}.frequency"), frequency);
                self.finite(&format!("{path}.phase"), phase);
                self.finite(&format!("{path}.amplitude"), amplitude);
                self.finite(&format!("{path}.offset"), offset);
                Profile::Sine {
                    frequency,
                    phase,
                    amplitude,
                    offset,
                }
            }
        }
    }
    /// A pin path: finite components, a linear path's end not before its start.
    fn pin_path(&mut self, path: &str, r: RawPinPath) -> PinPath {
        match r {
            RawPinPath::Fixed => PinPath::Fixed,
            RawPinPath::Linear { velocity, start, end } => {
                for (c, x) in velocity.iter().enumerate() {
                    self.finite(&format!("{path}.velocity[{c}]"), *x);
                }
                self.finite(&format!("{path}.start"), start);
                if !(end >= start) {
                    self.push(format!("{path}.end: must not be before start ({start}), got {end}"));
                }
                PinPath::Linear { velocity, start, end }
            }
            RawPinPath::Sine { amplitude, frequency } => {
                for (c, x) in amplitude.iter().enumerate() {
                    self.finite(&format!("{path}.amplitude[{c}]"), *x);
                }
                self.non_negative(&format!("{path}.frequency"), frequency);
                PinPath::Sine { amplitude, frequency }
            }
        }
    }
    /// A node set given in exactly one way, with known edge and corner names
    /// and node indices inside the `reference` grid. After a problem it
    /// stands in `Selector::All`, which is never used: the scene is refused.
    fn selector(&mut self, path: &str, r: &RawSelector, reference: &Reference) -> Selector {
        let given = [
            r.edge.is_some(),
            r.corner.is_some(),
            r.region.is_some(),
            r.ellipse.is_some(),
            r.nodes.is_some(),
            r.all.is_some(),
            r.vertices.is_some(),
            r.group.is_some(),
        ];
        if given.iter().filter(|g| **g).count() != 1 {
            self.push(format!(
                "{path}: give exactly one of edge, corner, region, ellipse, nodes, all, vertices, group"
            ));
            return Selector::All;
        }
        let reference = match reference {
            Reference::Grid(shape) => {
                for (field, given) in [("vertices", r.vertices.is_some()), ("group", r.group.is_some())] {
                    if given {
                        self.push(format!(
                            "{path}.{field}: a grid cloth has no {field}; use edge, corner, region, nodes or all"
                        ));
                        return Selector::All;
                    }
                }
                shape
            }
            Reference::Mesh(mesh) => return self.mesh_selector(path, r, mesh),
        };
        let edge = |s: &str| match s {
            "top" => Some(Edge::Top),
            "bottom" => Some(Edge::Bottom),
            "left" => Some(Edge::Left),
            "right" => Some(Edge::Right),
            _ => None,
        };
        if let Some(e) = &r.edge {
            return match edge(e) {
                Some(e) => Selector::Edge(e),
                None => {
                    self.push(format!(
                        "{path}.edge: unknown edge {e:?} (expected top, bottom, left or right)"
                    ));
                    Selector::All
                }
            };
        }
        if let Some(c) = &r.corner {
            let parts: Vec<_> = c.split('-').collect();
            return match (
                parts.as_slice(),
                parts.first().and_then(|a| edge(a)),
                parts.get(1).and_then(|b| edge(b)),
            ) {
                ([_, _], Some(a @ (Edge::Top | Edge::Bottom)), Some(b @ (Edge::Left | Edge::Right))) => {
                    Selector::Corner(a, b)
                }
                _ => {
                    self.push(format!(
                        "{path}.corner: unknown corner {c:?} (expected top-left, top-right, bottom-left or bottom-right)"
                    ));
                    Selector::All
                }
            };
        }
        if let Some(reg) = &r.region {
            self.interval(&format!("{path}.region.u"), reg.u);
            self.interval(&format!("{path}.region.v"), reg.v);
            return Selector::Region { u: reg.u, v: reg.v };
        }
        if let Some(e) = &r.ellipse {
            for c in 0..2 {
                self.finite(&format!("{path}.ellipse.center[{c}]"), e.center[c]);
                self.positive(&format!("{path}.ellipse.radii[{c}]"), e.radii[c]);
            }
            return Selector::Ellipse {
                center: e.center,
                radii: e.radii,
            };
        }
        if let Some(nodes) = &r.nodes {
            if nodes.is_empty() {
                self.push(format!("{path}.nodes: empty list"));
            }
            let mut pts = Vec::new();
            for (k, &[i, j]) in nodes.iter().enumerate() {
                if i >= reference.nx || j >= reference.ny {
                    self.push(format!(
                        "{path}.nodes[{k}]: [{i}, {j}] is outside the {}×{} grid",
                        reference.nx, reference.ny
                    ));
                } else {
                    pts.push(reference.uv(i, j));
                }
            }
            return Selector::Points(pts);
        }
        if r.all == Some(false) {
            self.push(format!(
                "{path}.all: false selects nothing; remove the pin/force instead"
            ));
        }
        Selector::All
    }

    /// A selector on a mesh cloth: vertices by index (in range) or by group
    /// (one the file has), sides, corners and regions of the material
    /// square, or all; `nodes = [[i, j]]` index a grid and are refused.
    fn mesh_selector(&mut self, path: &str, r: &RawSelector, mesh: &TriMesh) -> Selector {
        if r.nodes.is_some() {
            self.push(format!(
                "{path}.nodes: [i, j] index a grid; on a mesh cloth use vertices = [..], group, region, edge or corner"
            ));
            return Selector::All;
        }
        if let Some(ids) = &r.vertices {
            if ids.is_empty() {
                self.push(format!("{path}.vertices: empty list"));
            }
            let n = mesh.vertices();
            for (k, &i) in ids.iter().enumerate() {
                if i as usize >= n {
                    self.push(format!(
                        "{path}.vertices[{k}]: vertex {i} is outside the mesh's {n} vertices"
                    ));
                }
            }
            let mut ids = ids.clone();
            ids.sort_unstable();
            ids.dedup();
            return Selector::Vertices(ids);
        }
        if let Some(name) = &r.group {
            return match mesh.groups.get(name) {
                Some(ids) if !ids.is_empty() => Selector::Vertices(ids.clone()),
                _ => {
                    let known: Vec<&str> = mesh.groups.keys().map(String::as_str).collect();
                    self.push(format!(
                        "{path}.group: the mesh has no group {name:?} with vertices (its groups: {})",
                        if known.is_empty() {
                            "none".to_string()
                        } else {
                            known.join(", ")
                        }
                    ));
                    Selector::All
                }
            };
        }
        let grid = GridShape {
            nx: 2,
            ny: 2,
            width: 1.0,
            height: 1.0,
        };
        let plain = RawSelector {
            vertices: None,
            group: None,
            ..r.clone()
        };
        self.selector(path, &plain, &Reference::Grid(grid))
    }
}
