#!/usr/bin/env bash
# Generate the Python protobuf code of the wire contract (proto/) into the
# package, where it is checked in: installing or running the client needs no
# protoc. Run it after every change to proto/ (CI's .ci/python-gencode.sh
# fails when the checked-in files differ from what this writes).
#
#   bash clients/python/generate.sh            # rewrite src/lodcloth_client/v1/
#   bash clients/python/generate.sh OUT_DIR    # write OUT_DIR/lodcloth_pb2.py{,i} instead
#
# protoc is the one bundled in grpcio-tools from PyPI, at the version pinned
# below, installed into its own venv ($LODCLOTH_GEN_VENV, default
# ${TMPDIR:-/tmp}/lodcloth-genvenv) so that it never meets the client's
# runtime protobuf.
#
# Why 1.80.1: its protoc writes gencode for protobuf 6.31.1 (the gencode
# checks `runtime >= 6.31.1` at import). protobuf 6.x still runs on Python
# 3.9, and protobuf's cross-version guarantee has major-6 gencode supported
# by runtimes 6.x and 7.x, so pyproject.toml can allow protobuf>=6.31.1,<8:
# 3.9 gets 6.x, newer Pythons get 7.x. The grpcio-tools 1.81+ line writes
# 6.33.5 or 7.x gencode and itself needs Python >= 3.10. Raising this pin
# means raising pyproject.toml's protobuf floor to the new gencode version.
set -euo pipefail
GRPCIO_TOOLS=1.80.1
HERE="$(cd "$(dirname "$0")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
OUT="${1:-$HERE/src/lodcloth_client/v1}"
VENV="${LODCLOTH_GEN_VENV:-${TMPDIR:-/tmp}/lodcloth-genvenv}"

if ! "$VENV/bin/python" -c "
import importlib.metadata as m, sys
sys.exit(m.version('grpcio-tools') != '$GRPCIO_TOOLS')" 2> /dev/null; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --disable-pip-version-check "grpcio-tools==$GRPCIO_TOOLS"
fi

TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
# -I proto: the descriptor keeps the contract's own file name,
# lodcloth/v1/lodcloth.proto, as in the daemon's descriptor set.
(cd "$ROOT" && "$VENV/bin/python" -m grpc_tools.protoc -Iproto \
  --python_out="$TMP" --pyi_out="$TMP" lodcloth/v1/lodcloth.proto)
# protoc names the module after the file's path (lodcloth.v1.lodcloth_pb2);
# it lives in this package instead, and the classes' __module__ (used by
# pickle and repr) should say so. The one string is the only edit.
PY="$TMP/lodcloth/v1/lodcloth_pb2.py"
test "$(grep -c "'lodcloth.v1.lodcloth_pb2'" "$PY")" = 1 || {
  echo "generate.sh: protoc's output no longer names the module as expected; update the edit below" >&2
  exit 1
}
sed -i "s/'lodcloth.v1.lodcloth_pb2'/'lodcloth_client.v1.lodcloth_pb2'/" "$PY"
mkdir -p "$OUT"
cp "$PY" "$TMP/lodcloth/v1/lodcloth_pb2.pyi" "$OUT/"
echo "generated $OUT/lodcloth_pb2.py and lodcloth_pb2.pyi (grpcio-tools $GRPCIO_TOOLS)"
