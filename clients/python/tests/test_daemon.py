"""End-to-end tests against a live daemon running the default config
(config/default.toml: hanging, paper-1..3, skirt, sphere). Skipped unless
LODCLOTH_DAEMON names its endpoint:

    LODCLOTH_DAEMON=tcp/127.0.0.1:7450 python -m unittest discover -s clients/python/tests -v

They read and query, and pause/resume `hanging` briefly; the slow switch to
an unprepared level is left to the command-line smoke test
(.ci/daemon-smoke.sh).
"""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
import unittest

import lodcloth_client as lc
from lodcloth_client import v1

ENDPOINT = os.environ.get("LODCLOTH_DAEMON", "")
SKIP = "set LODCLOTH_DAEMON=<endpoint of a live `lodcloth serve`> (e.g. tcp/127.0.0.1:7450) to run the daemon tests"


@unittest.skipUnless(ENDPOINT, SKIP)
class LiveDaemon(unittest.TestCase):
    client: lc.Client

    @classmethod
    def setUpClass(cls):
        cls.client = lc.Client.open(connect=lc.options.split_endpoints(ENDPOINT), timeout=10.0)

    @classmethod
    def tearDownClass(cls):
        cls.client.close()

    def test_list_names_the_default_configs_instances(self):
        lists = self.client.list()
        self.assertEqual(len(lists), 1, "exactly one daemon answers")
        self.assertTrue(lists[0].daemon)
        by_name = {i.instance: i for i in lists[0].instances}
        self.assertLessEqual({"hanging", "paper-1", "sphere"}, set(by_name))
        self.assertEqual(by_name["hanging"].scene, "hanging")
        self.assertGreater(by_name["hanging"].publish_hz, 0)
        self.assertGreater(by_name["sphere"].level.points, 0)
        self.assertEqual([i.instance for i in self.client.instances()], [i.instance for i in lists[0].instances])

    def test_alive_tokens(self):
        self.assertLessEqual({"hanging", "paper-1", "sphere"}, set(self.client.alive()))

    def test_info_describes_a_cloth(self):
        info = self.client.info("hanging")
        self.assertEqual(info.instance, "hanging")
        self.assertEqual(info.kind, "cloth")
        self.assertIn(info.level, [lv.level for lv in info.levels])
        n = info.level.nx * info.level.ny
        self.assertEqual(len(info.triangles) % 3, 0)
        self.assertTrue(all(t < n for t in info.triangles))
        self.assertEqual(len(lc.unpack_vec3(info.rest_positions)), n)

    def test_info_describes_a_mesh_cloth(self):
        info = self.client.info("skirt")
        self.assertEqual(info.kind, "cloth")
        self.assertEqual(lc.level_str(info.reference), "2288v")
        self.assertIn(lc.level_str(info.level), ["570v", "915v", "1370v"])
        rest = lc.unpack_vec3(info.rest_positions)
        # The simplifier lands within 3 % of the asked count.
        self.assertLessEqual(abs(len(rest) - info.level.vertices), 0.03 * info.level.vertices)
        self.assertTrue(all(t < len(rest) for t in info.triangles))
        uv = lc.material_uv(info)
        self.assertEqual(len(uv), len(rest))
        self.assertTrue(all(0.0 <= u <= 1.0 and 0.0 <= v <= 1.0 for u, v in uv))
        state = next(iter(self.client.states("skirt", count=1, timeout=10)))
        if lc.level_str(state.level) == lc.level_str(info.level):
            self.assertEqual(len(lc.positions(state)), len(rest))

    def test_health(self):
        infos = self.client.health()
        self.assertLessEqual({"hanging", "paper-1", "sphere"}, {i.instance for i in infos})
        self.assertEqual([i.instance for i in self.client.health("sphere")], ["sphere"])

    def test_states_of_a_cloth_decode(self):
        frames = []
        for state in self.client.states("hanging", count=3, timeout=10):
            self.assertIsInstance(state, v1.State)
            self.assertEqual(state.instance, "hanging")
            pts = lc.positions(state)  # checks nx * ny nodes
            self.assertEqual(len(pts), state.level.nx * state.level.ny)
            self.assertGreater(state.stepped_unix_nanos, 0)
            frames.append(state.frame)
        self.assertEqual(len(frames), 3)
        self.assertEqual(frames, sorted(frames))

    def test_states_of_a_surface_carry_the_whole_cloud(self):
        info = self.client.info("sphere")
        self.assertEqual(info.kind, "surface")
        # Generous: right after the daemon starts, the surface may not publish
        # for a while (it prepares its level first).
        state = next(iter(self.client.states("sphere", count=1, timeout=60)))
        self.assertEqual(len(lc.positions(state)), info.cloud_points)
        self.assertEqual(len(lc.unpack_vec3(state.normals)), info.cloud_points)

    def test_watch_interleaves_states_and_metrics(self):
        kinds = set()
        with self.client.watch("hanging", timeout=10) as w:
            for message in w:
                kinds.add(type(message).__name__)
                if kinds == {"State", "Metrics"}:
                    break
        self.assertEqual(kinds, {"State", "Metrics"})
        m = next(iter(self.client.metrics("hanging", count=1, timeout=10)))
        self.assertEqual(m.instance, "hanging")
        self.assertGreater(m.dt, 0)
        self.assertGreater(m.steps, 0)

    def test_callbacks(self):
        got = []
        done = threading.Event()

        def on_state(s):
            got.append(s)
            if len(got) >= 2:
                done.set()

        with self.client.on_state("paper-1", on_state):
            self.assertTrue(done.wait(10), "no state of paper-1 within 10 s")
        self.assertTrue(all(isinstance(s, v1.State) and s.instance == "paper-1" for s in got))

    def test_a_silent_instance_times_out(self):
        with self.assertRaises(lc.NoDataError) as ctx:
            next(iter(self.client.states("no-such-instance", timeout=0.5)))
        self.assertIn("lodcloth/no-such-instance/state", str(ctx.exception))

    def test_an_unknown_instance_is_refused(self):
        with self.assertRaises(lc.RefusedError) as ctx:
            self.client.switch("nope", "16x16", timeout=10)
        self.assertEqual(ctx.exception.code, v1.Error.CODE_UNKNOWN_INSTANCE)
        self.assertEqual(ctx.exception.code_name, "CODE_UNKNOWN_INSTANCE")
        self.assertIn("nope", ctx.exception.message)
        with self.assertRaises(lc.RefusedError) as ctx:
            self.client.info("nope")
        self.assertEqual(ctx.exception.code_name, "CODE_UNKNOWN_INSTANCE")

    def test_a_level_outside_the_allowed_set_is_refused(self):
        with self.assertRaises(lc.RefusedError) as ctx:
            self.client.switch("hanging", "17x17", timeout=10)
        self.assertEqual(ctx.exception.code, v1.Error.CODE_LEVEL_NOT_ALLOWED)
        self.assertIn("17x17", ctx.exception.message)

    def test_pause_and_resume(self):
        try:
            r = self.client.pause("hanging")
            self.assertEqual(r.instance, "hanging")
            self.assertTrue(r.paused)
            self.assertTrue(self.client.info("hanging").paused)
        finally:
            r = self.client.resume("hanging")
        self.assertFalse(r.paused)

    def test_grab_and_release(self):
        # Pull the bottom centre of `hanging` towards the viewer, then let go;
        # every input that took effect comes back on the inputs key.
        seen: "queue.Queue[v1.InputEvent]" = queue.Queue()
        sub = self.client.on_input("hanging", seen.put)
        try:
            r = self.client.grab("hanging", 0.5, 1.0, (0.5, -0.8, 0.3), id=9)
            grab = seen.get(timeout=5)
            self.assertEqual((grab.frame, grab.instance, grab.idle), (r.frame, "hanging", False))
            self.assertEqual(grab.input.grab.id, 9)
            self.assertEqual(grab.input.grab.target.z, 0.3)
            self.assertEqual(r.instance, "hanging")
            self.assertIn(9, list(r.grabs))
            self.assertGreater(r.frame, 0)
            with self.assertRaises(lc.RefusedError) as ctx:
                self.client.grab("hanging", 1.5, 1.0, (0, 0, 0))
            self.assertEqual(ctx.exception.code, v1.Error.CODE_BAD_REQUEST)
            self.assertIn("grab.at.u", ctx.exception.message)
            # The episode's log has the grab too, numbered like the event.
            log = self.client.episode_inputs("hanging")
            self.assertIn(grab.seq, [e.seq for e in log.events])
            self.assertEqual(log.episode, grab.episode)
        finally:
            r = self.client.release("hanging")
            # The release's event is published as it takes effect, which may
            # be after the reply: wait for it before closing the subscriber
            # (closing first lost it now and then, on a loaded machine).
            try:
                released = seen.get(timeout=5)
            except queue.Empty:
                released = None
            sub.close()
        self.assertEqual(list(r.grabs), [])
        self.assertIsNotNone(released, "no release_all event within 5 s")
        self.assertEqual(released.input.WhichOneof("action"), "release_all")

    def test_switch_to_the_current_level(self):
        # It runs at that level, so the level is prepared; right after the
        # daemon starts, the reply may still wait for the background
        # preparation to attach its prediction (tens of seconds).
        current = self.client.info("paper-1").level
        r = self.client.switch("paper-1", current, timeout=300)
        self.assertEqual(r.instance, "paper-1")
        self.assertEqual(r.level, current)
        self.assertGreater(r.dt, 0)
        self.assertGreater(r.coefficients.structural_k, 0)

    def test_the_console_script(self):
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "lodcloth_client",
                "--connect",
                ENDPOINT,
                "switch",
                "nope",
                "--level",
                "16x16",
                "--timeout",
                "10",
            ],
            capture_output=True,
            text=True,
            timeout=60,
        )
        self.assertEqual(r.returncode, 1)
        self.assertIn("CODE_UNKNOWN_INSTANCE", r.stderr)
        r = subprocess.run(
            [sys.executable, "-m", "lodcloth_client", "--connect", ENDPOINT, "list"],
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
        )
        self.assertIn("hanging", r.stdout)
        # A mesh level publishes its vertices (not nx * ny = 0 points).
        info = self.client.info("skirt")
        r = subprocess.run(
            [sys.executable, "-m", "lodcloth_client", "--connect", ENDPOINT, "info", "skirt"],
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
        )
        published = len(lc.unpack_vec3(info.rest_positions))
        self.assertIn(f"({published} published points", r.stdout)


if __name__ == "__main__":
    unittest.main()
