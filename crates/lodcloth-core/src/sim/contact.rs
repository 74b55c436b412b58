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
//! A node inside the inflated body at the end of a step goes out along the
//! nearest surface, unless it came from outside and the nearest surface
//! faces away from where it came (it went through the middle of a thin
//! body): then, and when it ended clear on the far side of the body, it is
//! put back onto the tangent plane at the *first* point of its straight path
//! (in the body's frame, so a moving body counts) that touches the body,
//! keeping its motion along that plane. A node fast enough to cross a thin
//! box in one step is thus stopped on the side it came from. The signed
//! distance of a convex body is convex along a segment, with one minimum: a
//! golden-section search finds it and a bisection the first crossing before
//! it. That search runs only for a step that moved towards the body at its
//! start and away at its end while coming within reach of it (by the
//! distance's 1-Lipschitz bound); resting and sliding nodes never need it,
//! and a node far from every body costs one distance and one length.
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
    /// A solid upright (y-axis) cylinder with flat caps: a Cusick tester's
    /// support disc, a table's round top, a post.
    Cylinder {
        /// m, > 0.
        radius: f64,
        /// Half its height (m), > 0.
        half_height: f64,
    },
}

impl Shape {
    /// Signed distance from the surface at `q` (negative inside) and the
    /// outward unit direction in which it grows fastest.
    #[inline(always)]
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
                if d[0] > 0.0 || d[1] > 0.0 || d[2] > 0.0 {
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
            Shape::Cylinder { radius, half_height } => {
                let rho = (q[0] * q[0] + q[2] * q[2]).sqrt();
                let radial = if rho > 0.0 {
                    [q[0] / rho, 0.0, q[2] / rho]
                } else {
                    [1.0, 0.0, 0.0]
                };
                let up = [0.0, if q[1] < 0.0 { -1.0 } else { 1.0 }, 0.0];
                let (dr, dy) = (rho - radius, q[1].abs() - half_height);
                if dr > 0.0 && dy > 0.0 {
                    // Beyond the rim: from the nearest point of the rim circle.
                    let len = (dr * dr + dy * dy).sqrt();
                    (len, add(scale(radial, dr / len), scale(up, dy / len)))
                } else if dr > dy {
                    // Outside the side, or inside and nearer the side.
                    (dr, radial)
                } else {
                    (dy, up)
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
            Shape::Cylinder { radius, half_height } => {
                const SEGMENTS: usize = 48;
                let rim = |j: usize, y: f64| {
                    let phi = j as f64 * std::f64::consts::TAU / SEGMENTS as f64;
                    [radius * phi.cos(), y, radius * phi.sin()]
                };
                let (top, bottom) = ([0.0, half_height, 0.0], [0.0, -half_height, 0.0]);
                for j in 0..SEGMENTS {
                    let (a, b) = (rim(j, half_height), rim(j + 1, half_height));
                    let (c, d) = (rim(j, -half_height), rim(j + 1, -half_height));
                    // Caps seen from outside, then the side's quad.
                    out.extend([top, b, a, bottom, c, d, a, b, c, c, b, d]);
                }
            }
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
/// (`free[k] = 1`). `near` is scratch of one byte per node. Returns how
/// many node–body contacts it resolved.
///
/// Two passes per body: a branch-free one over every node (it vectorises)
/// marks those that ended within reach of the body — closer than the
/// clearance plus this step's length (relative to the body), since the
/// distance is 1-Lipschitz — and the marked few are then resolved one by
/// one.
#[inline(always)]
pub(crate) fn resolve(
    colliders: &[Collider],
    (t0, t1): (f64, f64),
    prev: &[f64],
    pos: &mut [f64],
    vel: &mut [f64],
    free: &[f64],
    near: &mut [u8],
) -> u32 {
    let n = free.len();
    let mut contacts = 0;
    for body in colliders {
        let ((c0, _), (c1, vc)) = (body.at(t0), body.at(t1));
        let frame = Frame { c0, c1, vc };
        let reach = Reach {
            c0,
            c1,
            gap: body.clearance,
            prev,
            pos,
            free,
        };
        match body.shape {
            Shape::Plane { normal } => reach.mark(near, |q| dot(q, normal)),
            Shape::Sphere { radius } => reach.mark(near, |q| norm(q) - radius),
            Shape::Capsule { half_axis, radius } => {
                let len2 = dot(half_axis, half_axis);
                let inv = if len2 > 0.0 { 1.0 / len2 } else { 0.0 };
                reach.mark(near, |q| {
                    let s = (dot(q, half_axis) * inv).clamp(-1.0, 1.0);
                    norm(sub(q, scale(half_axis, s))) - radius
                })
            }
            Shape::Cuboid { half_extents: e } => reach.mark(near, |q| {
                let d = [q[0].abs() - e[0], q[1].abs() - e[1], q[2].abs() - e[2]];
                norm(d.map(|x| x.max(0.0))) + d[0].max(d[1]).max(d[2]).min(0.0)
            }),
            Shape::Cylinder { radius, half_height } => reach.mark(near, |q| {
                let d = [(q[0] * q[0] + q[2] * q[2]).sqrt() - radius, q[1].abs() - half_height];
                (d[0].max(0.0).powi(2) + d[1].max(0.0).powi(2)).sqrt() + d[0].max(d[1]).min(0.0)
            }),
        }
        for k in 0..n {
            if near[k] != 0 {
                contacts += u32::from(respond(body, &frame, k, prev, pos, vel));
            }
        }
    }
    contacts
}

/// Where a body was at the start of the step, where it is at the end, and
/// its velocity there.
struct Frame {
    c0: V3,
    c1: V3,
    vc: V3,
}

/// What the marking pass reads.
struct Reach<'a> {
    c0: V3,
    c1: V3,
    gap: f64,
    prev: &'a [f64],
    pos: &'a [f64],
    free: &'a [f64],
}

impl Reach<'_> {
    /// `near[k] = 1` for the free nodes whose step (relative to the body)
    /// may have come within the gap, by the signed distance `sdf`.
    #[inline(always)]
    fn mark(&self, near: &mut [u8], sdf: impl Fn(V3) -> f64) {
        let n = self.free.len();
        let (px, rest) = self.pos.split_at(n);
        let (py, pz) = rest.split_at(n);
        let (bx, rest) = self.prev.split_at(n);
        let (by, bz) = rest.split_at(n);
        let (c1, dc) = (self.c1, sub(self.c1, self.c0));
        let (free, near) = (&self.free[..n], &mut near[..n]);
        let (pz, bz) = (&pz[..n], &bz[..n]);
        for k in 0..n {
            let q1 = [px[k] - c1[0], py[k] - c1[1], pz[k] - c1[2]];
            let step = [px[k] - bx[k] - dc[0], py[k] - by[k] - dc[1], pz[k] - bz[k] - dc[2]];
            let reach = sdf(q1) - norm(step);
            near[k] = u8::from(reach < self.gap) & u8::from(free[k] != 0.0);
        }
    }
}

/// Resolve node `k` against `body`; false when it turns out clear.
#[inline(never)]
fn respond(body: &Collider, frame: &Frame, k: usize, prev: &[f64], pos: &mut [f64], vel: &mut [f64]) -> bool {
    let n = pos.len() / 3;
    let get = |a: &[f64], k: usize| [a[k], a[n + k], a[2 * n + k]];
    let (shape, gap) = (&body.shape, body.clearance);
    let Frame { c0, c1, vc } = *frame;
    let q1 = sub(get(pos, k), c1);
    let (d1, n1) = shape.distance(q1);
    let q0 = sub(get(prev, k), c0);
    let hit = if d1 >= gap {
        // Ends clear of the body. Could it have passed through on the way?
        // Not unless it moved towards the body at the start and away at the
        // end (the distance is convex along the step) and came within reach.
        let step = sub(q1, q0);
        let len = norm(step);
        let (d0, n0) = shape.distance(q0);
        if !(d0 >= gap && dot(n0, step) < 0.0 && dot(n1, step) > 0.0 && 0.5 * (d0 + d1 - len) < gap) {
            return false;
        }
        first_touch(shape, gap, q0, q1).map(|touch| onto_tangent_plane(shape, gap, q1, touch))
    } else {
        let (d0, n0) = shape.distance(q0);
        if d0 >= gap && dot(n0, n1) < 0.5 {
            // Came from outside and ended past where the nearest surface
            // faces the way it came (through the middle of a thin body):
            // back where it first touched.
            first_touch(shape, gap, q0, q1).map(|touch| onto_tangent_plane(shape, gap, q1, touch))
        } else {
            // Resting, sliding or just arrived: out along the nearest
            // surface (moving along a convex body's normal keeps it).
            Some((add(q1, scale(n1, gap - d1)), n1))
        }
    };
    let Some((mut q, normal)) = hit else { return false };
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
        // The step's slide along the surface shrinks with the velocity: a
        // node held by static friction does not creep by the integrator's
        // g·sin θ·dt² a step.
        if keep < 1.0 {
            let moved = sub(q, q0);
            let slide = sub(moved, scale(normal, dot(moved, normal)));
            q = sub(q, scale(slide, 1.0 - keep));
            let (d, n) = shape.distance(q);
            if d < gap {
                q = add(q, scale(n, gap - d));
            }
        }
    }
    let p = add(q, c1);
    for c in 0..3 {
        pos[c * n + k] = p[c];
        vel[c * n + k] = out[c];
    }
    true
}

/// `q1` moved back onto the tangent plane at `touch` (a point at the gap and
/// its outward normal), keeping its motion along the plane, then out along
/// the nearest surface if still within the gap (a curved body).
/// Returns the point and the outward normal there.
fn onto_tangent_plane(shape: &Shape, gap: f64, q1: V3, (touch, normal): (V3, V3)) -> (V3, V3) {
    let q = add(q1, scale(normal, dot(sub(touch, q1), normal).max(0.0)));
    let (d, n) = shape.distance(q);
    if d < gap {
        (add(q, scale(n, gap - d)), n)
    } else {
        (q, n)
    }
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
        for _ in 0..48 {
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
    for _ in 0..48 {
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
