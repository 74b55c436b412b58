//! Blocks of springs: the arithmetic of Sung 2018 eq. 1 over `L` lanes at
//! once, and how runs, tails and gathered pairs feed it and add its forces.

use super::super::real::Real;
use super::super::topology::SpringGroup;
use super::precision::{GroupRest, KernelReal};
use super::MIN_LENGTH;

/// Coefficients the kernel needs for one group.
#[derive(Clone, Copy)]
pub(super) struct Coef<R> {
    pub(super) k: R,
    pub(super) c: R,
    /// L/L0 above which the Bayraktar adjustment uses K·L/L0 (∞ when off).
    pub(super) adjust_ratio: R,
}

/// Per-lane accumulators of one spring kind.
#[derive(Clone, Copy)]
pub(super) struct Acc<R, const L: usize> {
    /// Σ (L − L0)² (times ½K at the end: K is the same for the whole kind).
    pub(super) ext2: [R; L],
    pub(super) max_ratio: [R; L],
}

impl<R: Real, const L: usize> Acc<R, L> {
    pub(super) const EMPTY: Acc<R, L> = Acc {
        ext2: [R::ZERO; L],
        max_ratio: [R::NEG_INFINITY; L],
    };

    #[inline(always)]
    fn add<const N: usize>(&mut self, out: &BlockOut<R, N>) {
        for j in 0..N {
            self.ext2[j] = out.ext[j].mul_add(out.ext[j], self.ext2[j]);
            self.max_ratio[j] = if out.ratio[j] > self.max_ratio[j] {
                out.ratio[j]
            } else {
                self.max_ratio[j]
            };
        }
    }
}

/// Endpoint data of a batch of springs as parallel slices of equal length.
pub(super) struct Run<'a, R> {
    pub(super) xa: [&'a [R]; 3],
    pub(super) xb: [&'a [R]; 3],
    pub(super) va: [&'a [R]; 3],
    pub(super) vb: [&'a [R]; 3],
    pub(super) rest: &'a [R],
    pub(super) inv_rest: &'a [R],
    /// Per-slot mask (1 spring, 0 none), or empty when every slot is a spring.
    pub(super) live: &'a [R],
    /// The rest length and its inverse shared by every spring of the run,
    /// when they are (then `rest` and `inv_rest` are not read).
    pub(super) uniform: Option<(R, R)>,
}

impl<R> Run<'_, R> {
    fn len(&self) -> usize {
        self.rest.len()
    }
}

/// A run of springs `a → a + offset` with `offset ≥ 1`, adding +F at `a0 + i`
/// and −F at `b0 + i` block by block. Blocks of `L`, then one block
/// ending at the run's end with the lanes already counted masked out (or
/// single springs, for runs shorter than a block).
#[inline(always)]
pub(super) fn run_direct<R: Real, const L: usize, const ADJ: bool, const STATS: bool>(
    run: &Run<R>,
    a0: usize,
    b0: usize,
    coef: Coef<R>,
    f: &mut [&mut [R]; 3],
    acc: &mut Acc<R, L>,
) {
    let len = run.len();
    // Local accumulators (not behind a reference) so they stay in registers.
    let mut local = *acc;
    let mut i = 0;
    while i + L <= len {
        let o = block::<R, L, ADJ>(run, i, coef, 0);
        if STATS {
            local.add(&o);
        }
        add_pair(f, a0 + i, b0 + i, &o.f);
        i += L;
    }
    tail::<R, L, ADJ, STATS>(run, i, a0, b0, coef, f, &mut local);
    *acc = local;
}

/// Springs `i..len` of a run (fewer than `L`), added with [`add_pair`].
#[inline(always)]
fn tail<R: Real, const L: usize, const ADJ: bool, const STATS: bool>(
    run: &Run<R>,
    i: usize,
    a0: usize,
    b0: usize,
    coef: Coef<R>,
    f: &mut [&mut [R]; 3],
    acc: &mut Acc<R, L>,
) {
    let len = run.len();
    if i == len {
        return;
    }
    if len >= L {
        let s = len - L;
        let o = block::<R, L, ADJ>(run, s, coef, i - s);
        if STATS {
            acc.add(&o);
        }
        add_pair(f, a0 + s, b0 + s, &o.f);
    } else {
        for i in i..len {
            let o = block::<R, 1, ADJ>(run, i, coef, 0);
            if STATS {
                acc.add(&o);
            }
            add_pair(f, a0 + i, b0 + i, &o.f);
        }
    }
}

/// +F on nodes `a..a+N`, then −F on nodes `b..b+N`. Correct for any
/// `b > a` (the second range is read after the first is written); when the
/// ranges overlap the CPU stalls on the store-to-load dependency, so hot
/// loops with short offsets use [`run_carry`].
#[inline(always)]
fn add_pair<R: Real, const N: usize>(f: &mut [&mut [R]; 3], a: usize, b: usize, fo: &[[R; N]; 3]) {
    // All three components are loaded before any is stored: the component
    // arrays lie a multiple of 4 KiB apart on power-of-two grids, and a load
    // of y behind a store of x at the same offset waits on a false
    // dependency (4K aliasing); 64×64 took twice as long as 62×62.
    let mut fa = [[R::ZERO; N]; 3];
    for c in 0..3 {
        fa[c] = *<&[R; N]>::try_from(&f[c][a..a + N]).expect("N");
    }
    for c in 0..3 {
        for j in 0..N {
            fa[c][j] += fo[c][j];
        }
        f[c][a..a + N].copy_from_slice(&fa[c]);
    }
    let mut fb = [[R::ZERO; N]; 3];
    for c in 0..3 {
        fb[c] = *<&[R; N]>::try_from(&f[c][b..b + N]).expect("N");
    }
    for c in 0..3 {
        for j in 0..N {
            fb[c][j] -= fo[c][j];
        }
        f[c][b..b + N].copy_from_slice(&fb[c]);
    }
}

/// A run of springs `a → a + OFF` with `OFF < L` (horizontal structural
/// and bend springs of a grid). Node `a0 + i + j` receives +F of spring
/// `i + j` and −F of spring `i + j − OFF`; the block nets both in registers
/// (the second from this block shifted by OFF lanes, or from the previous
/// block) and updates the node forces once, with no overlapping
/// stores and loads between blocks.
#[inline(always)]
pub(super) fn run_carry<R: Real, const L: usize, const OFF: usize, const ADJ: bool, const STATS: bool>(
    run: &Run<R>,
    a0: usize,
    coef: Coef<R>,
    f: &mut [&mut [R]; 3],
    acc: &mut Acc<R, L>,
) {
    let len = run.len();
    let mut local = *acc;
    // Forces of the previous block; its last OFF lanes are still owed to
    // the b ends of its last OFF springs.
    let mut carry = [[R::ZERO; L]; 3];
    let mut i = 0;
    while i + L <= len {
        let o = block::<R, L, ADJ>(run, i, coef, 0);
        if STATS {
            local.add(&o);
        }
        // Loads of all three components before any store (4K aliasing, see
        // `add_pair`).
        let mut fa = [[R::ZERO; L]; 3];
        for c in 0..3 {
            fa[c] = *<&[R; L]>::try_from(&f[c][a0 + i..a0 + i + L]).expect("L");
        }
        for c in 0..3 {
            for j in 0..L {
                let back = if j >= OFF {
                    o.f[c][j - OFF]
                } else {
                    carry[c][L - OFF + j]
                };
                fa[c][j] += o.f[c][j] - back;
            }
            f[c][a0 + i..a0 + i + L].copy_from_slice(&fa[c]);
            carry[c] = o.f[c];
        }
        i += L;
    }
    if i > 0 {
        // −F of springs i − OFF .. i at their b ends, nodes a0 + i .. a0 + i + OFF.
        for c in 0..3 {
            for k in 0..OFF {
                f[c][a0 + i + k] -= carry[c][L - OFF + k];
            }
        }
    }
    tail::<R, L, ADJ, STATS>(run, i, a0, a0 + OFF, coef, f, &mut local);
    *acc = local;
}

/// Buffers of the gather path.
pub(super) struct GatherScratch<'a, R> {
    pub(super) out: &'a mut [R],
    pub(super) gather: &'a mut [R],
    pub(super) cap: usize,
}

/// A group of arbitrary node pairs: gather the endpoint data into contiguous
/// blocks, evaluate as one run, scatter the forces.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn gather_group<R: KernelReal, const L: usize, const ADJ: bool, const STATS: bool>(
    group: &SpringGroup,
    own: &GroupRest<R>,
    p: [&[R]; 3],
    v: [&[R]; 3],
    coef: Coef<R>,
    f: &mut [&mut [R]; 3],
    ws: GatherScratch<R>,
    acc: &mut Acc<R, L>,
) {
    let len = group.len();
    let cap = ws.cap;
    debug_assert!(len <= cap);
    // Gather endpoint data: blocks of `cap` entries, 12 blocks.
    {
        let g = &mut *ws.gather;
        for s in 0..len {
            let (a, b) = (group.a[s] as usize, group.b[s] as usize);
            for c in 0..3 {
                g[c * cap + s] = p[c][a];
                g[(3 + c) * cap + s] = p[c][b];
                g[(6 + c) * cap + s] = v[c][a];
                g[(9 + c) * cap + s] = v[c][b];
            }
        }
    }
    let g = &*ws.gather;
    let blk = |i: usize| &g[i * cap..i * cap + len];
    let (rest, inv_rest) = R::rest(group, own);
    let run = Run {
        xa: [blk(0), blk(1), blk(2)],
        xb: [blk(3), blk(4), blk(5)],
        va: [blk(6), blk(7), blk(8)],
        vb: [blk(9), blk(10), blk(11)],
        rest,
        inv_rest,
        live: &[],
        uniform: None,
    };
    let out = &mut *ws.out;
    let mut local = *acc;
    let mut put = |i: usize, skip: usize, fo: &[[R; L]; 3]| {
        for c in 0..3 {
            for j in skip..L {
                out[c * cap + i + j] = fo[c][j];
            }
        }
    };
    let mut i = 0;
    while i + L <= len {
        let o = block::<R, L, ADJ>(&run, i, coef, 0);
        if STATS {
            local.add(&o);
        }
        put(i, 0, &o.f);
        i += L;
    }
    if i < len && len >= L {
        let s = len - L;
        let o = block::<R, L, ADJ>(&run, s, coef, i - s);
        if STATS {
            local.add(&o);
        }
        put(s, i - s, &o.f);
    } else {
        for i in i..len {
            let o = block::<R, 1, ADJ>(&run, i, coef, 0);
            if STATS {
                local.add(&o);
            }
            for c in 0..3 {
                out[c * cap + i] = o.f[c][0];
            }
        }
    }
    *acc = local;
    for s in 0..len {
        let (a, b) = (group.a[s] as usize, group.b[s] as usize);
        for c in 0..3 {
            let fs = out[c * cap + s];
            f[c][a] += fs;
            f[c][b] -= fs;
        }
    }
}

/// Results of one block of `N` springs.
struct BlockOut<R, const N: usize> {
    /// Force on each spring's `a` end.
    f: [[R; N]; 3],
    /// L − L0.
    ext: [R; N],
    /// L / L0.
    ratio: [R; N],
}

/// Springs `i..i+N` of `run`. Lanes below `skip` are masked: zero force and
/// extension, ratio −∞ (they were counted by the previous block).
#[inline(always)]
fn block<R: Real, const N: usize, const ADJ: bool>(
    run: &Run<R>,
    i: usize,
    coef: Coef<R>,
    skip: usize,
) -> BlockOut<R, N> {
    // References, not copies: each lane loop below then reads the data
    // where it uses it, and fewer vectors are live at a time.
    #[inline(always)]
    fn arr<R: Copy, const N: usize>(s: &[R], i: usize) -> &[R; N] {
        s[i..i + N].try_into().expect("slice of N")
    }
    let (ax, ay, az) = (
        arr::<R, N>(run.xa[0], i),
        arr::<R, N>(run.xa[1], i),
        arr::<R, N>(run.xa[2], i),
    );
    let (bx, by, bz) = (
        arr::<R, N>(run.xb[0], i),
        arr::<R, N>(run.xb[1], i),
        arr::<R, N>(run.xb[2], i),
    );
    let (uax, uay, uaz) = (
        arr::<R, N>(run.va[0], i),
        arr::<R, N>(run.va[1], i),
        arr::<R, N>(run.va[2], i),
    );
    let (ubx, uby, ubz) = (
        arr::<R, N>(run.vb[0], i),
        arr::<R, N>(run.vb[1], i),
        arr::<R, N>(run.vb[2], i),
    );
    let (l0, il0) = match run.uniform {
        Some((l0, il0)) => ([l0; N], [il0; N]),
        None => (*arr::<R, N>(run.rest, i), *arr::<R, N>(run.inv_rest, i)),
    };
    let mask: [R; N] = if run.live.is_empty() {
        [R::ONE; N]
    } else {
        *arr::<R, N>(run.live, i)
    };
    let min2 = R::from_f64(MIN_LENGTH * MIN_LENGTH);
    let mut out = BlockOut {
        f: [[R::ZERO; N]; 3],
        ext: [R::ZERO; N],
        ratio: [R::ZERO; N],
    };
    // Straight-line code with selects only (no branches), so each line
    // becomes one vector instruction over the N lanes.
    for j in 0..N {
        // Sung 2018 eq. 1: F_a = K (L − L0) u + C ((v_b − v_a)·u) u, u = (x_b − x_a)/L.
        // Written as F_a = s·d with d = x_b − x_a, s = (K (L − L0) + C (Δv·d)/L)/L.
        let dx = bx[j] - ax[j];
        let dy = by[j] - ay[j];
        let dz = bz[j] - az[j];
        let len2 = dz.mul_add(dz, dy.mul_add(dy, dx * dx));
        // A coincident pair (L < MIN_LENGTH) has |d| < MIN_LENGTH too, so
        // scaling by 1/MIN_LENGTH keeps |d|/L < 1: bounded, direction-free.
        let safe2 = if len2 > min2 { len2 } else { min2 };
        // A square root and a division, both exactly rounded (the same bits
        // on every instruction set). Below MIN_LENGTH, L reads MIN_LENGTH:
        // a difference under 1e-12 m that no force notices.
        let len = safe2.sqrt();
        let inv = R::ONE / len;
        let dvd = (ubz[j] - uaz[j]).mul_add(dz, (uby[j] - uay[j]).mul_add(dy, (ubx[j] - uax[j]) * dx));
        let ext = len - l0[j];
        let ratio = len * il0[j];
        // Bayraktar 2007 (Yu eq. 6): K·L/L0 beyond the allowed length.
        let elastic = if ADJ {
            let scale = if ratio > coef.adjust_ratio { ratio } else { R::ONE };
            coef.k * scale * ext
        } else {
            coef.k * ext
        };
        let s = coef.c.mul_add(dvd * inv, elastic) * inv;
        let live = j >= skip && mask[j] != R::ZERO;
        let s = if live { s } else { R::ZERO };
        out.f[0][j] = s * dx;
        out.f[1][j] = s * dy;
        out.f[2][j] = s * dz;
        out.ext[j] = if live { ext } else { R::ZERO };
        out.ratio[j] = if live { ratio } else { R::NEG_INFINITY };
    }
    out
}
