"""Stop the browser view with SIGTERM again and again against a running
compose topology, and count the stops that did not exit 0.

Not run by CI (minutes per hundred stops). It repeats the measurement in
docs/deployment.md, "QUIC, not `tls/`": zenoh's `tls/` link aborted the
view at SIGTERM in about 1 of 100 stops, its QUIC link in none of 401.

    bash .ci/compose-check.sh --static-only      # makes out/ci-compose/secrets
    /tmp/lodcloth-pyvenv/bin/python .ci/view_stop_loop.py --stops 300 [--variant plain]

Each stop: the view runs 0.5-3 s (uniform) after it is healthy, gets
SIGTERM and must exit 0 within 20 s; a failed stop's log is kept as
out/ci-compose/loop-VARIANT/logs/view-stop-K.log (with RUST_BACKTRACE=1).
"""

from __future__ import annotations

import argparse
import random
import shutil
import signal
import sys
import time

import compose_check as cc


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stops", type=int, default=100)
    ap.add_argument("--variant", choices=["secure", "plain"], default="secure")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    random.seed(args.seed)
    secrets = cc.OUT / "secrets"
    cc.require(args.variant == "plain" or secrets.is_dir(),
               f"{secrets} is missing: run bash .ci/compose-check.sh --static-only first")
    name = "compose.secure.yaml" if args.variant == "secure" else "compose.yaml"
    c = cc.load_compose(cc.COMPOSE_DIR / name, secrets if args.variant == "secure" else None)
    cc.static_checks(c)
    t = cc.Topology(c, f"loop-{args.variant}")
    t.base_env["RUST_BACKTRACE"] = "1"
    view = c.services["view"]
    failed = 0
    try:
        t.up()
        for k in range(args.stops):
            proc = t.procs.pop("view")
            time.sleep(random.uniform(0.5, 3.0))
            proc.send_signal(signal.SIGTERM)
            rc = proc.wait(timeout=20)
            if rc != 0:
                failed += 1
                shutil.copy(t.dir / "logs" / "view.log", t.dir / "logs" / f"view-stop-{k}.log")
            cc.log(f"stop {k + 1}/{args.stops}: exit {rc}; {failed} failed so far")
            t.start(view)
            t.wait_healthy(view)
        t.down(require_clean=False)
    except BaseException:
        t.kill_all()
        raise
    cc.log(f"{failed} of {args.stops} stops of the view did not exit 0 ({args.variant})")
    return 1 if failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except cc.CheckError as e:
        cc.log(f"FAILED: {e}")
        sys.exit(1)
