//! The kernel's two precisions, f64 (8 lanes) and f32 (16 lanes): their
//! rest data, scratch buffers and entry points.

use super::super::pair::Pair;
use super::super::params::Material;
use super::super::real::Real;
use super::super::simd::Isa;
use super::super::topology::{SpringGroup, Topology};
use super::{all_springs, split_impl, SpringTotals};

/// A group's rest data in the kernel's precision (the group's own arrays
/// rounded; empty for f64, which reads the topology's directly).
#[derive(Debug, Clone, Default)]
pub struct GroupRest<R> {
    rest: Vec<R>,
    inv_rest: Vec<R>,
    /// [`super::topology::Padded`]'s rest, inverse rest and live mask.
    padded: [Vec<R>; 3],
    /// The rest length and its inverse (in this precision) when every
    /// spring of the padded run has the same: a regular grid's groups. The
    /// kernel then broadcasts them instead of streaming two arrays per group
    /// (at 64×64 in f32 about 190 KB of the step's working set, which a Zen 3
    /// core's 512 KB L2 does not hold beside the fields).
    pub(super) uniform: Option<(R, R)>,
}

/// The rest data of every group in the kernel's precision.
#[derive(Debug, Clone, Default)]
pub struct RestTable<R> {
    pub(super) groups: Vec<GroupRest<R>>,
}

impl<R: RestView> RestTable<R> {
    pub(super) fn new(topology: &Topology) -> RestTable<R> {
        let round = |v: &[f64]| -> Vec<R> {
            if R::NATIVE {
                Vec::new()
            } else {
                v.iter().map(|&x| R::from_f64(x)).collect()
            }
        };
        RestTable {
            groups: topology
                .groups
                .iter()
                .map(|g| GroupRest {
                    rest: round(&g.rest),
                    inv_rest: round(&g.inv_rest),
                    padded: match &g.padded {
                        Some(pd) => [round(&pd.rest), round(&pd.inv_rest), round(&pd.live)],
                        None => Default::default(),
                    },
                    uniform: g.padded.as_ref().and_then(|pd| {
                        // Rounded to R slot by slot: the same bits the arrays hold.
                        let mut live = pd
                            .live
                            .iter()
                            .zip(pd.rest.iter().zip(&pd.inv_rest))
                            .filter(|(l, _)| **l != 0.0);
                        let (_, first) = live.next()?;
                        let first = (R::from_f64(*first.0), R::from_f64(*first.1));
                        live.all(|(_, (r, i))| R::from_f64(*r) == first.0 && R::from_f64(*i) == first.1)
                            .then_some(first)
                    }),
                })
                .collect(),
        }
    }
}

/// The kernel's view of the rest data: the topology's own arrays in f64,
/// the rounded copies otherwise.
pub trait RestView: Real {
    /// `true` when the topology's f64 arrays are this precision.
    const NATIVE: bool;
    /// Rest lengths and their inverses of `group`'s springs.
    fn rest<'a>(group: &'a SpringGroup, own: &'a GroupRest<Self>) -> (&'a [Self], &'a [Self]);
    /// The padded run's rest, inverse rest and live mask.
    fn padded<'a>(group: &'a SpringGroup, own: &'a GroupRest<Self>) -> Option<[&'a [Self]; 3]>;
}

impl RestView for f64 {
    const NATIVE: bool = true;
    #[inline(always)]
    fn rest<'a>(group: &'a SpringGroup, _: &'a GroupRest<f64>) -> (&'a [f64], &'a [f64]) {
        (&group.rest, &group.inv_rest)
    }
    #[inline(always)]
    fn padded<'a>(group: &'a SpringGroup, _: &'a GroupRest<f64>) -> Option<[&'a [f64]; 3]> {
        group
            .padded
            .as_ref()
            .map(|pd| [&pd.rest[..], &pd.inv_rest[..], &pd.live[..]])
    }
}

impl RestView for f32 {
    const NATIVE: bool = false;
    #[inline(always)]
    fn rest<'a>(_: &'a SpringGroup, own: &'a GroupRest<f32>) -> (&'a [f32], &'a [f32]) {
        (&own.rest, &own.inv_rest)
    }
    #[inline(always)]
    fn padded<'a>(group: &'a SpringGroup, own: &'a GroupRest<f32>) -> Option<[&'a [f32]; 3]> {
        group
            .padded
            .as_ref()
            .map(|_| [&own.padded[0][..], &own.padded[1][..], &own.padded[2][..]])
    }
}

/// A precision the kernel runs in. Its lane count [`Real::LANES`] is a
/// const parameter `L` of every generic function below (`[R; R::LANES]` is
/// not a type stable Rust accepts); these entry points fix it per type, and
/// each instantiates the kernel three times: without the stiffness
/// adjustment (the usual case) its compare and select drop out of the
/// inner loop, and without the figures (`stats` false: an RK4 stage, a lean
/// step) so do the extension and strain sums, which on AVX2 also take four
/// of the sixteen vector registers (f32 step 9 % fewer instructions; the
/// lab's NOTEBOOK.md, "The AVX2 kernel's spills").
pub trait KernelReal: RestView {
    /// Every spring, on the calling thread.
    fn whole(
        topology: &Topology,
        material: &Material,
        adjust_ratio: f64,
        pos: &[Self],
        vel: &[Self],
        force: &mut [Self],
        scratch: &mut KernelScratch<Self>,
        stats: bool,
    ) -> SpringTotals;

    /// See [`spring_forces_split`].
    #[allow(clippy::too_many_arguments)]
    fn split(
        topology: &Topology,
        table: &RestTable<Self>,
        material: &Material,
        adjust_ratio: f64,
        pos: &[Self],
        vel: &[Self],
        force: &mut [Self],
        split: usize,
        pair: &dyn Pair,
        isa: Isa,
        stats: bool,
    ) -> SpringTotals;
}

macro_rules! kernel_real {
    ($t:ty, $lanes:literal) => {
        const _: () = assert!(<$t as Real>::LANES == $lanes);
        impl KernelReal for $t {
            #[inline(always)]
            fn whole(
                topology: &Topology,
                material: &Material,
                adjust_ratio: f64,
                pos: &[$t],
                vel: &[$t],
                force: &mut [$t],
                scratch: &mut KernelScratch<$t>,
                stats: bool,
            ) -> SpringTotals {
                // The adjustment computes L/L0 anyway: its figures are
                // always summed (three instances, not four; the caller
                // hides them when not asked for).
                if adjust_ratio < f64::INFINITY {
                    all_springs::<$t, $lanes, true, true>(topology, material, adjust_ratio, pos, vel, force, scratch)
                } else if stats {
                    all_springs::<$t, $lanes, false, true>(topology, material, adjust_ratio, pos, vel, force, scratch)
                } else {
                    all_springs::<$t, $lanes, false, false>(topology, material, adjust_ratio, pos, vel, force, scratch)
                }
            }

            fn split(
                topology: &Topology,
                table: &RestTable<$t>,
                material: &Material,
                adjust_ratio: f64,
                pos: &[$t],
                vel: &[$t],
                force: &mut [$t],
                split: usize,
                pair: &dyn Pair,
                isa: Isa,
                stats: bool,
            ) -> SpringTotals {
                // `split_impl` dispatches each of its parts itself: a
                // function pointer loses no inlining here.
                let instance: SplitFn<$t> = if adjust_ratio < f64::INFINITY {
                    split_impl::<$t, $lanes, true, true>
                } else if stats {
                    split_impl::<$t, $lanes, false, true>
                } else {
                    split_impl::<$t, $lanes, false, false>
                };
                instance(
                    topology,
                    table,
                    material,
                    adjust_ratio,
                    pos,
                    vel,
                    force,
                    split,
                    pair,
                    isa,
                )
            }
        }
    };
}

/// One instance of [`split_impl`].
type SplitFn<R> =
    fn(&Topology, &RestTable<R>, &Material, f64, &[R], &[R], &mut [R], usize, &dyn Pair, Isa) -> SpringTotals;

kernel_real!(f64, 8);
kernel_real!(f32, 16);

/// Preallocated buffers of the kernel; sized once from the topology.
#[derive(Debug, Clone, Default)]
pub struct KernelScratch<R> {
    /// Rest data in the kernel's precision.
    pub(crate) rest: RestTable<R>,
    /// Per-spring force of a gathered group, [x…, y…, z…] with `gather_len` entries each.
    pub(super) out: Vec<R>,
    /// Gathered endpoint data for non-stencil groups: 12 components.
    pub(super) gather: Vec<R>,
    pub(super) gather_len: usize,
}

impl<R: KernelReal> KernelScratch<R> {
    pub(crate) fn new(topology: &Topology) -> KernelScratch<R> {
        let gather_len = topology.max_gather_len();
        KernelScratch {
            rest: RestTable::new(topology),
            out: vec![R::ZERO; 3 * gather_len],
            gather: vec![R::ZERO; 12 * gather_len],
            gather_len,
        }
    }
}
