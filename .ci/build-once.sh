#!/usr/bin/env bash
# CI: the README's two commands share one build. Run after `cargo test
# --release`: `cargo build --release` (what `cargo run --release -- serve`
# builds) must find every unit it needs already built. A unit it would
# compile again means a dependency resolves to other features without the
# dev-dependencies (criterion, proptest, … turn features of shared crates
# on), so a user who runs `serve` first and the tests second, or the other
# way round, compiles zenoh and lodcloth twice; Cargo.toml's feature pins
# keep the two resolutions equal. Fails naming the units that rebuilt.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --message-format=json 2> /dev/null | python3 -c '
import json, sys
rebuilt = []
for line in sys.stdin:
    try:
        m = json.loads(line)
    except ValueError:
        continue
    if m.get("reason") == "compiler-artifact" and not m.get("fresh", True):
        rebuilt.append(m["target"]["name"] + " (" + m["package_id"] + ")")
    if m.get("reason") == "build-finished" and not m.get("success"):
        sys.exit("build-once: cargo build --release failed")
if rebuilt:
    print("build-once: cargo build --release compiled again what cargo test --release had built:", file=sys.stderr)
    for r in rebuilt:
        print("  " + r, file=sys.stderr)
    print("a dependency resolves to other features without the dev-dependencies: pin them in Cargo.toml (see its feature pins)", file=sys.stderr)
    sys.exit(1)
print("build-once: cargo build --release reuses the test build (every unit fresh)")
'
