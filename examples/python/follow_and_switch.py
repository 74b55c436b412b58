#!/usr/bin/env python3
"""Follow an instance's cloth with the lodcloth-client package, then switch it.

An example of the package as a library (its command line is `lodcloth-py`):
for a few seconds it prints the cloth's centroid and the mean node speed
between consecutive states, switches the level (--level or --max-error), and
follows the new level. Install the package first:

    pip install ./clients/python
    python examples/python/follow_and_switch.py hanging --level 32x32
    python examples/python/follow_and_switch.py paper-1 --max-error 0.05 --connect tcp/127.0.0.1:7450
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from lodcloth_client import Client, ConnectOptions, LodclothError, level_str, percent, positions


def follow(client: Client, instance: str, seconds: float) -> None:
    """Print the centroid and the mean node speed of each state for `seconds`."""
    previous = None
    until = time.monotonic() + seconds
    for state in client.states(instance, timeout=5):
        pts = positions(state)  # [(x, y, z), ...] in metres
        centroid = [sum(c) / len(pts) for c in zip(*pts)]
        speed = "-"
        if previous is not None and len(previous[1]) == len(pts) and state.time > previous[0]:
            dt = state.time - previous[0]
            mean = sum(math.dist(a, b) for a, b in zip(previous[1], pts)) / len(pts) / dt
            speed = f"{mean:.3f} m/s"
        previous = (state.time, pts)
        print(
            f"  t {state.time:7.3f} s  level {level_str(state.level):<7} "
            f"centroid ({centroid[0]:+.3f}, {centroid[1]:+.3f}, {centroid[2]:+.3f}) m  mean speed {speed}"
            + ("  [transition]" if state.transition else "")
        )
        if time.monotonic() > until:
            return


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("instance")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--level", help="level to switch to, e.g. 32x32 (a surface: a point count)")
    target.add_argument("--max-error", type=float, help="cheapest level within this relative error (0.05 = 5 %%)")
    p.add_argument("--connect", help="endpoint(s), comma separated (default $LODCLOTH_CONNECT or tcp/127.0.0.1:7450)")
    p.add_argument("--seconds", type=float, default=1.0, help="follow this long before and after (default %(default)s)")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds to wait for the switch (default %(default)s)")
    args = p.parse_args()
    options = ConnectOptions.from_env(connect=args.connect.split(",") if args.connect else None)
    try:
        with Client.open(options) as client:
            info = client.info(args.instance)
            print(
                f"{info.instance}: {info.kind} at {level_str(info.level)}, allowed "
                + ", ".join(level_str(lv.level) for lv in info.levels)
            )
            follow(client, args.instance, args.seconds)
            reply = client.switch(args.instance, args.level, max_error=args.max_error, timeout=args.timeout)
            print(
                f"switched {level_str(reply.previous)} -> {level_str(reply.level)} in {reply.seconds:.3f} s, "
                f"predicted error {percent(reply, 'predicted_error')}"
            )
            follow(client, args.instance, args.seconds)
    except LodclothError as e:  # RefusedError names the daemon's code, e.g. CODE_LEVEL_NOT_ALLOWED
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
