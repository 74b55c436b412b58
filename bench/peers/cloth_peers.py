#!/usr/bin/env python3
"""Peer comparison: the lodcloth benchmark cloth in NumPy, Taichi and Newton.

Every run: build the cloth (cloth_spec.py), warm up (this also JIT-compiles
Taichi and Warp kernels), then `--repeats` times: reset to the rest state,
time `--steps` steps (synchronised before the clock stops). The sanity values
are read after the last repeat, i.e. after exactly `--steps` steps from rest.

All runs are single-threaded: Taichi with cpu_max_num_threads=1, Warp's CPU
backend is serial, NumPy's elementwise kernels are serial (BLAS threads are
capped at 1 below anyway). The CPU-time/wall-time ratio is checked per run.
"""

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import cloth_spec as spec  # noqa: E402

INTEGRATORS = ("euler", "rk4")
FORCE_EVALS = {"euler": 1, "rk4": 4}
INTEGRATOR_NAMES = {"euler": "symplectic Euler", "rk4": "RK4"}


def run_configs(framework):
    """The runs for --framework: (factory(cloth, precision, integrator), precision, integrator)."""
    out = []
    if framework in ("numpy", "all"):
        from peer_numpy import NumpyCloth

        for kernel in ("springlist", "grid"):
            for integ in INTEGRATORS:
                out.append((lambda c, p, i, k=kernel: NumpyCloth(c, p, i, k), "f64", integ))
    if framework in ("taichi", "all"):
        import peer_taichi

        for serial, precisions in ((True, ("f64", "f32")), (False, ("f64",))):
            for prec in precisions:
                for integ in INTEGRATORS:
                    out.append((lambda c, p, i, s=serial: peer_taichi.TaichiCloth(c, p, i, s), prec, integ))
    if framework in ("newton", "all"):
        try:
            import peer_newton
        except Exception as e:  # optional peer: warp/newton missing or unloadable
            if framework == "newton":
                raise
            print(f"note: Newton skipped ({e})", file=sys.stderr)
        else:
            out.append((peer_newton.NewtonCloth, "f32", "euler"))
    return out


def bench(cloth, factory, precision, integrator, steps, repeats, warmup):
    t0 = time.perf_counter()
    sim = factory(cloth, precision, integrator)
    sim.step(warmup)
    sim.sync()
    setup = time.perf_counter() - t0
    walls, cpus = [], []
    for _ in range(repeats):
        sim.reset()
        sim.sync()
        c0, w0 = time.process_time(), time.perf_counter()
        sim.step(steps)
        sim.sync()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    x, v = sim.state()
    us = statistics.median(walls) / steps * 1e6
    return {
        "framework": sim.framework,
        "variant": sim.variant,
        "precision": precision,
        "integrator": integrator,
        "us_per_step": us,
        "us_min": min(walls) / steps * 1e6,
        "springs_per_s": cloth.n_springs * FORCE_EVALS[integrator] / (us * 1e-6),
        "cpu_over_wall": sum(cpus) / sum(walls),
        "setup_s": setup,
        "sanity": spec.sanity(x, v),
        "x": x,
        "v": v,
    }


def print_tables(results, steps, repeats):
    print(f"\n### Timing ({steps} steps, median of {repeats}; one CPU thread)\n")
    print("| framework | variant | precision | integrator | us/step | min us/step | springs/s | cpu/wall |")
    print("|---|---|---|---|---:|---:|---:|---:|")
    for r in results:
        print(
            f"| {r['framework']} | {r['variant']} | {r['precision']} | {INTEGRATOR_NAMES[r['integrator']]} "
            f"| {r['us_per_step']:.1f} | {r['us_min']:.1f} | {r['springs_per_s']:.3g} | {r['cpu_over_wall']:.2f} |"
        )
    print(
        "\nsprings/s = springs x force evaluations per step (1 Euler, 4 RK4) / median time per step. "
        "cpu/wall well below 1 means the run was starved by other load (numbers too slow); above 1, extra threads."
    )

    print(f"\n### Sanity after {steps} steps from rest (t = {steps * spec.DT:g} s)\n")
    print("| framework | variant | precision | integrator | y(i=32,j=63) [m] | max abs v [m/s] |")
    print("|---|---|---|---|---:|---:|")
    for r in results:
        y, vmax = r["sanity"]
        print(
            f"| {r['framework']} | {r['variant']} | {r['precision']} | {INTEGRATOR_NAMES[r['integrator']]} "
            f"| {y:.15g} | {vmax:.15g} |"
        )

    # Cross-check against the first f64 run of each integrator.
    refs = {}
    for integ in INTEGRATORS:
        ref = next((r for r in results if r["integrator"] == integ and r["precision"] == "f64"), None)
        if ref is not None:
            refs[integ] = ref
    if not refs:
        return True
    print("\n### Agreement with the reference run of the same integrator\n")
    print(
        "Reference: "
        + "; ".join(f"{INTEGRATOR_NAMES[i]}: {r['framework']} {r['variant']} {r['precision']}" for i, r in refs.items())
        + ". Tolerance: 1e-6 relative for f64, 1e-3 for f32.\n"
    )
    print("| framework | variant | precision | integrator | rel. diff y | rel. diff max abs v | max abs dx [m] |")
    print("|---|---|---|---|---:|---:|---:|")
    ok = True
    for r in results:
        ref = refs.get(r["integrator"])
        if ref is None or r is ref:
            continue
        (y, vm), (y0, vm0) = r["sanity"], ref["sanity"]
        ry, rv = abs(y - y0) / abs(y0), abs(vm - vm0) / abs(vm0)
        dx = float(np.abs(r["x"] - ref["x"]).max())
        print(
            f"| {r['framework']} | {r['variant']} | {r['precision']} | {INTEGRATOR_NAMES[r['integrator']]} "
            f"| {ry:.1e} | {rv:.1e} | {dx:.1e} |"
        )
        tol = 1e-6 if r["precision"] == "f64" else 1e-3
        ok &= ry < tol and rv < tol
    return ok


def print_ratio(results, path):
    """lodcloth's median step time against the fastest peer's, per integrator."""
    import json

    with open(path) as f:
        ours = json.load(f)
    keys = {"euler": "symplectic_euler", "rk4": "rk4"}
    print("\n### lodcloth against the fastest peer (this sitting, one CPU thread each)\n")
    print("| integrator | lodcloth us/step | fastest peer | peer us/step | ratio (peer / lodcloth) |")
    print("|---|---:|---|---:|---:|")
    for integ, key in keys.items():
        peers = [r for r in results if r["integrator"] == integ]
        if not peers:
            continue
        best = min(peers, key=lambda r: r["us_per_step"])
        # f64 springs, then f32 springs (the rest of lodcloth's step in f64)
        for suffix, label in (("", "f64"), ("_f32", "f32 springs")):
            if key + suffix not in ours:
                continue
            us = ours[key + suffix]["us_per_step"]
            # The report's figures the step computed: "lean" (no spring
            # energy or strain, as a peer's step) or "full".
            report = ours[key + suffix].get("report", "full")
            print(
                f"| {INTEGRATOR_NAMES[integ]} | {us:.1f} ({label}, {ours[key + suffix]['isa']}, {report} report) | {best['framework']} "
                f"{best['variant']} {best['precision']} | {best['us_per_step']:.1f} | {best['us_per_step'] / us:.2f}x |"
            )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--framework", choices=("taichi", "numpy", "newton", "all"), default="all")
    ap.add_argument("--steps", type=int, default=1000, help="timed steps per repeat (default 1000)")
    ap.add_argument("--repeats", type=int, default=3, help="timed repeats, median reported (default 3)")
    ap.add_argument("--warmup", type=int, default=50, help="untimed steps first (default 50)")
    ap.add_argument(
        "--lodcloth",
        metavar="JSON",
        help="lodcloth's step times of this sitting (run.sh writes them with the peer_step bench): "
        "print lodcloth against the fastest peer per integrator",
    )
    args = ap.parse_args()

    cloth = spec.build()
    print(
        f"cloth: {spec.N_SIDE}x{spec.N_SIDE} nodes, {cloth.n_springs} springs, dt={spec.DT:g} s; "
        f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}"
    )
    mmap = os.environ.get("MALLOC_MMAP_THRESHOLD_")
    print(
        f"glibc MALLOC_MMAP_THRESHOLD_={mmap}"
        if mmap
        else "note: MALLOC_MMAP_THRESHOLD_ unset: NumPy spring-list times vary with glibc's adaptive "
        "mmap threshold (use run.sh, see README)"
    )
    results = []
    for factory, prec, integ in run_configs(args.framework):
        r = bench(cloth, factory, prec, integ, args.steps, args.repeats, args.warmup)
        results.append(r)
        warn = ""
        if r["cpu_over_wall"] > 1.1:
            warn = "  (WARNING: cpu/wall > 1.1, more than one thread?)"
        elif r["cpu_over_wall"] < 0.9:
            warn = "  (WARNING: cpu/wall < 0.9, machine busy? timing may be unreliable)"
        print(
            f"  {r['framework']:7s} {r['variant']:18s} {prec} {integ:5s}: {r['us_per_step']:9.1f} us/step "
            f"(min {r['us_min']:.1f}), setup+warmup {r['setup_s']:.1f} s, cpu/wall {r['cpu_over_wall']:.2f}{warn}",
            flush=True,
        )
    ok = print_tables(results, args.steps, args.repeats)
    if args.lodcloth:
        print_ratio(results, args.lodcloth)
    if not ok:
        print("\nWARNING: runs disagree beyond tolerance (f64: 1e-6 rel, f32: 1e-3 rel)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
