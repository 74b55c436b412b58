#!/usr/bin/env bash
# CI: deploy/compose/ checked as far as a machine without a Docker engine
# allows (`docker` may be installed, `docker compose` and a daemon are not).
#
#   bash .ci/compose-check.sh [--static-only] [--no-secure-run]
#
# .ci/compose_check.py does the work (its docstring says what is checked):
# both compose files parsed and their structure validated against the
# repository, the Dockerfile and the built binary; then each file's
# services run as local processes of target/release/lodcloth, from the
# file's own commands, environment and health checks, with service
# hostnames on 127.0.0.1, ports remapped to free loopback ports, volumes and
# secrets under out/ci-compose/; the CLI asserts that `list` through the
# router sees both daemons' instances, that `watch`/`record` get metrics and
# states from an instance of each, that the view lists them, that a switch
# of an instance daemon-b owns succeeds and an input to one of its cloths
# reaches it and a later recorder (and, secured, that an observer's switch
# and input are refused, and sessions without a certificate, account or
# right password are not admitted); everything is stopped with SIGTERM and
# must exit 0.
#
# Not checked without Docker: that the image builds, the container's
# filesystem, users and permissions (uid 10001 reading the mounted files,
# writing the volumes), Docker's DNS and networks, published ports on the
# host, compose's own parsing (interpolation, merge keys and conditions are
# reimplemented here), restart policies, and health checks run by the
# engine.
#
# PyYAML comes from PyPI into the CI venv (.ci/run makes it for the daemon
# smoke test); it is installed once and reused.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${LODCLOTH_PYVENV:-/tmp/lodcloth-pyvenv}
PYYAML_VERSION=6.0.3
if [[ ! -x $VENV/bin/python ]]; then
  python3 -m venv "$VENV"
fi
if ! "$VENV/bin/python" -c "import yaml, sys; sys.exit(yaml.__version__ != '$PYYAML_VERSION')" 2> /dev/null; then
  "$VENV/bin/pip" install --quiet --disable-pip-version-check "PyYAML==$PYYAML_VERSION"
fi
exec "$VENV/bin/python" .ci/compose_check.py "$@"
