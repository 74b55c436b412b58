//! Contact with rigid bodies: planes, spheres, capsules and boxes, at rest or
//! moving along a [`PinPath`], with Coulomb friction.
//!
//! # The model
//! Contact is a constraint on the cloth's *nodes*, resolved once per step
//! after the integrator (and after pins and strain limiting), the way
//! Bridson, Fedkiw and Anderson (2002) resolve cloth–body contact at the
//! velocity level:
//! - **Position.** No free node ends a step closer than the collider's
//!   `clearance` to its surface (the cloth's half thickness plus a margin,
//!   so the triangles between nodes rarely cut into a curved body).
//! - **Velocity.** The node's velocity relative to the body loses its
//!   approaching normal part Δvₙ (perfectly inelastic), and its tangential
//!   part shrinks by μ·Δvₙ, never past zero (Coulomb friction with one
//!   coefficient for sliding and sticking). A node resting on a plane under
//!   gravity at any `dt` thus feels exactly μ·m·g·cos θ of friction per step
//!   (`tests/contact.rs` checks the sliding block's ½(g sin θ − μ g cos θ)t²).
//!
//! # No tunnelling
//! A node that came from outside the inflated body this step is put back
//! onto the tangent plane at the *first* point of its straight path (in the
//! body's frame, so a moving body counts) that touches it, keeping its
//! motion along that plane; not at the nearest surface point of its end
//! position. A node fast enough to cross a thin box in one step is thus
//! stopped on the side it came from. The signed distance of a convex body is a
//! convex function, so along a segment it has one minimum; a golden-section
//! search finds it and a bisection the first crossing before it. Segments
//! that cannot reach the body (by the distance's 1-Lipschitz bound) are
//! rejected with two distance evaluations, so a node far from every body
//! costs about as much as one wind or load term.
//!
//! Only nodes collide: an edge between two nodes on either side of a thin
//! edge of a box can still pass it. At the shipped scenes' cell sizes
//! (≥ 2 cm on the bodies' ≥ 10 cm features) this does not show.

use super::loads::PinPath;
use super::vec3::{add, dot, norm, normalize, scale, sub, tangent_basis, V3};

/// A rigid body's shape, in its own frame (centred on the body's position).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// The half-space behind a plane through the position, with unit outward
    /// `normal`.
    Plane {
        /// Unit normal pointing out of the solid side.
        normal: V3,
    },
    /// A ball.
    Sphere {
        /// m, > 0.
        radius: f64,
    },
    /// The points within `radius` of the segment from −`half_axis` to
    /// +`half_axis`.
    Capsule {
        /// Half the axis segment (m); may be zero (a sphere).
        half_axis: V3,
        /// m, > 0.
        radius: f64,
    },
    /// An axis-aligned box.
    Cuboid {
        /// Half its size along x, y, z (m), each > 0.
        half_extents: V3,
    },
}

impl Shape {
    /// Signed distance from the surface at `q` (negative inside) and the
    /// outward unit direction in which it grows fastest.
    #[inline]
    pub fn distance(&self, q: V3) -> (f64, V3) {
        match *self {
            Shape::Plane { normal } => (dot(q, normal), normal),
            Shape::Sphere { radius } => round(q, radius),
            Shape::Capsule { half_axis, radius } => {
                let len2 = dot(half_axis, half_axis);
                let s = if len2 > 0.0 {
                    (dot(q, half_axis) / len2).clamp(-1.0, 1.0)
                } else {
                    0.0
                };
                round(sub(q, scale(half_axis, s)), radius)
            }
            Shape::Cuboid { half_extents: e } => {
                let d = [q[0].abs() - e[0], q[1].abs() - e[1], q[2].abs() - e[2]];
                let sign = q.map(|x| if x < 0.0 { -1.0 } else { 1.0 });
                if d.iter().any(|&x| x > 0.0) {
                    let out = d.map(|x| x.max(0.0));
                    let len = norm(out);
                    (len, [0, 1, 2].map(|c| sign[c] * out[c] / len))
                } else {
                    // Inside: the nearest face.
                    let c = (0..3).fold(0, |b, c| if d[c] > d[b] { c } else { b });
                    let mut n = [0.0; 3];
                    n[c] = sign[c];
                    (d[c], n)
                }
            }
        }
    }
}

impl Shape {
    /// Its surface as a triangle soup about its centre (three vertices per
    /// triangle, wound outwards), for drawing: a sphere or capsule as 24
    /// segments by 12 rings a hemisphere, a box as its 12 triangles, a plane
    /// as a square `plane_size` across.
    pub fn triangles(&self, plane_size: f64) -> Vec<V3> {
        let mut out = Vec::new();
        match *self {
            Shape::Plane { normal } => {
                let (t1, t2) = tangent_basis(normal);
                let h = 0.5 * plane_size;
                let corner = |a: f64, b: f64| add(scale(t1, a * h), scale(t2, b * h));
                let [p00, p10, p11, p01] = [
                    corner(-1.0, -1.0),
                    corner(1.0, -1.0),
                    corner(1.0, 1.0),
                    corner(-1.0, 1.0),
                ];
                out.extend([p00, p10, p11, p00, p11, p01]);
            }
            Shape::Sphere { radius } => round_triangles(radius, [0.0, 0.0, 0.0], &mut out),
            Shape::Capsule { half_axis, radius } => round_triangles(radius, half_axis, &mut out),
            Shape::Cuboid { half_extents: e } => {
                for axis in 0..3 {
                    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                    for sign in [1.0, -1.0] {
                        let vertex = |a: f64, b: f64| {
                            let mut p = [0.0; 3];
                            p[axis] = sign * e[axis];
                            p[u] = a * e[u];
                            p[v] = b * sign * e[v];
                            p
                        };
                        let [p00, p10, p11, p01] = [
                            vertex(-1.0, -1.0),
                            vertex(1.0, -1.0),
                            vertex(1.0, 1.0),
                            vertex(-1.0, 1.0),
                        ];
                        out.extend([p00, p10, p11, p00, p11, p01]);
                    }
                }
            }
        }
        out
    }
}

/// A capsule of `radius` about the segment ±`half_axis` (a sphere when it
/// is zero) as triangles: two hemispheres of rings joined at the equator.
fn round_triangles(radius: f64, half_axis: V3, out: &mut Vec<V3>) {
    const SEGMENTS: usize = 24;
    const RINGS: usize = 12;
    let axis = normalize(half_axis).unwrap_or([0.0, 0.0, 1.0]);
    let (t1, t2) = tangent_basis(axis);
    // Rows from the +axis pole to the −axis pole; the equator twice, once
    // on each end of the segment, so the cylinder between is a row of quads.
    let mut rows: Vec<(f64, V3)> = Vec::with_capacity(2 * RINGS + 2);
    for (i, end) in [(0..=RINGS).collect::<Vec<_>>(), (RINGS..=2 * RINGS).collect()]
        .into_iter()
        .zip([half_axis, scale(half_axis, -1.0)])
    {
        for r in i {
            rows.push((r as f64 * std::f64::consts::PI / (2 * RINGS) as f64, end));
        }
    }
    let at = |(theta, end): (f64, V3), j: usize| {
        let phi = j as f64 * std::f64::consts::TAU / SEGMENTS as f64;
        let (st, ct) = theta.sin_cos();
        let dir = add(
            add(scale(t1, st * phi.cos()), scale(t2, st * phi.sin())),
            scale(axis, ct),
        );
        add(end, scale(dir, radius))
    };
    for w in rows.windows(2) {
        for j in 0..SEGMENTS {
            let (a, b) = (at(w[0], j), at(w[1], j));
            let (c, d) = (at(w[0], j + 1), at(w[1], j + 1));
            out.extend([a, b, c, c, b, d]);
        }
    }
}

/// Distance to a ball of `radius` about the origin; any outward direction at
/// the centre itself.
#[inline]
fn round(q: V3, radius: f64) -> (f64, V3) {
    let len = norm(q);
    if len > 0.0 {
        (len - radius, scale(q, 1.0 / len))
    } else {
        (-radius, [0.0, 1.0, 0.0])
    }
}

/// A rigid body the cloth cannot pass through.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Collider {
    /// Its shape.
    pub shape: Shape,
    /// Where its centre (a plane: a point on it) is at t = 0 (m).
    pub position: V3,
    /// How it moves from there (it never rotates).
    pub path: PinPath,
    /// Coulomb friction coefficient μ (≥ 0).
    pub friction: f64,
    /// Distance kept between nodes and the surface (m, ≥ 0).
    pub clearance: f64,
}

impl Collider {
    /// Position of the centre and velocity at time `t`.
    #[inline]
    pub fn at(&self, t: f64) -> (V3, V3) {
        let (d, v) = self.path.at(t);
        (add(self.position, d), v)
    }

    /// Signed distance of `p` from the surface at time `t` (negative inside).
    pub fn distance(&self, p: V3, t: f64) -> f64 {
        self.shape.distance(sub(p, self.at(t).0)).0
    }
}

/// Resolve contact for the step from `t0` (positions `prev`) to `t1`
/// (positions `pos`, velocities `vel`, all SoA), for free nodes only
/// (`free[k] = 1`). Returns how many node–body contacts it resolved.
pub(crate) fn resolve(
    colliders: &[Collider],
    (t0, t1): (f64, f64),
    prev: &[f64],
    pos: &mut [f64],
    vel: &mut [f64],
    free: &[f64],
) -> u32 {
    let n = free.len();
    let get = |a: &[f64], k: usize| [a[k], a[n + k], a[2 * n + k]];
    let mut contacts = 0;
    for body in colliders {
        let ((c0, _), (c1, vc)) = (body.at(t0), body.at(t1));
        let (shape, gap) = (&body.shape, body.clearance);
        for k in 0..n {
            if free[k] == 0.0 {
                continue;
            }
            let q1 = sub(get(pos, k), c1);
            let (d1, n1) = shape.distance(q1);
            let q0 = sub(get(prev, k), c0);
            let (d0, _) = shape.distance(q0);
            let hit = if d0 >= gap && (d1 < gap || 0.5 * (d0 + d1 - norm(sub(q1, q0))) < gap) {
                // Came from outside and touched (or passed through) the
                // body: back onto the tangent plane where it first touched,
                // keeping the motion along it.
                first_touch(shape, gap, q0, q1).map(|(touch, normal)| {
                    let q = add(q1, scale(normal, dot(sub(touch, q1), normal).max(0.0)));
                    let (d, n) = shape.distance(q);
                    if d < gap {
                        add(q, scale(n, gap - d))
                    } else {
                        q
                    }
                })
            } else if d1 < gap {
                // Was already touching: out along the nearest surface.
                Some(add(q1, scale(n1, gap - d1)))
            } else {
                None
            };
            let Some(mut q) = hit else { continue };
            contacts += 1;
            let (_, normal) = shape.distance(q);
            let v = get(vel, k);
            let rel = sub(v, vc);
            let vn = dot(rel, normal);
            let mut out = v;
            if vn < 0.0 {
                let tangential = sub(rel, scale(normal, vn));
                let speed = norm(tangential);
                let keep = if speed > 0.0 {
                    (1.0 - body.friction * -vn / speed).max(0.0)
                } else {
                    0.0
                };
                out = add(vc, scale(tangential, keep));
                // The step's slide along the surface shrinks with the
                // velocity: a node held by static friction does not creep
                // by the integrator's g·sin θ·dt² a step.
                let moved = sub(q, q0);
                let slide = sub(moved, scale(normal, dot(moved, normal)));
                q = sub(q, scale(slide, 1.0 - keep));
                let (d, n) = shape.distance(q);
                if d < gap {
                    q = add(q, scale(n, gap - d));
                }
            }
            let p = add(q, c1);
            for c in 0..3 {
                pos[c * n + k] = p[c];
                vel[c * n + k] = out[c];
            }
        }
    }
    contacts
}

/// Where the segment `q0 → q1` (body frame) first comes within `gap` of the
/// surface, given that `q0` is not within it, and the outward normal there;
/// `None` when it never does. Exact to ~1e-9 of the segment's length.
fn first_touch(shape: &Shape, gap: f64, q0: V3, q1: V3) -> Option<(V3, V3)> {
    let at = |s: f64| add(q0, scale(sub(q1, q0), s));
    let f = |s: f64| shape.distance(at(s)).0;
    // The minimum of a convex function on [0, 1] by golden section, stopping
    // early once below the gap.
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    let mut low = 1.0;
    if f(1.0) >= gap {
        const R: f64 = 0.618_033_988_749_894_8;
        let (mut a, mut b) = (hi - R * (hi - lo), lo + R * (hi - lo));
        let (mut fa, mut fb) = (f(a), f(b));
        let mut found = None;
        for _ in 0..60 {
            if fa < gap {
                found = Some(a);
                break;
            }
            if fb < gap {
                found = Some(b);
                break;
            }
            if fa <= fb {
                hi = b;
                b = a;
                fb = fa;
                a = hi - R * (hi - lo);
                fa = f(a);
            } else {
                lo = a;
                a = b;
                fa = fb;
                b = lo + R * (hi - lo);
                fb = f(b);
            }
        }
        low = found?;
    }
    // f(0) ≥ gap > f(low): bisect for the first crossing (f falls on [0, low]).
    let (mut a, mut b) = (0.0, low);
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        if f(m) >= gap {
            a = m;
        } else {
            b = m;
        }
    }
    let q = at(a);
    let (d, n) = shape.distance(q);
    Some((add(q, scale(n, (gap - d).max(0.0))), n))
}
