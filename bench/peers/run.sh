#!/usr/bin/env bash
# Peer-comparison benchmark: make a venv (bench/peers/.venv, gitignored),
# install the pinned PyPI requirements, time lodcloth's own 64x64 step
# (cargo bench -p lodcloth-core --bench peer_step), run cloth_peers.py and
# print lodcloth against the fastest peer.
# Usage: bench/peers/run.sh [--framework taichi|numpy|newton|all] [--steps N] [--repeats N] [--warmup N]
# Env: PYTHON (default python3.11, else python3), VENV (default bench/peers/.venv).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
py="${PYTHON:-$(command -v python3.11 || command -v python3)}"
venv="${VENV:-$here/.venv}"

if [ ! -x "$venv/bin/python" ]; then
    "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --upgrade pip
fi
stamp="$venv/.requirements.installed"
if ! cmp -s "$here/requirements.txt" "$stamp"; then
    "$venv/bin/python" -m pip install --quiet -r "$here/requirements.txt"
    cp "$here/requirements.txt" "$stamp"
fi

# one thread everywhere (Taichi and Warp are set up single-threaded in the script)
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
# Fixed glibc malloc thresholds: NumPy's per-step temporaries (~0.5-1 MB) are
# then reused from the heap instead of being mmapped, page-faulted and zeroed
# anew every step. Without this the NumPy spring-list times swing by ~1.7x
# depending on glibc's adaptive threshold (history-dependent). No effect on
# Taichi/Newton (no per-step allocation).
export MALLOC_MMAP_THRESHOLD_="${MALLOC_MMAP_THRESHOLD_:-33554432}"
export MALLOC_TRIM_THRESHOLD_="${MALLOC_TRIM_THRESHOLD_:-134217728}"
# lodcloth's own step first, in the same sitting, for the ratio at the end
# (LODCLOTH_PEERS_SKIP=1 leaves it out: the peers alone, no Rust build).
extra=()
if [ "${LODCLOTH_PEERS_SKIP:-0}" != 1 ]; then
    json="$venv/lodcloth_step.json"
    (cd "$here/../.." && cargo bench -q -p lodcloth-core --bench peer_step -- --json "$json")
    extra=(--lodcloth "$json")
fi
cd "$here"
exec "$venv/bin/python" cloth_peers.py "${extra[@]}" "$@"
