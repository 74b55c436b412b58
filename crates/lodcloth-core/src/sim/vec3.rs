//! Small helpers on `[f64; 3]` for geometry outside the hot kernels (which
//! work on structure-of-arrays slices instead).

/// A 3-vector.
pub type V3 = [f64; 3];

/// `a + b`.
#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a − b`.
#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s · a`.
#[inline]
pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// The dot product `a · b`.
#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The cross product `a × b` (right-handed).
#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The Euclidean length `|a|`.
#[inline]
pub fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// The Euclidean distance `|a − b|`.
#[inline]
pub fn dist(a: V3, b: V3) -> f64 {
    norm(sub(a, b))
}

/// `a / |a|`, or `None` when `a` is zero or not finite.
#[inline]
pub fn normalize(a: V3) -> Option<V3> {
    let l = norm(a);
    (l > 0.0 && l.is_finite()).then(|| scale(a, 1.0 / l))
}

/// Two unit vectors `t1, t2` with `t1 × t2 = n` for a unit normal `n`
/// (Duff et al. 2017, branchless and continuous except at n_z = −1).
pub fn tangent_basis(n: V3) -> (V3, V3) {
    let sign = 1f64.copysign(n[2]);
    let a = -1.0 / (sign + n[2]);
    let b = n[0] * n[1] * a;
    let t1 = [1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]];
    let t2 = [b, sign + n[1] * n[1] * a, -n[1]];
    (t1, t2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangent_basis_is_right_handed_and_orthonormal() {
        for n in [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.6, 0.0, 0.8], [-0.48, 0.6, -0.64]] {
            let (t1, t2) = tangent_basis(n);
            for (a, b, want) in [(t1, t1, 1.0), (t2, t2, 1.0), (t1, t2, 0.0), (t1, n, 0.0), (t2, n, 0.0)] {
                assert!((dot(a, b) - want).abs() < 1e-12, "{n:?}");
            }
            let c = cross(t1, t2);
            assert!(dist(c, n) < 1e-12, "t1 × t2 = {c:?} for n = {n:?}");
        }
    }
}
