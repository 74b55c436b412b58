//! Plain-value parameters of a simulation: spring coefficients per type, the
//! integrator, and super-elasticity control. All `Copy`, all SI units.

use std::fmt;

/// The three spring types of a mass-spring cloth (Sung 2018 §3, Provot 1995).
///
/// The discriminant is the index into per-kind arrays such as
/// [`crate::sim::StepReport::max_strain`] and [`StrainLimit::kinds`];
/// coefficients are per [`SpringClass`] (a kind and its grid direction).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SpringKind {
    /// 4-neighbour springs along rows and columns: resist stretching.
    Structural = 0,
    /// Diagonal springs: resist in-plane shearing.
    Shear = 1,
    /// Springs two apart along rows and columns: resist bending.
    Bend = 2,
}

impl SpringKind {
    /// All kinds, in index order.
    pub const ALL: [SpringKind; 3] = [SpringKind::Structural, SpringKind::Shear, SpringKind::Bend];

    /// Index into per-type arrays.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Lower-case name used in config files, CSV headers and logs.
    pub const fn name(self) -> &'static str {
        match self {
            SpringKind::Structural => "structural",
            SpringKind::Shear => "shear",
            SpringKind::Bend => "bend",
        }
    }
}

impl fmt::Display for SpringKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The five coefficient slots of a [`Material`]: each [`SpringKind`] and, for
/// the kinds that lie along a grid direction, that direction.
///
/// On a grid whose cells are not square a spring along u and one along v are
/// different springs (lengths hx and hy), so a resolution-independent material
/// ([`super::Membrane`]) gives them different K and C. Shear springs follow the
/// diagonal, which is the same in both diagonal directions. Springs with no
/// grid direction (point-sampled surfaces) use the `U` slots; their materials
/// are isotropic (u = v).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SpringClass {
    /// Structural springs along u (rows, spacing hx).
    StructuralU = 0,
    /// Structural springs along v (columns, spacing hy).
    StructuralV = 1,
    /// Shear springs (both diagonals).
    Shear = 2,
    /// Bend springs along u (two cells, 2·hx).
    BendU = 3,
    /// Bend springs along v (two cells, 2·hy).
    BendV = 4,
}

impl SpringClass {
    /// All classes, in index order.
    pub const ALL: [SpringClass; 5] = [
        SpringClass::StructuralU,
        SpringClass::StructuralV,
        SpringClass::Shear,
        SpringClass::BendU,
        SpringClass::BendV,
    ];

    /// Index into [`Material::springs`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The spring kind.
    pub const fn kind(self) -> SpringKind {
        match self {
            SpringClass::StructuralU | SpringClass::StructuralV => SpringKind::Structural,
            SpringClass::Shear => SpringKind::Shear,
            SpringClass::BendU | SpringClass::BendV => SpringKind::Bend,
        }
    }

    /// The class of `kind` along u (shear: the shear class).
    pub const fn along_u(kind: SpringKind) -> SpringClass {
        match kind {
            SpringKind::Structural => SpringClass::StructuralU,
            SpringKind::Shear => SpringClass::Shear,
            SpringKind::Bend => SpringClass::BendU,
        }
    }

    /// The class of `kind` along v (shear: the shear class).
    pub const fn along_v(kind: SpringKind) -> SpringClass {
        match kind {
            SpringKind::Structural => SpringClass::StructuralV,
            SpringKind::Shear => SpringClass::Shear,
            SpringKind::Bend => SpringClass::BendV,
        }
    }

    /// Lower-case name used in files, CSV headers and logs.
    pub const fn name(self) -> &'static str {
        match self {
            SpringClass::StructuralU => "structural_u",
            SpringClass::StructuralV => "structural_v",
            SpringClass::Shear => "shear",
            SpringClass::BendU => "bend_u",
            SpringClass::BendV => "bend_v",
        }
    }
}

impl fmt::Display for SpringClass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Stiffness and damping of one spring type (Sung 2018 eq. 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpringCoeffs {
    /// Stiffness K in N/m, ≥ 0.
    pub k: f64,
    /// Damping C of the relative velocity along the spring, in N·s/m, ≥ 0.
    pub c: f64,
}

/// Per-spring coefficients: one [`SpringCoeffs`] per [`SpringClass`].
///
/// These are *per-spring* coefficients, as in the paper: the same values on a
/// coarser mesh, or on cells of another aspect ratio, give a different cloth.
/// [`super::Membrane`] is the resolution-independent material they are made
/// from at each level's spacing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Indexed by [`SpringClass::index`].
    pub springs: [SpringCoeffs; 5],
}

impl Material {
    /// The same coefficients along u and v for each kind, indexed by
    /// [`SpringKind::index`].
    pub const fn isotropic(kinds: [SpringCoeffs; 3]) -> Material {
        let [s, h, b] = kinds;
        Material {
            springs: [s, s, h, b, b],
        }
    }

    /// Coefficients of one class.
    pub fn get(&self, class: SpringClass) -> SpringCoeffs {
        self.springs[class.index()]
    }

    /// Coefficients of one kind along u (the kind's only value when the
    /// material is isotropic).
    pub fn of_kind(&self, kind: SpringKind) -> SpringCoeffs {
        self.get(SpringClass::along_u(kind))
    }

    /// True when u and v coefficients are equal for every kind.
    pub fn is_isotropic(&self) -> bool {
        let s = &self.springs;
        s[0] == s[1] && s[3] == s[4]
    }

    /// This material with every class of `kind` (along u and v) having its
    /// stiffness times `k` and its damping times `c`; on a mesh the bend
    /// kind is the bending rigidity and its damping.
    #[must_use]
    pub fn kind_scaled(&self, kind: SpringKind, k: f64, c: f64) -> Material {
        let mut m = *self;
        for class in SpringClass::ALL.into_iter().filter(|class| class.kind() == kind) {
            let s = &mut m.springs[class.index()];
            s.k *= k;
            s.c *= c;
        }
        m
    }
}

/// Time integration scheme.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Integrator {
    /// Forward Euler: x += dt·v, v += dt·a(x, v). First order; gains energy
    /// without damping at any dt.
    ExplicitEuler,
    /// Symplectic (semi-implicit) Euler: v += dt·a(x, v), then x += dt·v.
    /// First order; energy bounded while ω·dt < 2.
    SymplecticEuler,
    /// Classic fourth-order Runge–Kutta on (x, v) (Sung 2018 eq. 2).
    Rk4,
    /// Backward Euler linearised once per step and solved by preconditioned
    /// conjugate gradients (Baraff & Witkin 1998). Stable at any dt; adds
    /// numerical damping.
    ImplicitEuler,
    /// Extended position-based dynamics with small steps (Macklin et al.
    /// 2016, 2019): springs as compliant constraints, one Gauss–Seidel sweep
    /// per step. Backward Euler in the positions: stable at any dt, with its
    /// numerical damping.
    Xpbd,
}

impl Integrator {
    /// All integrators, in a fixed order for sweeps and tables.
    pub const ALL: [Integrator; 5] = [
        Integrator::ExplicitEuler,
        Integrator::SymplecticEuler,
        Integrator::Rk4,
        Integrator::ImplicitEuler,
        Integrator::Xpbd,
    ];

    /// Name used in config files, CSV and the CLI.
    pub const fn name(self) -> &'static str {
        match self {
            Integrator::ExplicitEuler => "explicit_euler",
            Integrator::SymplecticEuler => "symplectic_euler",
            Integrator::Rk4 => "rk4",
            Integrator::ImplicitEuler => "implicit_euler",
            Integrator::Xpbd => "xpbd",
        }
    }

    /// Parse a [`Integrator::name`] (see [`crate::names`]).
    pub fn from_name(name: &str) -> Option<Integrator> {
        crate::names::parse(name).ok()
    }

    /// True for the integrators stable at any dt (backward Euler and XPBD).
    pub const fn unconditionally_stable(self) -> bool {
        matches!(self, Integrator::ImplicitEuler | Integrator::Xpbd)
    }

    /// Force evaluations per step (cost model for benchmarks and pacing;
    /// an XPBD sweep counts as one).
    pub const fn force_evaluations(self) -> u32 {
        match self {
            Integrator::Rk4 => 4,
            _ => 1,
        }
    }
}

impl crate::names::Named for Integrator {
    const ALL: &'static [Integrator] = &Integrator::ALL;
    fn name(self) -> &'static str {
        Integrator::name(self)
    }
}

impl<'de> serde::Deserialize<'de> for Integrator {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Integrator, D::Error> {
        crate::names::deserialize(d)
    }
}

impl fmt::Display for Integrator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The precision the spring forces are evaluated in. Everything else of a
/// step (state, loads, pins, integration, strain limiting, the report) stays
/// f64 whichever is chosen.
///
/// `F32` rounds positions and velocities to f32 for the spring kernel and
/// adds its forces back in f64: the kernel runs 16 lanes instead of 8 (about
/// twice the springs per second, on AVX-512 and on AVX2), while the state
/// never accumulates f32 rounding. For live instances; estimation and
/// references stay f64 (they difference positions twice, where f32 rounding
/// would be of the order of gravity). Bit-reproducible like f64: the same
/// bits on every instruction set. A mesh's bending stencils stay f64 but
/// go through their assembled operator with `F32` ([`super::Assembled`]:
/// the same forces in another order of summation, fewer operations), so
/// `F32` is the live level's fast path as a whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SpringPrecision {
    /// Double precision (the default).
    #[default]
    F64,
    /// Spring forces in single precision, the rest of the step in double.
    F32,
}

impl SpringPrecision {
    /// Both, in a fixed order.
    pub const ALL: [SpringPrecision; 2] = [SpringPrecision::F64, SpringPrecision::F32];

    /// Name used in config files and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            SpringPrecision::F64 => "f64",
            SpringPrecision::F32 => "f32",
        }
    }

    /// Parse a [`SpringPrecision::name`] (see [`crate::names`]).
    pub fn from_name(name: &str) -> Option<SpringPrecision> {
        crate::names::parse(name).ok()
    }
}

impl crate::names::Named for SpringPrecision {
    const ALL: &'static [SpringPrecision] = &SpringPrecision::ALL;
    fn name(self) -> &'static str {
        SpringPrecision::name(self)
    }
}

impl<'de> serde::Deserialize<'de> for SpringPrecision {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<SpringPrecision, D::Error> {
        crate::names::deserialize(d)
    }
}

impl fmt::Display for SpringPrecision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Bayraktar et al. 2007 stiffness adjustment (Yu, eq. 6): a spring longer
/// than `(1 + allowed) · L0` uses `K · L / L0` instead of `K`.
///
/// Passive: it stiffens over-stretched springs but cannot bound the stretch
/// under sudden loads (see [`StrainLimit`] for that).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffnessAdjustment {
    /// Allowed deformation rate (strain), e.g. 0.10 for woven fabric.
    pub allowed: f64,
}

/// Provot-style strain limiting: after each step, springs of the selected
/// kinds stretched beyond `(1 + max_strain) · L0` are shortened back by moving
/// both ends (weighted by inverse mass, pins never move), and the nodes'
/// velocities get the same correction divided by dt, so the over-stretching
/// velocity is removed too (position *and* velocity correction).
///
/// Corrections are computed for all springs from the same positions and then
/// averaged per node (Jacobi), so the result does not depend on spring order
/// and mirror-symmetric scenes stay symmetric.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrainLimit {
    /// Largest allowed strain (L − L0) / L0, e.g. 0.10.
    pub max_strain: f64,
    /// Upper bound on Jacobi sweeps over the springs found too long by the full
    /// checks so far (a sweep with no violation ends early; at most 8 full checks a step).
    pub max_iterations: u32,
    /// Violations at or below `max_strain · (1 + tolerance)` count as satisfied.
    pub tolerance: f64,
    /// Which spring kinds are limited, indexed by [`SpringKind::index`].
    pub kinds: [bool; 3],
}

impl Default for StrainLimit {
    fn default() -> Self {
        StrainLimit {
            max_strain: 0.10,
            max_iterations: 64,
            tolerance: 1e-3,
            kinds: [true, true, false],
        }
    }
}

/// Settings of the implicit solver's conjugate-gradient loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CgSettings {
    /// Stop when ‖r‖ ≤ tolerance · ‖b‖ (preconditioned norms are not used).
    pub tolerance: f64,
    /// Hard cap on iterations per step; the report says when it was hit.
    pub max_iterations: u32,
}

impl Default for CgSettings {
    fn default() -> Self {
        CgSettings {
            tolerance: 1e-8,
            max_iterations: 500,
        }
    }
}

/// Everything that parameterises a step except topology, masses and loads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimParams {
    /// Fixed time step in seconds. Never stretched: the engine sub-steps.
    pub dt: f64,
    /// Integration scheme.
    pub integrator: Integrator,
    /// Spring coefficients per type.
    pub material: Material,
    /// Gravitational acceleration (m/s²); (0, −9.81, 0) on Earth with y up.
    pub gravity: [f64; 3],
    /// Global drag rate γ in 1/s: every free node feels −γ·m·v (air
    /// resistance; makes the low-frequency swinging settle).
    pub drag: f64,
    /// Optional Bayraktar stiffness adjustment.
    pub stiffness_adjustment: Option<StiffnessAdjustment>,
    /// Optional Provot strain limiting.
    pub strain_limit: Option<StrainLimit>,
    /// Implicit-Euler solver settings (ignored by the explicit integrators).
    pub cg: CgSettings,
    /// Self-contact (see [`super::selfcontact`]); None: the cloth passes
    /// through itself.
    pub self_contact: Option<super::SelfContact>,
}
