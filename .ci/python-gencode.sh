#!/usr/bin/env bash
# The Python client's protobuf code is checked in
# (clients/python/src/lodcloth_client/v1/lodcloth_pb2.py and .pyi); it must be
# exactly what clients/python/generate.sh makes from proto/ now. Fails when
# the .proto changed without regenerating (or the generated files were edited).
# generate.sh installs its pinned grpcio-tools from PyPI into its own venv.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="$(mktemp -d)"
trap 'rm -rf "$OUT"' EXIT
bash clients/python/generate.sh "$OUT" > /dev/null
stale=0
for f in lodcloth_pb2.py lodcloth_pb2.pyi; do
  if ! diff -u "clients/python/src/lodcloth_client/v1/$f" "$OUT/$f"; then
    stale=1
  fi
done
if [ "$stale" != 0 ]; then
  echo "python-gencode.sh: the checked-in protobuf code of clients/python is not what proto/ generates" >&2
  echo "                   (diff above: checked in, then generated); run bash clients/python/generate.sh and commit it" >&2
  exit 1
fi
echo "python gencode: clients/python/src/lodcloth_client/v1 is up to date with proto/"
