//! Plain-value parameters of a simulation: spring coefficients per type, the
//! integrator, and super-elasticity control. All `Copy`, all SI units.

use std::fmt;

/// The three spring types of a mass-spring cloth (Sung 2018 §3, Provot 1995).
///
/// The discriminant is the index into per-type arrays such as
/// [`Material::springs`] and [`crate::sim::StepReport::max_strain`].
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

/// Stiffness and damping of one spring type (Sung 2018 eq. 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpringCoeffs {
    /// Stiffness K in N/m, ≥ 0.
    pub k: f64,
    /// Damping C of the relative velocity along the spring, in N·s/m, ≥ 0.
    pub c: f64,
}

/// Material coefficients: one [`SpringCoeffs`] per [`SpringKind`].
///
/// These are *per-spring* coefficients, as in the paper: the same values on a
/// coarser mesh give a different (stiffer or softer) cloth, which is exactly
/// the incoherence that coefficient estimation corrects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Indexed by [`SpringKind::index`].
    pub springs: [SpringCoeffs; 3],
}

impl Material {
    /// Coefficients of one kind.
    pub fn get(&self, kind: SpringKind) -> SpringCoeffs {
        self.springs[kind.index()]
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
}

impl Integrator {
    /// All integrators, in a fixed order for sweeps and tables.
    pub const ALL: [Integrator; 4] = [
        Integrator::ExplicitEuler,
        Integrator::SymplecticEuler,
        Integrator::Rk4,
        Integrator::ImplicitEuler,
    ];

    /// Name used in config files, CSV and the CLI.
    pub const fn name(self) -> &'static str {
        match self {
            Integrator::ExplicitEuler => "explicit_euler",
            Integrator::SymplecticEuler => "symplectic_euler",
            Integrator::Rk4 => "rk4",
            Integrator::ImplicitEuler => "implicit_euler",
        }
    }

    /// Parse a [`Integrator::name`] (see [`crate::names`]).
    pub fn from_name(name: &str) -> Option<Integrator> {
        crate::names::parse(name).ok()
    }

    /// Force evaluations per step (cost model for benchmarks and pacing).
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
}
