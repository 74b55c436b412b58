//! Closest points between a point and a triangle and between two segments,
//! and the times in a step at which four linearly moving points are
//! coplanar: the narrow phase of self-contact.

use crate::sim::vec3::{add, cross, dot, scale, sub, V3};

/// The closest point to `p` on triangle `(a, b, c)`, as barycentric
/// weights `[wa, wb, wc]` (non-negative, summing to 1). Ericson,
/// *Real-Time Collision Detection* (2005), §5.1.5: the Voronoi region of
/// the triangle's features that holds `p`. Also how a mesh level's
/// vertices are located on another's surface (`mesh::locate`).
pub fn point_triangle(p: V3, a: V3, b: V3, c: V3) -> [f64; 3] {
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = va + vb + vc;
    if !(denom.abs() > 0.0) {
        // A degenerate triangle: its first vertex.
        return [1.0, 0.0, 0.0];
    }
    // Inside the face: rounding can leave a weight a few ulps below zero.
    let weights = [va / denom, vb / denom, vc / denom].map(|x| x.max(0.0));
    let sum: f64 = weights.iter().sum();
    weights.map(|x| x / sum)
}

/// The closest points of segments `p1–q1` and `p2–q2` as their parameters
/// `(s, t)` in [0, 1]: `p1 + s·(q1 − p1)` and `p2 + t·(q2 − p2)`. Ericson
/// (2005), §5.1.9, parallel and degenerate segments included.
pub fn segment_segment(p1: V3, q1: V3, p2: V3, q2: V3) -> (f64, f64) {
    let d1 = sub(q1, p1);
    let d2 = sub(q2, p2);
    let r = sub(p1, p2);
    let a = dot(d1, d1);
    let e = dot(d2, d2);
    let f = dot(d2, r);
    const TINY: f64 = 1e-30;
    if a <= TINY && e <= TINY {
        return (0.0, 0.0);
    }
    if a <= TINY {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = dot(d1, r);
    if e <= TINY {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = dot(d1, d2);
    let denom = a * e - b * b;
    // Parallel segments (denom 0): any s; 0 then t from it.
    let mut s = if denom > 1e-12 * a * e {
        ((b * f - c * e) / denom).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    (s, t)
}

/// `a + s·(b − a)`.
#[inline]
pub fn lerp(a: V3, b: V3, s: f64) -> V3 {
    add(a, scale(sub(b, a), s))
}

/// The times τ in [0, 1], ascending, at which points `x[k] + τ·d[k]`
/// (k = 0…3) are coplanar: the roots of the cubic
/// `((x1 − x0) × (x2 − x0)) · (x3 − x0)` in τ (Provot 1997; Bridson et
/// al. 2002). At most three; written into `out`, their count returned. A
/// cubic that vanishes identically (the four points stay coplanar) gives
/// τ = 0 alone: the proximity test at that time decides.
pub fn coplanar_times(x: [V3; 4], d: [V3; 4], out: &mut [f64; 3]) -> usize {
    let a1 = sub(x[1], x[0]);
    let a2 = sub(x[2], x[0]);
    let a3 = sub(x[3], x[0]);
    let b1 = sub(d[1], d[0]);
    let b2 = sub(d[2], d[0]);
    let b3 = sub(d[3], d[0]);
    let a12 = cross(a1, a2);
    let mixed = add(cross(b1, a2), cross(a1, b2));
    let b12 = cross(b1, b2);
    let c0 = dot(a12, a3);
    let c1 = dot(mixed, a3) + dot(a12, b3);
    let c2 = dot(b12, a3) + dot(mixed, b3);
    let c3 = dot(b12, b3);
    let f = |t: f64| ((c3 * t + c2) * t + c1) * t + c0;
    let scale = c0.abs().max(c1.abs()).max(c2.abs()).max(c3.abs());
    if !(scale > 0.0) || !scale.is_finite() {
        out[0] = 0.0;
        return 1;
    }
    let tol = 1e-12 * scale;
    // Most pairs a step checks never become coplanar: the cubic's Bernstein
    // coefficients on [0, 1] all of one sign bound it away from zero there
    // (it lies in their convex hull), so no root is sought.
    let bern = [c0, c0 + c1 / 3.0, c0 + (2.0 * c1 + c2) / 3.0, c0 + c1 + c2 + c3];
    if bern.iter().all(|&b| b > tol) || bern.iter().all(|&b| b < -tol) {
        return 0;
    }
    // Split [0, 1] where the derivative vanishes: f is monotone between.
    let mut cuts = [0.0, 1.0, 1.0, 1.0];
    let mut m = 1;
    {
        // f' = 3c3 t² + 2c2 t + c1.
        let (qa, qb, qc) = (3.0 * c3, 2.0 * c2, c1);
        let mut push = |t: f64| {
            if t > 0.0 && t < 1.0 {
                cuts[m] = t;
                m += 1;
            }
        };
        if qa.abs() > 1e-14 * scale {
            let disc = qb * qb - 4.0 * qa * qc;
            if disc >= 0.0 {
                let sq = disc.sqrt();
                // The numerically stable pair of roots.
                let q = -0.5 * (qb + qb.signum() * sq);
                let (r1, r2) = (q / qa, if q != 0.0 { qc / q } else { -qb / (2.0 * qa) });
                let (lo, hi) = if r1 < r2 { (r1, r2) } else { (r2, r1) };
                push(lo);
                push(hi);
            }
        } else if qb.abs() > 1e-14 * scale {
            push(-qc / qb);
        }
    }
    cuts[m] = 1.0;
    let cuts = &mut cuts[..=m];
    cuts.sort_by(f64::total_cmp);
    let mut count = 0;
    let mut push_root = |t: f64, count: &mut usize| {
        if *count < 3 && (*count == 0 || t > out[*count - 1]) {
            out[*count] = t;
            *count += 1;
        }
    };
    if f(0.0).abs() <= tol {
        push_root(0.0, &mut count);
    }
    for w in cuts.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        let (flo, fhi) = (f(lo), f(hi));
        if fhi.abs() <= tol {
            push_root(hi, &mut count);
            continue;
        }
        if flo.abs() <= tol || (flo < 0.0) == (fhi < 0.0) {
            continue;
        }
        // Bisection: f is monotone here, 52 halvings reach f64's resolution.
        let rising = fhi > flo;
        for _ in 0..52 {
            let mid = 0.5 * (lo + hi);
            if (f(mid) < 0.0) == rising {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        push_root(0.5 * (lo + hi), &mut count);
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_point_on_a_triangle_is_in_the_right_region() {
        let (a, b, c) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        // Above the face.
        let w = point_triangle([0.25, 0.25, 1.0], a, b, c);
        assert!((w[0] - 0.5).abs() < 1e-15 && (w[1] - 0.25).abs() < 1e-15);
        // Beyond vertex b, beyond edge bc.
        assert_eq!(point_triangle([2.0, -1.0, 0.0], a, b, c), [0.0, 1.0, 0.0]);
        let w = point_triangle([1.0, 1.0, 0.0], a, b, c);
        assert!((w[1] - 0.5).abs() < 1e-15 && (w[2] - 0.5).abs() < 1e-15);
    }

    #[test]
    fn closest_points_of_crossed_and_parallel_segments() {
        let (s, t) = segment_segment([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 1.0, 1.0]);
        assert!((s - 0.5).abs() < 1e-15 && (t - 0.5).abs() < 1e-15);
        let (s, t) = segment_segment([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [3.0, 1.0, 0.0]);
        assert_eq!((s, t), (1.0, 0.0));
    }

    #[test]
    fn a_point_falling_through_a_triangle_is_coplanar_when_it_crosses() {
        let x = [[0.2, 0.2, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let d = [[0.0, 0.0, -4.0], [0.0; 3], [0.0; 3], [0.0; 3]];
        let mut out = [0.0; 3];
        let n = coplanar_times(x, d, &mut out);
        assert_eq!(n, 1);
        assert!((out[0] - 0.25).abs() < 1e-15, "{}", out[0]);
        // Rising through a rising triangle: never coplanar.
        let d = [[0.0, 0.0, 1.0]; 4];
        assert_eq!(coplanar_times(x, d, &mut out), 0);
    }

    #[test]
    fn every_coplanar_time_of_four_moving_points_is_found() {
        // Four points in general motion: the volume vanishes at every time
        // found, and every sign change of it over [0, 1] is a time found.
        let x = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.3], [0.0, 1.0, -0.2], [0.3, 0.3, 0.1]];
        let d = [[0.1, 0.0, 0.2], [0.0, 0.5, -0.9], [0.4, -0.2, 0.7], [-0.6, 0.1, -0.5]];
        let mut out = [0.0; 3];
        let n = coplanar_times(x, d, &mut out);
        let volume = |t: f64| {
            let p: Vec<V3> = (0..4).map(|k| add(x[k], scale(d[k], t))).collect();
            dot(cross(sub(p[1], p[0]), sub(p[2], p[0])), sub(p[3], p[0]))
        };
        for &t in &out[..n] {
            assert!(volume(t).abs() < 1e-12, "τ = {t}: volume {}", volume(t));
        }
        // Every sign change over a fine sampling is a root found.
        let changes = (0..1000)
            .filter(|&i| (volume(i as f64 / 1000.0) < 0.0) != (volume((i + 1) as f64 / 1000.0) < 0.0))
            .count();
        assert_eq!(changes, n, "roots {:?}", &out[..n]);
    }
}
