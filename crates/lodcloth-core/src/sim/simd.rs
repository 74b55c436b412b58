//! Runtime choice of instruction set for the hot loops.
//!
//! The crate is built for the baseline of its target (x86-64: SSE2), so the
//! vector loops of a step would run two f64 lanes wide. [`dispatch`] runs a
//! closure inside a function compiled with AVX-512F or AVX2+FMA when the CPU
//! has them; everything the closure inlines (functions marked
//! `#[inline(always)]` and the closure itself) is compiled for that
//! instruction set. Calls that are not inlined run baseline code.
//!
//! Results do not depend on the choice: the loops use only exactly rounded
//! IEEE operations (`mul_add` is a fused multiply-add everywhere, a library
//! call without hardware FMA), and reductions have a fixed lane structure,
//! never one that follows the vector width.

/// An instruction-set level the hot loops are compiled for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    /// x86-64 AVX-512F (8 f64 lanes).
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// x86-64 AVX2 with FMA (4 f64 lanes).
    #[cfg(target_arch = "x86_64")]
    Avx2Fma,
    /// Whatever the target's baseline is.
    Generic,
}

impl Isa {
    /// Every level this CPU can run, best first.
    pub(crate) fn supported() -> impl Iterator<Item = Isa> {
        let all = [
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma,
            Isa::Generic,
        ];
        all.into_iter().filter(|isa| isa.available())
    }

    /// The best level this CPU can run.
    pub(crate) fn best() -> Isa {
        Isa::supported().next().unwrap_or(Isa::Generic)
    }

    fn available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => std::is_x86_feature_detected!("avx512f"),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma"),
            Isa::Generic => true,
        }
    }
}

/// Which compiled path the hot loops of this thread take (see
/// [`force_baseline`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VectorPath {
    /// The best instruction set of this CPU (the default).
    Best,
    /// The target's baseline (x86-64: SSE2, two f64 lanes), as if the CPU
    /// had nothing better.
    Baseline,
    /// x86-64 AVX2 with FMA even on a CPU with AVX-512 (the baseline where
    /// the CPU lacks AVX2): to time, on one machine, the path that AVX2-only
    /// CPUs (AMD Zen 3 and older, many Intel client cores) run.
    Avx2,
}

thread_local! {
    static PATH: std::cell::Cell<VectorPath> = const { std::cell::Cell::new(VectorPath::Best) };
}

/// Run the hot loops of the calling thread on `path` from now on; returns
/// the path it replaces. For the vectorisation guard (`cargo bench -p
/// lodcloth-core --bench vector_guard`): the same step timed on both paths
/// in one run shows whether the vector path still runs vector code (a
/// function on the hot path that is not inlined into the dispatched
/// closure silently runs baseline code). Results are bit-identical on
/// either path.
pub fn force_path(path: VectorPath) -> VectorPath {
    PATH.with(|p| p.replace(path))
}

/// The instruction set the hot loops of this thread run: the best this CPU
/// has, unless [`force_path`] asked for the baseline.
pub fn active_isa_name() -> &'static str {
    match current() {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 => "AVX-512F",
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2Fma => "AVX2+FMA",
        Isa::Generic => "baseline",
    }
}

pub(crate) fn current() -> Isa {
    match PATH.with(std::cell::Cell::get) {
        VectorPath::Best => Isa::best(),
        VectorPath::Baseline => Isa::Generic,
        #[cfg(target_arch = "x86_64")]
        VectorPath::Avx2 if Isa::Avx2Fma.available() => Isa::Avx2Fma,
        VectorPath::Avx2 => Isa::Generic,
    }
}

/// Run `f` compiled for the best instruction set of this CPU (or the
/// baseline, see [`force_path`]). Mark the closure `#[inline(always)]` so
/// that its body is compiled in that context.
#[inline(always)]
pub(crate) fn dispatch<R>(f: impl FnOnce() -> R) -> R {
    run(current(), f)
}

/// Run `f` compiled for `isa`; falls back to [`Isa::Generic`] when the CPU
/// lacks it (so this is safe to call with any level, e.g. from tests).
#[inline(always)]
pub(crate) fn run<R>(isa: Isa, f: impl FnOnce() -> R) -> R {
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `available` checked that the CPU supports AVX-512F.
        Isa::Avx512 if isa.available() => unsafe { avx512(f) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `available` checked that the CPU supports AVX2 and FMA.
        Isa::Avx2Fma if isa.available() => unsafe { avx2_fma(f) },
        _ => f(),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn avx512<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn avx2_fma<R>(f: impl FnOnce() -> R) -> R {
    f()
}
