//! The resolution-independent material of a grid cloth ([`Membrane`]) and its
//! exact conversion to and from per-spring coefficients at any cell spacing.
//!
//! # The derivation (small-strain energy match)
//! A spring of stiffness K whose rest vector is d = |d|·n stores, under a
//! small uniform in-plane strain ε, the energy ½K(n·ε·n)²|d|². Summing the
//! springs a grid cell of hx × hy owns (one structural spring along each
//! axis, one bend spring along each axis spanning two cells, two diagonals of
//! length D = √(hx² + hy²)) and dividing by the cell's area gives the energy
//! density of an orthotropic membrane,
//! W = ½C₁₁ε₁₁² + ½C₂₂ε₂₂² + C₁₂ε₁₁ε₂₂ + 2C₆₆ε₁₂², with (u along hx)
//!
//! | modulus | structural | bend | shear |
//! |---|---|---|---|
//! | C₁₁ | K_u·hx/hy | 4·K_bu·hx/hy | 2·K_d·hx³/(D²·hy) = C₆₆·hx²/hy² |
//! | C₂₂ | K_v·hy/hx | 4·K_bv·hy/hx | 2·K_d·hy³/(D²·hx) = C₆₆·hy²/hx² |
//! | C₆₆ = C₁₂ | | | 2·K_d·hx·hy/D² |
//!
//! (central-force springs obey the Cauchy relation C₁₂ = C₆₆). The moduli are
//! membrane stiffnesses in N/m: C₁₁ is the tension per unit width, per unit
//! strain along u, with v held. Inverting the table gives the springs that make
//! a given membrane at any spacing, and that is what "the same cloth at every
//! level" means: stretching, shearing, and therefore static sag and membrane
//! wave speeds are the same at every resolution and cell aspect. On square
//! cells the inverse returns the springs it started from, so square levels of
//! a square reference get today's per-spring coefficients unchanged.
//!
//! Damping forces C·((v_b − v_a)·n)·n have the same geometry as the springs'
//! K·(L − L₀)·n, so the same table maps viscous moduli (N·s/m) to per-spring C.
//!
//! # What the bend springs mean
//! A bend spring resists bending only through the shortening of a curved
//! chord: for curvature κ its strain is −h²κ²/6, so its energy is quartic in κ
//! and a spring cloth has no linear bending stiffness to match. The membrane
//! therefore keeps the bend springs' *share of the stretch stiffness*
//! (`bend_u`, `bend_v`, N/m), which is what they add to C₁₁ and C₂₂; the split
//! between structural and bend springs is the same at every level. The
//! curvature-energy of that split grows like h⁴ at a fixed curvature (coarse
//! levels resist large bends more); the estimators are what correct that.
//!
//! # Cells too elongated for the shear
//! The diagonals of an elongated cell lie almost along its long side and add
//! C₆₆·(hx/hy)² to that side's stretch. When that exceeds the stretch the
//! membrane asks for (less its bend share), no non-negative structural
//! stiffness makes it: [`Membrane::springs`] then lowers the shear until the
//! structural springs are zero — stretch moduli, which set sag and tension,
//! stay exact; shear stiffness is lost. [`Membrane::from_springs`] on the
//! result tells what was made.

use super::params::{Material, SpringClass, SpringCoeffs};

/// Membrane moduli of one quantity: stiffness (N/m) or viscous damping
/// (N·s/m). See the module docs for what each means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Moduli {
    /// C₁₁: tension per unit width per unit strain along u, v held.
    pub stretch_u: f64,
    /// C₂₂: the same along v.
    pub stretch_v: f64,
    /// C₆₆: in-plane shear modulus (shear force per unit width per unit
    /// engineering shear strain).
    pub shear: f64,
    /// The part of `stretch_u` carried by the bend springs.
    pub bend_u: f64,
    /// The part of `stretch_v` carried by the bend springs.
    pub bend_v: f64,
}

/// A cloth's material independent of its discretisation: membrane stiffness
/// and damping (areal density lives with the scene's masses).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Membrane {
    /// Stiffness moduli (N/m).
    pub stiffness: Moduli,
    /// Damping moduli (N·s/m).
    pub damping: Moduli,
}

impl Membrane {
    /// The membrane that `material`'s springs make on cells of `hx × hy`.
    pub fn from_springs(material: &Material, hx: f64, hy: f64) -> Membrane {
        let pick = |f: fn(SpringCoeffs) -> f64| -> [f64; 5] { material.springs.map(f) };
        Membrane {
            stiffness: moduli_from(pick(|s| s.k), hx, hy),
            damping: moduli_from(pick(|s| s.c), hx, hy),
        }
    }

    /// The per-spring coefficients that make this membrane on cells of
    /// `hx × hy` (shear lowered where the cells are too elongated for it; see
    /// the module docs).
    pub fn springs(&self, hx: f64, hy: f64) -> Material {
        let k = springs_from(&self.stiffness, hx, hy);
        let c = springs_from(&self.damping, hx, hy);
        let mut springs = [SpringCoeffs { k: 0.0, c: 0.0 }; 5];
        for (i, s) in springs.iter_mut().enumerate() {
            *s = SpringCoeffs { k: k[i], c: c[i] };
        }
        Material { springs }
    }

    /// `material` (made for cells of `from`) converted to cells of `to`
    /// (each `(hx, hy)`), through the membrane it makes; `material` itself,
    /// bit for bit, when the cells are the same or both square (the
    /// conversion is then the identity, and rounding would only add noise:
    /// a long run of a falling cloth is sensitive to the last bit of a
    /// coefficient).
    pub fn convert(material: &Material, from: (f64, f64), to: (f64, f64)) -> Material {
        if from == to || (from.0 == from.1 && to.0 == to.1) {
            return *material;
        }
        Membrane::from_springs(material, from.0, from.1).springs(to.0, to.1)
    }
}

/// The table of the module docs, forwards: per-class values → moduli.
fn moduli_from(v: [f64; 5], hx: f64, hy: f64) -> Moduli {
    let [su, sv, d, bu, bv] = v;
    let (r, d2) = (hx / hy, hx * hx + hy * hy);
    let shear = 2.0 * d * hx * hy / d2;
    let bend_u = 4.0 * bu * r;
    let bend_v = 4.0 * bv / r;
    Moduli {
        stretch_u: su * r + bend_u + shear * r * r,
        stretch_v: sv / r + bend_v + shear / (r * r),
        shear,
        bend_u,
        bend_v,
    }
}

/// The table backwards: moduli → per-class values, indexed by
/// [`SpringClass::index`]. Negative structural values are avoided by
/// lowering the shear (then the bend share) as the module docs say.
fn springs_from(m: &Moduli, hx: f64, hy: f64) -> [f64; 5] {
    let (r, d2) = (hx / hy, hx * hx + hy * hy);
    let bend_u = m.bend_u.min(m.stretch_u);
    let bend_v = m.bend_v.min(m.stretch_v);
    // Largest shear both directions can carry with non-negative structural springs.
    let room = ((m.stretch_u - bend_u) / (r * r)).min((m.stretch_v - bend_v) * r * r);
    let shear = m.shear.min(room).max(0.0);
    let mut out = [0.0; 5];
    out[SpringClass::StructuralU.index()] = ((m.stretch_u - bend_u - shear * r * r) / r).max(0.0);
    out[SpringClass::StructuralV.index()] = ((m.stretch_v - bend_v - shear / (r * r)) * r).max(0.0);
    out[SpringClass::Shear.index()] = shear * d2 / (2.0 * hx * hy);
    out[SpringClass::BendU.index()] = bend_u / (4.0 * r);
    out[SpringClass::BendV.index()] = bend_v * r / 4.0;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material() -> Material {
        Material::isotropic([
            SpringCoeffs { k: 400.0, c: 0.04 },
            SpringCoeffs { k: 60.0, c: 0.006 },
            SpringCoeffs { k: 8.0, c: 0.0008 },
        ])
    }

    #[test]
    fn square_cells_give_back_the_springs_at_any_size() {
        let m = material();
        for h in [0.5, 1.0 / 63.0, 1e-3] {
            // Through the formulas: the identity up to rounding …
            let back = Membrane::from_springs(&m, 0.03, 0.03).springs(h, h);
            for (a, b) in back.springs.iter().zip(&m.springs) {
                assert!(
                    (a.k - b.k).abs() < 1e-12 * b.k && (a.c - b.c).abs() < 1e-12 * b.c,
                    "{a:?} vs {b:?}"
                );
            }
            // … and `convert` skips them, bit for bit.
            assert_eq!(Membrane::convert(&m, (0.03, 0.03), (h, h)), m);
        }
    }

    #[test]
    fn round_trips_through_any_cell_shape() {
        let m = material();
        let membrane = Membrane::from_springs(&m, 0.02, 0.02);
        for (hx, hy) in [(0.02, 0.035), (0.05, 0.03), (1.0 / 39.0, 1.0 / 23.0)] {
            let springs = membrane.springs(hx, hy);
            let again = Membrane::from_springs(&springs, hx, hy);
            for (a, b) in [(again.stiffness, membrane.stiffness), (again.damping, membrane.damping)] {
                for (x, y) in [
                    (a.stretch_u, b.stretch_u),
                    (a.stretch_v, b.stretch_v),
                    (a.shear, b.shear),
                    (a.bend_u, b.bend_u),
                    (a.bend_v, b.bend_v),
                ] {
                    assert!((x - y).abs() <= 1e-12 * y.abs().max(1e-30), "{hx}×{hy}: {x} vs {y}");
                }
            }
            // Longer springs along u are softer per spring: K·h is what a row carries.
            let (ku, kv) = (
                springs.get(SpringClass::StructuralU).k,
                springs.get(SpringClass::StructuralV).k,
            );
            assert!((ku > kv) == (hx < hy), "{hx}×{hy}: K_u {ku}, K_v {kv}");
        }
    }

    #[test]
    fn too_elongated_cells_keep_the_stretch_and_lose_shear() {
        let membrane = Membrane::from_springs(&material(), 0.02, 0.02);
        // hx = 4·hy: the diagonals add 16·C66 to C11 = 472, more than it has.
        let (hx, hy) = (0.08, 0.02);
        let springs = membrane.springs(hx, hy);
        assert!(springs.springs.iter().all(|s| s.k >= 0.0 && s.c >= 0.0));
        assert_eq!(springs.get(SpringClass::StructuralU).k, 0.0);
        let made = Membrane::from_springs(&springs, hx, hy);
        let want = membrane.stiffness;
        assert!((made.stiffness.stretch_u - want.stretch_u).abs() < 1e-9 * want.stretch_u);
        assert!((made.stiffness.stretch_v - want.stretch_v).abs() < 1e-9 * want.stretch_v);
        assert!(made.stiffness.shear < want.shear);
    }
}
