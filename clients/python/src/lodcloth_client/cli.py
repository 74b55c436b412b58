"""``lodcloth-py``: the command line of the Python client.

    lodcloth-py list                               # instances of every daemon
    lodcloth-py watch paper-1 --count 5            # 5 states + 5 metrics, decoded
    lodcloth-py switch paper-1 --level 16x16       # prints the SwitchReply
    lodcloth-py switch paper-1 --max-error 0.05    # cheapest level with <= 5 % error
    lodcloth-py info paper-1                       # levels, coefficients, mesh size
    lodcloth-py control paper-1 pause              # pause | resume | reset
    lodcloth-py health                             # exit 0 when every instance answers

Connection options go before the subcommand and have the Rust CLI's names
and environment variables: --connect (LODCLOTH_CONNECT, comma separated),
--client-mode, --user/--password, --tls-ca, --tls-cert/--tls-key. Any
failure prints ``error: ...`` (a refusal with the daemon's code) and exits 1.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import List, Optional

from . import __version__, v1
from .client import Client
from .codec import ACTIONS, level_str, parse_level, percent, positions, unpack_vec3, v_coefficients
from .errors import LodclothError
from .options import ConnectOptions, split_endpoints

__all__ = ["main", "parse_args"]


def _level(text: str):
    try:
        return parse_level(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text} must be positive")
    return value


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError("must be at least 1")
    return value


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="lodcloth-py",
        description="Python client of a lodcloth daemon (list, watch, switch, info, control, health).",
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    c = p.add_argument_group("connection (defaults from the environment, as the Rust CLI's)")
    c.add_argument(
        "--connect",
        type=split_endpoints,
        help="zenoh endpoint(s) of a daemon or router, comma separated "
        "(default $LODCLOTH_CONNECT or tcp/127.0.0.1:7450; empty: multicast discovery)",
    )
    c.add_argument("--prefix", help="key prefix of the daemon (default lodcloth)")
    c.add_argument(
        "--client-mode",
        action="store_true",
        default=None,
        help="zenoh client mode: one connection, through a router ($LODCLOTH_CLIENT_MODE)",
    )
    c.add_argument("--user", help="user name for a daemon that authenticates ($LODCLOTH_USER)")
    c.add_argument("--password", help="password of --user; prefer $LODCLOTH_PASSWORD")
    c.add_argument("--tls-ca", help="PEM of the CA that signed the daemon's certificate ($LODCLOTH_TLS_CA)")
    c.add_argument("--tls-cert", help="this client's PEM certificate, for mTLS ($LODCLOTH_TLS_CERT)")
    c.add_argument("--tls-key", help="the private key of --tls-cert ($LODCLOTH_TLS_KEY)")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("list", help="list every reachable daemon's instances")
    s.add_argument("--timeout", type=_positive, default=5.0, help="seconds to wait for replies (default %(default)s)")

    s = sub.add_parser("watch", help="print an instance's states and metrics")
    s.add_argument("instance")
    s.add_argument("--count", type=_count, default=10, help="stop after N states and N metrics (default %(default)s)")
    s.add_argument(
        "--timeout", type=_positive, default=5.0, help="seconds to wait for each message (default %(default)s)"
    )

    s = sub.add_parser("switch", help="switch an instance to another level")
    s.add_argument("instance")
    target = s.add_mutually_exclusive_group(required=True)
    target.add_argument("--level", type=_level, help="target level: NXxNY for a cloth (16x16), N for a surface (300)")
    target.add_argument(
        "--max-error", type=_positive, help="cheapest level with at most this relative error (0.05 = 5 %%)"
    )
    s.add_argument("--method", help="estimation method (same, gkd, fit, follow, drape); default: the instance's")
    s.add_argument(
        "--at-once",
        action="store_true",
        help="an unprepared level goes live at once with the scene's coefficients; the estimate follows in place",
    )
    s.add_argument(
        "--timeout",
        type=_positive,
        default=600.0,
        help="seconds to wait for the reply; an unprepared level is estimated first (default %(default)s)",
    )

    s = sub.add_parser("info", help="print an instance's levels, coefficients and mesh")
    s.add_argument("instance")
    s.add_argument("--timeout", type=_positive, default=10.0, help="seconds to wait (default %(default)s)")

    s = sub.add_parser("control", help="pause, resume or reset an instance")
    s.add_argument("instance")
    s.add_argument("action", choices=list(ACTIONS))
    s.add_argument("--timeout", type=_positive, default=10.0, help="seconds to wait (default %(default)s)")

    s = sub.add_parser("health", help="exit 0 when the daemon answers for every instance (or --instance)")
    s.add_argument("--instance")
    s.add_argument("--timeout", type=_positive, default=3.0, help="seconds to wait per query (default %(default)s)")
    return p


def parse_args(argv: Optional[List[str]] = None) -> argparse.Namespace:
    return parser().parse_args(argv)


def options(args: argparse.Namespace) -> ConnectOptions:
    """The environment's connect options, with the command line's on top."""
    return ConnectOptions.from_env(
        connect=args.connect,
        prefix=args.prefix,
        client_mode=args.client_mode,
        user=args.user,
        password=args.password,
        tls_ca=args.tls_ca,
        tls_cert=args.tls_cert,
        tls_key=args.tls_key,
    )


# --------------------------------------------------------------------------
# commands


def cmd_list(args, client: Client) -> None:
    lists = client.list(args.timeout)
    if not lists:
        raise LodclothError(f"no daemon answered {client.prefix}/instances within {args.timeout:g} s")
    for lst in lists:
        print(f"daemon {lst.daemon}: {len(lst.instances)} instance(s)")
        for i in lst.instances:
            print(
                f"  {i.instance:<10} level {level_str(i.level):<7} method {i.method:<5} "
                f"{i.publish_hz:4g} Hz  scene {i.scene}"
            )


def cmd_watch(args, client: Client) -> None:
    # Stop after `count` messages of each kind.
    seen = {"state": 0, "metrics": 0}
    with client.watch(args.instance, timeout=args.timeout) as messages:
        for message in messages:
            kind = "state" if isinstance(message, v1.State) else "metrics"
            if seen[kind] >= args.count:
                continue
            seen[kind] += 1
            if isinstance(message, v1.State):
                print_state(message)
            else:
                print_metrics(message)
            if min(seen.values()) >= args.count:
                break


def print_state(s: "v1.State") -> None:
    pos = positions(s)  # a cloth: nx * ny nodes; a surface: its whole cloud
    first, last = (pos[0], pos[-1]) if pos else ((math.nan,) * 3,) * 2
    print(
        f"state   frame {s.frame:>7}  t {s.time:8.3f} s  level {level_str(s.level):<7} "
        f"nodes {len(pos):>5}  first ({first[0]:+.3f}, {first[1]:+.3f}, {first[2]:+.3f}) m  "
        f"last ({last[0]:+.3f}, {last[1]:+.3f}, {last[2]:+.3f}) m" + ("  [transition]" if s.transition else "")
    )


def print_metrics(m: "v1.Metrics") -> None:
    print(
        f"metrics frame {m.frame:>7}  t {m.time:8.3f} s  level {level_str(m.level):<7} "
        f"predicted {percent(m, 'predicted_error'):>8}  live {percent(m, 'live_error'):>8}  "
        + (f"under input {percent(m, 'predicted_error_under_input'):>8}  " if m.touched else "")
        + f"RTF {m.real_time_factor:.3f}"
        + (f"  halted: {m.halted}" if m.halted else "")
    )


def cmd_switch(args, client: Client) -> None:
    started = time.monotonic()
    r = client.switch(
        args.instance,
        args.level,
        max_error=args.max_error,
        method=args.method,
        at_once=args.at_once,
        timeout=args.timeout,
    )
    c = r.coefficients
    print(
        f"{r.instance}: {level_str(r.previous)} -> {level_str(r.level)} ({r.method}), "
        f"predicted error {percent(r, 'predicted_error')} "
        f"({percent(r, 'predicted_error_under_input')} under input), dt {r.dt:.3e} s, "
        f"took {r.seconds:.3f} s ({'prepared' if r.cached else 'estimated now'}; "
        f"{time.monotonic() - started:.1f} s here), "
        f"coefficient version {r.coefficient_version}, frame {r.frame}"
    )
    if r.level.vertices or r.level.points:
        # A mesh's or a surface's springs are stretch and bend alone; the
        # other classes keep the prior's values and are not printed.
        print(f"  K/C stretch {c.structural_k:.4e}/{c.structural_c:.4e}  bend {c.bend_k:.4e}/{c.bend_c:.4e}")
        return
    (svk, svc), (bvk, bvc) = v_coefficients(c)
    print(
        f"  K/C structural u {c.structural_k:.4e}/{c.structural_c:.4e} v {svk:.4e}/{svc:.4e}  "
        f"shear {c.shear_k:.4e}/{c.shear_c:.4e}  "
        f"bend u {c.bend_k:.4e}/{c.bend_c:.4e} v {bvk:.4e}/{bvc:.4e}"
    )


def cmd_info(args, client: Client) -> None:
    i = client.info(args.instance, args.timeout)
    if i.kind == "surface":
        nodes = i.cloud_points
    elif i.level.vertices:
        # A mesh level: the simplifier lands near the asked count; its
        # vertices are what states carry.
        nodes = len(unpack_vec3(i.rest_positions))
    else:
        nodes = i.level.nx * i.level.ny
    print(f"{i.instance}: {i.kind or 'cloth'} scene {i.scene}  {i.description}".rstrip())
    print(
        f"  level {level_str(i.level)} ({nodes} published points, {len(i.triangles) // 3} triangles, "
        f"{len(i.pinned)} pinned)  reference {level_str(i.reference)}  method {i.method}  "
        f"integrator {i.integrator}  dt {i.dt:.3e} s  {i.publish_hz:g} Hz"
    )
    print(
        f"  O_max {i.o_max:.4f} m  shadow reference {'yes' if i.shadow_reference else 'no'}  "
        f"coefficient version {i.coefficient_version}"
        + ("  paused" if i.paused else "")
        + (f"  halted: {i.halted}" if i.halted else "")
    )
    for lv in i.levels:
        mark = "*" if lv.level == i.level else " "
        print(
            f"  {mark} {level_str(lv.level):<8} predicted {percent(lv, 'predicted_error'):>8}  "
            f"under input {percent(lv, 'predicted_error_under_input'):>8}  "
            f"dt {lv.dt:.3e} s  {'ready' if lv.ready else 'not prepared'}"
        )
    for k, c in enumerate(i.colliders):
        print(f"  collider {k}: {collider_str(c)}")


def collider_str(c) -> str:
    """One line of a scene's rigid body (``v1.Collider``)."""
    p = c.position
    size = {
        "sphere": f"radius {c.radius:g} m",
        "capsule": f"radius {c.radius:g} m, half axis ({c.axis.x:g}, {c.axis.y:g}, {c.axis.z:g}) m",
        "box": f"size {2 * c.half_extents.x:g} x {2 * c.half_extents.y:g} x {2 * c.half_extents.z:g} m",
        "plane": f"normal ({c.axis.x:g}, {c.axis.y:g}, {c.axis.z:g})",
        "cylinder": f"radius {c.radius:g} m, height {2 * c.axis.y:g} m",
    }.get(c.shape, "")
    return (
        f"{c.shape} at ({p.x:g}, {p.y:g}, {p.z:g}) m, {size}, friction {c.friction:g}, "
        f"clearance {c.clearance * 1000:g} mm"
    )


def cmd_control(args, client: Client) -> None:
    r = client.control(args.instance, args.action, args.timeout)
    print(f"{r.instance}: {args.action} done, {'paused' if r.paused else 'running'} at frame {r.frame}")


def cmd_health(args, client: Client) -> None:
    try:
        infos = client.health(args.instance, args.timeout)
    except LodclothError as e:
        raise LodclothError(f"unhealthy: {e}") from None
    for i in infos:
        print(f"{i.instance}: ok, level {level_str(i.level)}, {i.method}")


COMMANDS = {
    "list": cmd_list,
    "watch": cmd_watch,
    "switch": cmd_switch,
    "info": cmd_info,
    "control": cmd_control,
    "health": cmd_health,
}


def main(argv: Optional[List[str]] = None) -> int:
    args = parse_args(argv)
    try:
        with Client.open(options(args)) as client:
            COMMANDS[args.command](args, client)
    except LodclothError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
