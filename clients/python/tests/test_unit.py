"""Unit tests that need no daemon: messages, levels, packed coordinates,
encodings, refusals, connect options, the command line's arguments.

    python -m unittest discover -s clients/python/tests -v
"""

from __future__ import annotations

import json
import math
import os
import re
import struct
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

import lodcloth_client as lc
from lodcloth_client import cli, keys, v1
from lodcloth_client.codec import ACTIONS

REPO = Path(__file__).resolve().parents[3]


class GeneratedCode(unittest.TestCase):
    def test_messages_carry_the_contract_names(self):
        self.assertEqual(v1.DESCRIPTOR.name, "lodcloth/v1/lodcloth.proto")
        self.assertEqual(v1.DESCRIPTOR.package, "lodcloth.v1")
        for name in [
            "State",
            "Metrics",
            "InstanceInfo",
            "InstanceList",
            "SwitchRequest",
            "SwitchReply",
            "ControlRequest",
            "ControlReply",
            "Error",
            "Level",
            "LevelInfo",
            "InstanceSummary",
            "Coefficients",
        ]:
            self.assertEqual(getattr(v1, name).DESCRIPTOR.full_name, f"lodcloth.v1.{name}")
        self.assertEqual(v1.State.__module__, "lodcloth_client.v1.lodcloth_pb2")

    def test_the_daemons_schema_names_are_the_messages(self):
        # The daemon's encodings name these schemas (src/proto.rs, `schema`).
        src = REPO / "src" / "proto.rs"
        if not src.is_file():
            self.skipTest(f"{src} not here (tests run outside the repository)")
        schemas = re.findall(r'pub const \w+: &str = "(lodcloth\.v1\.\w+)";', src.read_text())
        self.assertGreaterEqual(len(schemas), 9)
        for schema in schemas:
            cls = getattr(v1, schema.rsplit(".", 1)[1])
            self.assertEqual(cls.DESCRIPTOR.full_name, schema)

    def test_no_protoc_at_run_time(self):
        # Importing the package compiles nothing: grpc_tools is not imported
        # (and need not be installed).
        code = "import sys, lodcloth_client, lodcloth_client.cli; sys.exit('grpc_tools' in sys.modules)"
        subprocess.run([sys.executable, "-c", code], check=True)

    def test_a_state_round_trips(self):
        pts = [(0.0, 1.0, 2.0), (-0.5, 0.25, 3.5), (1.5, -2.0, 0.125), (4.0, 5.0, -6.0)]
        s = v1.State(instance="hanging", frame=7, time=0.5, level=v1.Level(nx=2, ny=2), positions=lc.pack_vec3(pts))
        back = lc.decode(v1.State, s.SerializeToString(), "application/protobuf;lodcloth.v1.State", "k")
        self.assertEqual(back, s)
        self.assertEqual(lc.positions(back), pts)


class Encodings(unittest.TestCase):
    def test_encoding_names_the_message(self):
        self.assertEqual(lc.encoding_of(v1.SwitchRequest()), "application/protobuf;lodcloth.v1.SwitchRequest")
        self.assertEqual(lc.encoding_of(v1.State), "application/protobuf;lodcloth.v1.State")
        self.assertEqual(lc.encoding_of("Metrics"), "application/protobuf;lodcloth.v1.Metrics")

    def test_schema_of(self):
        self.assertEqual(lc.schema_of("application/protobuf;lodcloth.v1.State"), "lodcloth.v1.State")
        self.assertIsNone(lc.schema_of("application/protobuf"))
        self.assertIsNone(lc.schema_of("zenoh/string"))
        self.assertIsNone(lc.schema_of(None))

    def test_decode_rejects_another_message(self):
        m = v1.Metrics(instance="x", frame=3)
        with self.assertRaises(lc.DecodeError) as ctx:
            lc.decode(v1.State, m.SerializeToString(), lc.encoding_of(m), "lodcloth/x/state")
        self.assertIn("lodcloth.v1.Metrics", str(ctx.exception))
        self.assertIn("lodcloth/x/state", str(ctx.exception))

    def test_decode_rejects_garbage(self):
        with self.assertRaises(lc.DecodeError):
            lc.decode(v1.State, b"\xff\xff\xff", None, "k")

    def test_decode_without_a_schema(self):
        # No encoding (or one without a schema): decoded as asked.
        s = v1.State(frame=1)
        self.assertEqual(lc.decode(v1.State, s.SerializeToString()).frame, 1)


class Refusals(unittest.TestCase):
    def test_a_refusal_names_code_and_message(self):
        e = v1.Error(code=v1.Error.CODE_UNKNOWN_INSTANCE, message="no instance 'nope'")
        r = lc.refusal(e.SerializeToString(), lc.encoding_of(e), "lodcloth/nope/switch")
        self.assertIsInstance(r, lc.RefusedError)
        self.assertEqual(r.code, v1.Error.CODE_UNKNOWN_INSTANCE)
        self.assertEqual(r.code_name, "CODE_UNKNOWN_INSTANCE")
        self.assertEqual(r.message, "no instance 'nope'")
        self.assertEqual(str(r), "lodcloth/nope/switch refused: CODE_UNKNOWN_INSTANCE: no instance 'nope'")

    def test_zenohs_own_errors_are_not_refusals(self):
        self.assertIsNone(lc.refusal(b"Timeout", "zenoh/string"))
        self.assertIsNone(lc.refusal(b"", "application/protobuf;lodcloth.v1.State"))

    def test_a_code_newer_than_the_package(self):
        self.assertEqual(lc.code_name(99), "code 99")
        e = v1.Error(code=99, message="new")
        self.assertEqual(
            lc.refusal(e.SerializeToString(), "application/protobuf;lodcloth.v1.Error").code_name, "code 99"
        )

    def test_no_reply_names_the_key(self):
        e = lc.NoReplyError("lodcloth/x/switch", 2.5, "Timeout")
        self.assertIn("lodcloth/x/switch", str(e))
        self.assertIn("2.5 s", str(e))
        self.assertIn("Timeout", str(e))
        self.assertIsInstance(lc.NoDataError(["a"], 1.0), TimeoutError)


class Levels(unittest.TestCase):
    def test_parse(self):
        self.assertEqual(lc.parse_level("16x16"), v1.Level(nx=16, ny=16))
        self.assertEqual(lc.parse_level(" 24X12 "), v1.Level(nx=24, ny=12))
        self.assertEqual(lc.parse_level("300"), v1.Level(points=300))
        self.assertEqual(lc.parse_level("85pts"), v1.Level(points=85))
        self.assertEqual(lc.parse_level(300), v1.Level(points=300))
        self.assertEqual(lc.parse_level((8, 4)), v1.Level(nx=8, ny=4))
        self.assertEqual(lc.parse_level("504v"), v1.Level(vertices=504))
        lvl = v1.Level(nx=3, ny=3)
        self.assertIs(lc.parse_level(lvl), lvl)

    def test_parse_refuses_nonsense(self):
        for bad in ["", "x", "16x", "axb", "0x16", "-3", "0", "1x2x3", "12.5", "v", "0v", True, (1,), 2.0]:
            with self.subTest(bad=bad), self.assertRaises(ValueError):
                lc.parse_level(bad)

    def test_make_level_is_one_kind(self):
        with self.assertRaises(ValueError):
            lc.make_level(nx=4, ny=4, points=10)
        with self.assertRaises(ValueError):
            lc.make_level(points=10, vertices=10)

    def test_format(self):
        self.assertEqual(lc.level_str(v1.Level(nx=16, ny=8)), "16x8")
        self.assertEqual(lc.level_str(v1.Level(points=85)), "85pts")
        self.assertEqual(lc.level_str(v1.Level(vertices=504)), "504v")
        for text in ["16x16", "85pts", "504v"]:
            self.assertEqual(lc.level_str(lc.parse_level(text)), text)


class Coordinates(unittest.TestCase):
    def test_pack_and_unpack(self):
        pts = [(1.0, 2.0, 3.0), (-1.5, 0.0, 1e-3)]
        raw = lc.pack_vec3(pts)
        self.assertEqual(len(raw), 24)
        self.assertEqual(raw[:4], b"\x00\x00\x80\x3f")  # 1.0f, little-endian
        back = lc.unpack_vec3(raw)
        self.assertEqual(back[0], pts[0])
        self.assertTrue(math.isclose(back[1][2], 1e-3, rel_tol=1e-6))

    def test_unpack_refuses_a_partial_point(self):
        with self.assertRaises(ValueError):
            lc.unpack_vec3(b"\x00" * 13)
        with self.assertRaises(ValueError):
            lc.pack_vec3([(1.0, 2.0)])

    def test_material_coordinates_pair_with_the_rest_positions(self):
        info = v1.InstanceInfo(
            instance="m",
            rest_positions=lc.pack_vec3([(0, 0, 0)] * 2),
            material_uv=struct.pack("<4f", 0.25, 0.5, 1.0, 0.0),
        )
        self.assertEqual(lc.material_uv(info), [(0.25, 0.5), (1.0, 0.0)])
        info.material_uv = struct.pack("<2f", 0.25, 0.5)
        with self.assertRaises(lc.DecodeError) as ctx:
            lc.material_uv(info)
        self.assertIn("1 material coordinates for 2 nodes", str(ctx.exception))
        info.material_uv = b"\x00" * 12
        with self.assertRaises(lc.DecodeError):
            lc.material_uv(info)

    def test_positions_checked_against_the_level(self):
        s = v1.State(instance="c", level=v1.Level(nx=2, ny=2), positions=lc.pack_vec3([(0, 0, 0)] * 3))
        with self.assertRaises(lc.DecodeError) as ctx:
            lc.positions(s)
        self.assertIn("3 nodes for level 2x2", str(ctx.exception))
        # A surface publishes its whole cloud, whatever the level's point count.
        s = v1.State(level=v1.Level(points=2), positions=lc.pack_vec3([(0, 0, 0)] * 5))
        self.assertEqual(len(lc.positions(s)), 5)


class Requests(unittest.TestCase):
    def test_switch_to_a_level(self):
        r = lc.switch_request("24x24", method="fit")
        self.assertEqual(r.WhichOneof("target"), "level")
        self.assertEqual(r.level, v1.Level(nx=24, ny=24))
        self.assertEqual(r.method, "fit")
        again = v1.SwitchRequest.FromString(r.SerializeToString())
        self.assertEqual(again, r)

    def test_switch_at_once(self):
        r = lc.switch_request("24x24", at_once=True)
        self.assertTrue(r.at_once)
        self.assertTrue(v1.SwitchRequest.FromString(r.SerializeToString()).at_once)
        self.assertFalse(lc.switch_request("24x24").at_once)
        with self.assertRaises(ValueError):
            lc.switch_request(max_error=0.05, at_once=True)

    def test_switch_by_error(self):
        r = lc.switch_request(max_error=0.05)
        self.assertEqual(r.WhichOneof("target"), "max_error")
        self.assertEqual(r.max_error, 0.05)
        self.assertEqual(r.method, "")

    def test_switch_needs_one_target(self):
        with self.assertRaises(ValueError):
            lc.switch_request()
        with self.assertRaises(ValueError):
            lc.switch_request("16x16", max_error=0.05)
        for bad in [0.0, -0.1, float("nan"), float("inf")]:
            with self.subTest(bad=bad), self.assertRaises(ValueError):
                lc.switch_request(max_error=bad)

    def test_control(self):
        self.assertEqual(lc.control_request("pause").action, v1.ControlRequest.ACTION_PAUSE)
        self.assertEqual(lc.control_request("RESET").action, v1.ControlRequest.ACTION_RESET)
        self.assertEqual(lc.control_request(v1.ControlRequest.ACTION_RESUME).action, v1.ControlRequest.ACTION_RESUME)
        with self.assertRaises(ValueError):
            lc.control_request("stop")
        with self.assertRaises(ValueError):
            lc.control_request(0)
        self.assertEqual(sorted(ACTIONS), ["pause", "reset", "resume"])

    def test_inputs(self):
        g = lc.grab_request(0.5, 1.0, (0.1, -0.2, 0.3), id=4, stiffness=30.0, radius=0.05)
        self.assertEqual(g.WhichOneof("action"), "grab")
        self.assertEqual((g.grab.id, g.grab.at.u, g.grab.at.v, g.grab.at.radius), (4, 0.5, 1.0, 0.05))
        self.assertEqual((g.grab.target.x, g.grab.target.y, g.grab.target.z), (0.1, -0.2, 0.3))
        self.assertEqual((g.grab.stiffness, g.grab.damping), (30.0, 0.2))
        self.assertFalse(lc.grab_request(0.5, 0.5).grab.HasField("target"))
        self.assertEqual(lc.move_request([1, 2, 3], id=4).move.target.z, 3.0)
        self.assertEqual(lc.release_request(4).WhichOneof("action"), "release")
        self.assertEqual(lc.release_request().WhichOneof("action"), "release_all")
        self.assertEqual(lc.wind_request(None).WhichOneof("action"), "scene_wind")
        w = lc.wind_request((0, 0, 3), gust=0.3, gust_hz=0.5)
        self.assertEqual((w.wind.velocity.z, w.wind.gust, w.wind.gust_hz), (3.0, 0.3, 0.5))
        self.assertEqual(lc.impulse_request(0.2, 0.3, (0, 0, 0.01)).impulse.at.radius, 0.05)
        self.assertEqual(lc.move_pin_request(0, (0, 0.1, 0), seconds=2).move_pin.seconds, 2.0)
        # It crosses the wire whole.
        self.assertEqual(v1.InputRequest.FromString(g.SerializeToString()), g)
        with self.assertRaises(ValueError):
            lc.grab_request(0.5, 0.5, (1, 2))

    def test_optional_fields(self):
        m = v1.Metrics()
        self.assertIsNone(lc.optional(m, "predicted_error"))
        self.assertEqual(lc.percent(m, "predicted_error"), "-")
        m.predicted_error = 0.0123
        self.assertEqual(lc.optional(m, "predicted_error"), 0.0123)
        self.assertEqual(lc.percent(m, "predicted_error"), "1.23 %")

    def test_v_coefficients_default_to_u(self):
        c = v1.Coefficients(structural_k=1, structural_c=2, bend_k=5, bend_c=6)
        self.assertEqual(lc.v_coefficients(c), ((1, 2), (5, 6)))
        c.structural_v_k, c.structural_v_c, c.bend_v_k, c.bend_v_c = 10, 20, 50, 60
        self.assertEqual(lc.v_coefficients(c), ((10, 20), (50, 60)))


class Colliders(unittest.TestCase):
    def test_a_collider_is_described_by_its_shape(self):
        box = v1.Collider(
            shape="box",
            position=v1.Vec3(x=0.8, y=-0.395, z=0.8),
            half_extents=v1.Vec3(x=0.5, y=0.375, z=0.5),
            friction=0.4,
            clearance=0.005,
        )
        self.assertEqual(
            cli.collider_str(box),
            "box at (0.8, -0.395, 0.8) m, size 1 x 0.75 x 1 m, friction 0.4, clearance 5 mm",
        )
        ball = v1.Collider(shape="sphere", position=v1.Vec3(), radius=0.15, friction=0.5, clearance=0.004)
        self.assertIn("radius 0.15 m", cli.collider_str(ball))


class Keys(unittest.TestCase):
    def test_the_contracts_table(self):
        self.assertEqual(keys.state("lodcloth", "a"), "lodcloth/a/state")
        self.assertEqual(keys.metrics("lodcloth", "a"), "lodcloth/a/metrics")
        self.assertEqual(keys.info("p", "a"), "p/a/info")
        self.assertEqual(keys.switch("p", "a"), "p/a/switch")
        self.assertEqual(keys.control("p", "a"), "p/a/control")
        self.assertEqual(keys.input("p", "a"), "p/a/input")
        self.assertEqual(keys.inputs("p", "a"), "p/a/inputs")
        self.assertEqual(keys.episode_inputs("p", "a"), "p/a/episode_inputs")
        self.assertEqual(keys.instances("p"), "p/instances")
        self.assertEqual(keys.alive("p", "*"), "p/alive/*")

    def test_instance_names_come_back_out_of_their_keys(self):
        # The same cases as src/service/keys.rs.
        self.assertEqual(keys.instance_of("lodcloth", "switch", "lodcloth/a-1/switch"), "a-1")
        self.assertEqual(keys.instance_of("a/b", "info", "a/b/x/info"), "x")
        self.assertIsNone(keys.instance_of("lodcloth", "switch", "lodcloth/*/switch"))
        self.assertIsNone(keys.instance_of("lodcloth", "switch", "lodcloth/x/y/switch"))
        self.assertIsNone(keys.instance_of("lodcloth", "switch", "other/x/switch"))
        self.assertEqual(keys.alive_instance("lodcloth", keys.alive("lodcloth", "h")), "h")


def cfg(config, key):
    """A zenoh config value (get_json answers JSON text)."""
    return json.loads(config.get_json(key))


class Options(unittest.TestCase):
    def test_defaults_are_the_rust_clis(self):
        o = lc.ConnectOptions()
        self.assertEqual(o.connect, ["tcp/127.0.0.1:7450"])
        self.assertEqual(o.prefix, "lodcloth")
        self.assertFalse(o.client_mode)
        c = o.zenoh_config()
        self.assertEqual(cfg(c, "mode"), "peer")
        self.assertEqual(cfg(c, "connect/endpoints"), ["tcp/127.0.0.1:7450"])
        self.assertEqual(cfg(c, "listen/endpoints"), [])
        self.assertIs(cfg(c, "scouting/multicast/enabled"), False)

    def test_credentials_and_certificates(self):
        with tempfile.TemporaryDirectory() as d:
            files = {}
            for name in ["ca.pem", "me.pem", "me.key"]:
                files[name] = Path(d, name)
                files[name].write_text("-----BEGIN-----\n")
            o = lc.ConnectOptions(
                connect=["tls/localhost:7450"],
                client_mode=True,
                user="op",
                password="Secret-Pass-1",
                tls_ca=files["ca.pem"],
                tls_cert=files["me.pem"],
                tls_key=str(files["me.key"]),
            )
            self.assertNotIn("Secret-Pass-1", repr(o))
            c = o.zenoh_config()
            self.assertEqual(cfg(c, "mode"), "client")
            self.assertEqual(cfg(c, "transport/auth/usrpwd/user"), "op")
            self.assertEqual(cfg(c, "transport/auth/usrpwd/password"), "Secret-Pass-1")
            self.assertEqual(cfg(c, "transport/link/tls/root_ca_certificate"), str(files["ca.pem"]))
            self.assertEqual(cfg(c, "transport/link/tls/connect_certificate"), str(files["me.pem"]))
            self.assertEqual(cfg(c, "transport/link/tls/connect_private_key"), str(files["me.key"]))
            self.assertIs(cfg(c, "transport/link/tls/enable_mtls"), True)

    def test_problems_are_named(self):
        o = lc.ConnectOptions(user="op", tls_cert="/nonexistent/me.pem", connect=[], client_mode=True)
        with self.assertRaises(lc.ConnectError) as ctx:
            o.zenoh_config()
        text = str(ctx.exception)
        for part in [
            "user and password go together",
            "tls_cert and tls_key go together",
            "/nonexistent/me.pem is not a readable file",
            "client mode needs an endpoint",
        ]:
            self.assertIn(part, text)

    def test_environment(self):
        env = {
            "LODCLOTH_CONNECT": "tcp/10.0.0.1:7450, tcp/10.0.0.2:7450",
            "LODCLOTH_CLIENT_MODE": "true",
            "LODCLOTH_USER": "op",
            "LODCLOTH_PASSWORD": "pw",
        }
        o = lc.ConnectOptions.from_env(env)
        self.assertEqual(o.connect, ["tcp/10.0.0.1:7450", "tcp/10.0.0.2:7450"])
        self.assertTrue(o.client_mode)
        self.assertEqual((o.user, o.password), ("op", "pw"))
        o = lc.ConnectOptions.from_env(env, connect=["tcp/127.0.0.1:1"], client_mode=False, user=None)
        self.assertEqual(o.connect, ["tcp/127.0.0.1:1"])
        self.assertFalse(o.client_mode)
        self.assertEqual(o.user, "op")  # None: not overridden
        with self.assertRaises(lc.ConnectError):
            lc.ConnectOptions.from_env({"LODCLOTH_CLIENT_MODE": "maybe"})
        with self.assertRaises(TypeError):
            lc.ConnectOptions.from_env({}, nonsense=1)

    def test_client_mode_without_a_daemon_fails_clearly(self):
        # Nothing listens on port 1 of loopback: a client-mode session cannot open.
        with self.assertRaises(lc.ConnectError) as ctx:
            lc.Client.open(connect=["tcp/127.0.0.1:1"], client_mode=True)
        self.assertIn("tcp/127.0.0.1:1", str(ctx.exception))


class CommandLine(unittest.TestCase):
    def test_subcommands_of_the_example(self):
        a = cli.parse_args(
            ["--connect", "tcp/127.0.0.1:7450", "switch", "hanging", "--level", "24x24", "--timeout", "300"]
        )
        self.assertEqual(a.command, "switch")
        self.assertEqual(a.level, v1.Level(nx=24, ny=24))
        self.assertEqual(a.timeout, 300.0)
        self.assertEqual(a.connect, ["tcp/127.0.0.1:7450"])
        a = cli.parse_args(["switch", "paper-1", "--max-error", "0.05"])
        self.assertEqual(a.max_error, 0.05)
        a = cli.parse_args(["watch", "sphere", "--count", "3"])
        self.assertEqual((a.instance, a.count, a.timeout), ("sphere", 3, 5.0))
        a = cli.parse_args(["list"])
        self.assertEqual(a.command, "list")
        a = cli.parse_args(["control", "hanging", "pause"])
        self.assertEqual(a.action, "pause")

    def test_bad_arguments_exit_2(self):
        for argv in [
            ["switch", "x"],
            ["switch", "x", "--level", "16x"],
            ["switch", "x", "--level", "4x4", "--max-error", "0.1"],
            ["watch", "x", "--count", "0"],
            ["list", "--timeout", "-1"],
            ["control", "x", "stop"],
            [],
        ]:
            with self.subTest(argv=argv):
                with self.assertRaises(SystemExit) as ctx, open(os.devnull, "w") as null:
                    err, sys.stderr = sys.stderr, null
                    try:
                        cli.parse_args(argv)
                    finally:
                        sys.stderr = err
                self.assertEqual(ctx.exception.code, 2)

    def test_command_line_options_override_the_environment(self):
        a = cli.parse_args(["--connect", "tcp/127.0.0.1:9", "--user", "u", "--password", "p", "list"])
        old = dict(os.environ)
        try:
            os.environ["LODCLOTH_CONNECT"] = "tcp/127.0.0.1:8"
            os.environ["LODCLOTH_CLIENT_MODE"] = "1"
            o = cli.options(a)
        finally:
            os.environ.clear()
            os.environ.update(old)
        self.assertEqual(o.connect, ["tcp/127.0.0.1:9"])
        self.assertTrue(o.client_mode)
        self.assertEqual((o.user, o.password), ("u", "p"))

    def test_a_failure_prints_error_and_exits_1(self):
        r = subprocess.run(
            [sys.executable, "-m", "lodcloth_client", "--connect", "tcp/127.0.0.1:1", "--client-mode", "list"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        self.assertEqual(r.returncode, 1, r.stderr)
        self.assertTrue(r.stderr.startswith("error: "), r.stderr)


if __name__ == "__main__":
    unittest.main()
