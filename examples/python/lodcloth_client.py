#!/usr/bin/env python3
"""A minimal lodcloth client in Python, built from the .proto file alone.

It talks to a running `lodcloth serve` daemon over Eclipse Zenoh, the way a
client in any other language would: the key expressions and messages are the
ones documented in proto/lodcloth/v1/lodcloth.proto.

The protobuf classes are made at run time: protoc (from the grpcio-tools
wheel) compiles the .proto into a descriptor set in a temporary directory,
and protobuf builds the message classes from it. No generated code is kept.

    python lodcloth_client.py list
    python lodcloth_client.py watch paper-1 --count 5
    python lodcloth_client.py switch paper-1 --level 16x16
    python lodcloth_client.py switch paper-1 --max-error 0.05
"""

from __future__ import annotations

import argparse
import os
import queue
import struct
import sys
import tempfile
import time
from pathlib import Path

import zenoh
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError
from grpc_tools import protoc

# The .proto sits at <repo>/proto/lodcloth/v1/lodcloth.proto; this file at
# <repo>/examples/python/. Override with --proto or LODCLOTH_PROTO.
DEFAULT_PROTO = Path(__file__).resolve().parents[2] / "proto" / "lodcloth" / "v1" / "lodcloth.proto"
PACKAGE = "lodcloth.v1"


class ClientError(Exception):
    """A failure to report to the user (exit status 1)."""


# --------------------------------------------------------------------------
# protobuf: message classes from the .proto, no generated code
# --------------------------------------------------------------------------


class Messages:
    """The lodcloth.v1 message classes, by name: msgs.State, msgs.Error, ..."""

    def __init__(self, proto: Path):
        if not proto.is_file():
            raise ClientError(f"no .proto at {proto}; pass --proto PATH")
        with tempfile.TemporaryDirectory(prefix="lodcloth-proto-") as tmp:
            out = Path(tmp) / "lodcloth.desc"
            code = protoc.main(
                ["protoc", f"-I{proto.parent}", f"--descriptor_set_out={out}", str(proto)]
            )
            if code != 0:
                raise ClientError(f"protoc failed on {proto} (exit {code})")
            files = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes())
        pool = descriptor_pool.DescriptorPool()
        for f in files.file:
            pool.Add(f)
        self._pool = pool

    def __getattr__(self, name: str):
        desc = self._pool.FindMessageTypeByName(f"{PACKAGE}.{name}")
        cls = message_factory.GetMessageClass(desc)
        setattr(self, name, cls)
        return cls


def encoding(message_name: str) -> zenoh.Encoding:
    """The zenoh encoding of a lodcloth message: application/protobuf;lodcloth.v1.<Name>."""
    return zenoh.Encoding(f"application/protobuf;{PACKAGE}.{message_name}")


# --------------------------------------------------------------------------
# formatting helpers
# --------------------------------------------------------------------------


def level_str(level) -> str:
    """A grid cloth as NXxNY, a point-sampled surface as Npts."""
    return f"{level.points}pts" if level.points else f"{level.nx}x{level.ny}"


def parse_level(text: str) -> tuple[int, int, int]:
    """(nx, ny, points): NXxNY for a cloth, N or Npts for a surface."""
    t = text.lower().strip()
    try:
        if "x" in t:
            nx, ny = (int(v) for v in t.split("x"))
            points = 0
        else:
            nx, ny, points = 0, 0, int(t.removesuffix("pts"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"level '{text}' is not NXxNY (a cloth, e.g. 16x16) or N (a surface's points, e.g. 300)"
        ) from None
    if min(nx, ny) < 0 or (points == 0 and min(nx, ny) < 1) or points < 0:
        raise argparse.ArgumentTypeError(f"level '{text}' must have positive sizes")
    return nx, ny, points


def pct(msg, field: str) -> str:
    """An optional relative-error field as a percentage, or '-' when absent."""
    return f"{100 * getattr(msg, field):.2f} %" if msg.HasField(field) else "-"


def positions(state) -> list[tuple[float, float, float]]:
    """State.positions: packed little-endian f32 x y z per node."""
    raw = state.positions
    if len(raw) % 12:
        raise ClientError(f"state frame {state.frame}: {len(raw)} position bytes, not a multiple of 12")
    return list(struct.iter_unpack("<3f", raw))


def lodcloth_error(msgs: Messages, err: zenoh.ReplyError):
    """The lodcloth.v1.Error of an error reply, or None when zenoh itself
    answered (e.g. "Timeout", encoded as a zenoh/string)."""
    if not str(err.encoding).startswith("application/protobuf"):
        return None
    try:
        return msgs.Error.FromString(err.payload.to_bytes())
    except Exception:  # noqa: BLE001 - not an Error after all
        return None


def error_text(msgs: Messages, err: zenoh.ReplyError) -> str:
    e = lodcloth_error(msgs, err)
    if e is not None:
        return f"{msgs.Error.Code.Name(e.code)}: {e.message}"
    return err.payload.to_bytes().decode("utf-8", "replace") or "(empty error reply)"


# --------------------------------------------------------------------------
# zenoh
# --------------------------------------------------------------------------


def open_session(connect: str) -> zenoh.Session:
    """Client mode, connected to `connect`, multicast scouting off."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", f'["{connect}"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    try:
        return zenoh.open(config)
    except zenoh.ZError as e:
        raise ClientError(f"cannot connect to {connect}: {e}") from None


def query(session, key: str, timeout: float, **kwargs) -> tuple[list, list]:
    """All replies to `key` within `timeout` s: (ok samples, error replies)."""
    ok, errors = [], []
    replies = session.get(key, timeout=timeout, target=zenoh.QueryTarget.ALL, **kwargs)
    for reply in replies:  # ends when every queryable has answered or at the timeout
        if reply.ok is not None:
            ok.append(reply.ok)
        else:
            errors.append(reply.err)
    return ok, errors


# --------------------------------------------------------------------------
# commands
# --------------------------------------------------------------------------


def cmd_list(args, session, msgs: Messages) -> None:
    key = f"{args.prefix}/instances"
    # One reply per daemon, all on the same key: don't let zenoh consolidate them.
    ok, errors = query(session, key, args.timeout, consolidation=zenoh.ConsolidationMode.NONE)
    for err in errors:
        print(f"error reply from {key}: {error_text(msgs, err)}", file=sys.stderr)
    if not ok:
        raise ClientError(f"no daemon answered {key} within {args.timeout} s")
    for sample in ok:
        lst = msgs.InstanceList.FromString(sample.payload.to_bytes())
        print(f"daemon {lst.daemon}: {len(lst.instances)} instance(s)")
        for i in lst.instances:
            print(
                f"  {i.instance:<10} level {level_str(i.level):<7} method {i.method:<5} "
                f"{i.publish_hz:4g} Hz  scene {i.scene}"
            )


def cmd_watch(args, session, msgs: Messages) -> None:
    state_key = f"{args.prefix}/{args.instance}/state"
    metrics_key = f"{args.prefix}/{args.instance}/metrics"
    # Callbacks run on zenoh's threads; hand the samples to this thread.
    inbox: queue.Queue = queue.Queue(maxsize=1000)

    def enqueue(kind):
        def callback(sample):
            try:
                inbox.put_nowait((kind, sample.payload.to_bytes()))
            except queue.Full:
                pass  # this thread is behind; drop rather than block zenoh

        return callback

    subs = [
        session.declare_subscriber(state_key, enqueue("state")),
        session.declare_subscriber(metrics_key, enqueue("metrics")),
    ]
    seen = {"state": 0, "metrics": 0}
    try:
        # Stop after `count` messages of each kind.
        while min(seen.values()) < args.count:
            try:
                kind, raw = inbox.get(timeout=args.timeout)
            except queue.Empty:
                raise ClientError(
                    f"nothing on {state_key} or {metrics_key} for {args.timeout} s "
                    f"(states {seen['state']}, metrics {seen['metrics']}); "
                    f"is '{args.instance}' running? try `list`"
                ) from None
            if seen[kind] >= args.count:
                continue
            seen[kind] += 1
            if kind == "state":
                s = msgs.State.FromString(raw)
                pos = positions(s)
                # A surface publishes its whole cloud (and the simulated points apart).
                expected = s.level.nx * s.level.ny if not s.level.points else len(pos)
                if len(pos) != expected:
                    raise ClientError(f"state frame {s.frame}: {len(pos)} nodes for level {level_str(s.level)}")
                # Node k sits at grid column k % nx, row k / nx.
                first, last = (pos[0], pos[-1]) if pos else ((float("nan"),) * 3,) * 2
                print(
                    f"state   frame {s.frame:>7}  t {s.time:8.3f} s  level {level_str(s.level):<7} "
                    f"nodes {len(pos):>5}  first ({first[0]:+.3f}, {first[1]:+.3f}, {first[2]:+.3f}) m  "
                    f"last ({last[0]:+.3f}, {last[1]:+.3f}, {last[2]:+.3f}) m"
                    + ("  [transition]" if s.transition else "")
                )
            else:
                m = msgs.Metrics.FromString(raw)
                print(
                    f"metrics frame {m.frame:>7}  t {m.time:8.3f} s  level {level_str(m.level):<7} "
                    f"predicted {pct(m, 'predicted_error'):>8}  live {pct(m, 'live_error'):>8}  "
                    f"RTF {m.real_time_factor:.3f}"
                )
    finally:
        for sub in subs:
            sub.undeclare()


def cmd_switch(args, session, msgs: Messages) -> None:
    key = f"{args.prefix}/{args.instance}/switch"
    req = msgs.SwitchRequest(method=args.method or "")
    if args.level is not None:
        req.level.nx, req.level.ny, req.level.points = args.level
    else:
        req.max_error = args.max_error
    started = time.monotonic()
    ok, errors = query(
        session,
        key,
        args.timeout,
        payload=req.SerializeToString(),
        encoding=encoding("SwitchRequest"),
    )
    if ok:
        r = msgs.SwitchReply.FromString(ok[0].payload.to_bytes())
        c = r.coefficients
        print(
            f"{r.instance}: {level_str(r.previous)} -> {level_str(r.level)} ({r.method}), "
            f"predicted error {pct(r, 'predicted_error')}, dt {r.dt:.3e} s, "
            f"took {r.seconds:.3f} s ({'prepared' if r.cached else 'estimated now'}), "
            f"coefficient version {r.coefficient_version}, frame {r.frame}"
        )
        # Along v where the level's cells are not square (absent: as along u).
        sv = (c.structural_v_k, c.structural_v_c) if c.HasField("structural_v_k") else (c.structural_k, c.structural_c)
        bv = (c.bend_v_k, c.bend_v_c) if c.HasField("bend_v_k") else (c.bend_k, c.bend_c)
        print(
            f"  K/C structural u {c.structural_k:.4e}/{c.structural_c:.4e} v {sv[0]:.4e}/{sv[1]:.4e}  "
            f"shear {c.shear_k:.4e}/{c.shear_c:.4e}  "
            f"bend u {c.bend_k:.4e}/{c.bend_c:.4e} v {bv[0]:.4e}/{bv[1]:.4e}"
        )
        return
    refusals = [err for err in errors if lodcloth_error(msgs, err) is not None]
    if refusals:
        raise ClientError(f"switch refused: {error_text(msgs, refusals[0])}")
    waited = time.monotonic() - started
    detail = f" (zenoh: {error_text(msgs, errors[0])})" if errors else ""
    raise ClientError(
        f"no reply from {key} within {waited:.1f} s{detail}; "
        "an unprepared level may need a longer --timeout, or no daemon serves it (try `list`)"
    )


# --------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--connect", default="tcp/127.0.0.1:7450", help="zenoh endpoint of the daemon (default %(default)s)")
    p.add_argument("--prefix", default="lodcloth", help="key expression prefix (default %(default)s)")
    p.add_argument(
        "--proto",
        type=Path,
        default=Path(os.environ.get("LODCLOTH_PROTO", DEFAULT_PROTO)),
        help="path to lodcloth.proto (default: $LODCLOTH_PROTO or the repository's)",
    )
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("list", help="list every reachable daemon's instances")
    s.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for replies (default %(default)s)")

    s = sub.add_parser("watch", help="print an instance's states and metrics")
    s.add_argument("instance")
    s.add_argument("--count", type=int, default=10, help="stop after N states and N metrics (default %(default)s)")
    s.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for each message (default %(default)s)")

    s = sub.add_parser("switch", help="switch an instance to another level")
    s.add_argument("instance")
    target = s.add_mutually_exclusive_group(required=True)
    target.add_argument("--level", type=parse_level, help="target level, e.g. 16x16")
    target.add_argument("--max-error", type=float, help="cheapest level with at most this relative error (0.05 = 5 %%)")
    s.add_argument("--method", help="estimation method (same, bcd, gkd, lsq, fit); default: the instance's")
    s.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        help="seconds to wait for the reply; an unprepared level is estimated first (default %(default)s)",
    )
    args = p.parse_args(argv)
    if getattr(args, "count", 1) < 1:
        p.error("--count must be at least 1")
    if args.timeout <= 0:
        p.error("--timeout must be positive")
    return args


COMMANDS = {"list": cmd_list, "watch": cmd_watch, "switch": cmd_switch}


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        msgs = Messages(args.proto)
        session = open_session(args.connect)
        try:
            COMMANDS[args.command](args, session, msgs)
        finally:
            session.close()
    except ClientError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except DecodeError as e:
        print(f"error: undecodable payload (does {args.proto} match the daemon's?): {e}", file=sys.stderr)
        return 1
    except zenoh.ZError as e:
        print(f"error: zenoh: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
