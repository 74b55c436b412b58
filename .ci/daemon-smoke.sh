#!/usr/bin/env bash
# Start `lodcloth serve` (config/default.toml, peer on tcp/127.0.0.1:7450),
# drive it with the Rust CLI clients and the Python client package
# (clients/python, pip-installed by .ci/run into /tmp/lodcloth-pyvenv, or the
# venv named by LODCLOTH_PYVENV), then stop it with SIGTERM and require a
# clean exit.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=target/release/lodcloth
PYVENV="${LODCLOTH_PYVENV:-/tmp/lodcloth-pyvenv}"
PY="$PYVENV/bin/lodcloth-py"
LOG=out/ci-serve.log
mkdir -p out
"$BIN" serve > "$LOG" 2>&1 &
DAEMON=$!
VIEW=
trap 'kill $DAEMON $VIEW 2>/dev/null || true' EXIT
for _ in $(seq 50); do "$BIN" health > /dev/null 2>&1 && break; sleep 0.2; done
"$BIN" health
"$BIN" list
"$BIN" watch paper-1 --count 3
"$BIN" switch paper-1 16x16 --timeout 300
if "$BIN" switch paper-1 17x17; then echo "a level outside the allowed set was accepted" >&2; exit 1; fi
"$BIN" record paper-1 --seconds 1 --out out/ci-record.lct
"$BIN" inspect out/ci-record.lct
# The Foxglove channels to an MCAP file, and the browser view's server (the
# page itself is driven by tests/clients.rs in headless Chromium).
"$BIN" record paper-1 --seconds 1 --mcap out/ci-record.mcap
test -s out/ci-record.mcap
"$BIN" view --listen 127.0.0.1:8090 > out/ci-view.log 2>&1 &
VIEW=$!
# (curl's output is read whole before grep: `curl | grep -q` fails under
# pipefail when grep exits before curl has written everything.)
for _ in $(seq 50); do
  grep -q sphere <<< "$(curl -fsS http://127.0.0.1:8090/api/instances 2>/dev/null || true)" && break
  sleep 0.2
done
grep -q '"name":"paper-1","alive":true' <<< "$(curl -fsS http://127.0.0.1:8090/api/instances)"
grep -q '<canvas id="view"' <<< "$(curl -fsS http://127.0.0.1:8090/)"
kill -TERM $VIEW
wait $VIEW
VIEW=
# The Python client's console script, as installed by pip.
$PY list --timeout 10
$PY watch hanging --count 3 --timeout 10
$PY switch hanging --level 24x24 --timeout 300
# The package as a library: examples/python follows the cloth and switches it
# (to the level it is at now, so at once).
"$PYVENV/bin/python" examples/python/follow_and_switch.py hanging --level 24x24 --seconds 0.2 --timeout 300
# The point-sampled surface: its whole cloud on `state`, a switch to another size.
"$BIN" watch sphere --count 2
"$BIN" switch sphere 85 --timeout 300
$PY watch sphere --count 3 --timeout 10
if refusal="$($PY switch nope --level 16x16 --timeout 10 2>&1)"; then echo "an unknown instance was accepted" >&2; exit 1; fi
grep -q "CODE_UNKNOWN_INSTANCE" <<< "$refusal" || { echo "the refusal does not name its code: $refusal" >&2; exit 1; }
# The package's own tests: the unit tests and, with LODCLOTH_DAEMON set, the
# ones against this daemon (decoded states of a cloth and a surface, refusals,
# callbacks, pause/resume), run against the installed package.
LODCLOTH_DAEMON=tcp/127.0.0.1:7450 "$PYVENV/bin/python" -m unittest discover -s clients/python/tests -v
kill -TERM $DAEMON
wait $DAEMON
grep -q "stopped" "$LOG"
# The default config snapshots every instance at shutdown; a second start
# resumes them (paper-1 at the 16x16 it was switched to) instead of
# starting from rest.
test -s out/snapshots/paper-1.snapshot && test -s out/snapshots/sphere.snapshot
"$BIN" serve --log-json > out/ci-serve-2.log 2>&1 &
DAEMON=$!
for _ in $(seq 50); do "$BIN" health > /dev/null 2>&1 && break; sleep 0.2; done
timeout 300 "$BIN" watch paper-1 --count 3
for _ in $(seq 600); do
  grep '"instance":"paper-1"' out/ci-serve-2.log | grep -q "predicted and live error attached" && break
  sleep 0.2
done
kill -TERM $DAEMON
wait $DAEMON
trap - EXIT
grep "resumed from its snapshot" out/ci-serve-2.log | grep -q '"instance":"paper-1"'
# paper-1 resumed with its saved coefficients at once; its level, prepared
# again in the background, is then attached (prediction and live error).
grep '"instance":"paper-1"' out/ci-serve-2.log | grep -q "predicted and live error attached"
echo "daemon smoke test passed"
