"""Check deploy/compose/ as far as a machine without a Docker engine allows.

Run by .ci/compose-check.sh (which provides PyYAML); see that script for
what is checked and what is not. Two parts:

1. Static: both compose files parse and have the structure the deployment
   relies on: one image built from the repository's Dockerfile; every
   command names a subcommand and options the built binary has; every
   LODCLOTH_* variable is one the service's subcommand (or its health
   check's) reads; every file a service reads (its command's configs, the
   files those configs name, its secrets) is mounted, a secret, or copied
   into the image by the Dockerfile, and exists; ports published on
   127.0.0.1 by default and unique; depends_on targets exist, with health
   checks where the condition needs one; each daemon owns a disjoint part
   of config/default.toml's instances, its health check names exactly them,
   and the secure daemons' configs equal the plain ones but for [zenoh].

2. Run: each compose file's services as local processes of
   target/release/lodcloth, from the file's own entrypoint, command,
   environment and health checks (compose interpolation applied). Service
   hostnames become 127.0.0.1, every port a service listens on becomes a
   free loopback port, the image's WORKDIR (/opt/lodcloth) is the
   repository root, named volumes and secrets are directories and files
   under out/ci-compose/. Services start in depends_on order, each
   condition waited for by running the health check itself. Then the CLI
   asserts what the deployment is for, and every process is stopped with
   SIGTERM and must exit 0.

The one deliberate difference from the compose files: the daemons' configs
are run with `precompute = false` (see PRECOMPUTE_NOTE).
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import tomllib
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent
COMPOSE_DIR = REPO / "deploy" / "compose"
BIN = REPO / "target" / "release" / "lodcloth"
OUT = REPO / "out" / "ci-compose"
SUBCOMMANDS = {"serve", "router", "view", "foxglove", "list", "watch", "switch", "health", "record"}
# Variables only the compose files' shell snippets read (not the binary).
SCRIPT_VARS = {"OWNED_INSTANCES", "LODCLOTH_PASSWORD_FILE"}
PRECOMPUTE_NOTE = (
    "the daemons run with precompute = false here: with it on, both daemons spend the first "
    "minutes of a fresh cache estimating all 19 levels on CI's two cores (in a deployment that "
    "happens once, cached on the volume), and a switch would queue behind it"
)
T0 = time.monotonic()


class CheckError(Exception):
    pass


def log(msg: str) -> None:
    print(f"[compose-check {time.monotonic() - T0:6.1f}s] {msg}", flush=True)


def require(cond: bool, msg: str) -> None:
    if not cond:
        raise CheckError(msg)


# ---------------------------------------------------------------------------
# Compose: interpolation, the Dockerfile's image, services
# ---------------------------------------------------------------------------

INTERP = re.compile(r"\$(?:\$|\{(?P<braced>[^}]*)\}|(?P<bare>[A-Za-z_][A-Za-z0-9_]*))")


def interpolate(value, env: dict[str, str], used: set[str]):
    """Compose's variable interpolation of every string in `value`."""
    if isinstance(value, dict):
        return {k: interpolate(v, env, used) for k, v in value.items()}
    if isinstance(value, list):
        return [interpolate(v, env, used) for v in value]
    if not isinstance(value, str):
        return value

    def one(m: re.Match) -> str:
        if m.group(0) == "$$":
            return "$"
        expr = m.group("braced") if m.group("braced") is not None else m.group("bare")
        mm = re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)(?:(:?[-?])(.*))?", expr, re.S)
        require(mm is not None, f"bad interpolation ${{{expr}}}")
        name, op, arg = mm.group(1), mm.group(2), mm.group(3)
        used.add(name)
        val = env.get(name)
        if op == ":-":
            return val if val else arg
        if op == "-":
            return val if val is not None else arg
        if op in (":?", "?"):
            require(val is not None and (op == "?" or val), f"${{{expr}}}: {arg}")
            return val
        require(val is not None, f"${name} is not set and has no default")
        return val

    return INTERP.sub(one, value)


@dataclass
class Image:
    workdir: str
    entrypoint: list[str]
    cmd: list[str]
    env: dict[str, str]
    copies: list[str]  # container paths the runtime stage COPYs from the build context
    healthcheck: bool


def dockerfile_image(path: Path) -> Image:
    """The runtime stage of the Dockerfile: what the compose services inherit."""
    text = re.sub(r"\\\n", " ", path.read_text())
    stages: list[list[str]] = []
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if line.upper().startswith("FROM "):
            stages.append([])
        if stages:
            stages[-1].append(line)
    lines = stages[-1]
    workdir, entrypoint, cmd, env, copies, health = "/", [], [], {}, [], False
    for line in lines:
        word, _, rest = line.partition(" ")
        word = word.upper()
        if word == "WORKDIR":
            workdir = rest.strip()
        elif word == "ENTRYPOINT":
            entrypoint = json.loads(rest)
        elif word == "CMD":
            cmd = json.loads(rest)
        elif word == "ENV":
            for k, v in re.findall(r'([A-Za-z_][A-Za-z0-9_]*)=("[^"]*"|\S+)', rest):
                env[k] = v.strip('"')
        elif word == "HEALTHCHECK":
            health = "NONE" not in rest.upper().split()
        elif word == "COPY" and "--from" not in rest:
            parts = rest.split()
            dest = parts[-1]
            if not dest.startswith("/"):
                dest = workdir.rstrip("/") + "/" + dest
            for src in parts[:-1]:
                require((REPO / src).exists(), f"Dockerfile COPY {src}: not in the repository")
                if dest.endswith("/"):
                    copies.append(dest + (Path(src).name if not src.endswith("/") else ""))
                else:
                    copies.append(dest)
    return Image(workdir, entrypoint, cmd, env, [c.rstrip("/") for c in copies], health)


@dataclass
class Service:
    name: str
    spec: dict
    argv: list[str]  # entrypoint + command, as in the container
    env: dict[str, str]  # image ENV + environment
    mounts: list[tuple[str, Path, str]] = field(default_factory=list)  # (target, host source, kind)
    listens: set[int] = field(default_factory=set)
    # The ports of those that are UDP (quic/, udp/ endpoints): Docker
    # publishes TCP unless a port says /udp.
    udp_listens: set[int] = field(default_factory=set)
    instances: list[str] = field(default_factory=list)  # a daemon's, from its config

    @property
    def subcommand(self) -> str:
        words = [w for w in self.argv if w in SUBCOMMANDS]
        return words[0] if words else ""

    def option(self, name: str, default: str | None = None) -> str | None:
        a = self.argv
        for i, w in enumerate(a):
            if w == name and i + 1 < len(a):
                return a[i + 1]
            if w.startswith(name + "="):
                return w.split("=", 1)[1]
        return default

    def setting(self, option: str, env: str | None, default: str | None = None) -> str | None:
        """An option of the command, else its environment variable, else the default (clap's order)."""
        v = self.option(option)
        if v is None and env:
            v = self.env.get(env)
        return v if v is not None else default

    def serve_config(self) -> str:
        cfg = self.setting("--config", "LODCLOTH_CONFIG")
        require(cfg is not None, f"services.{self.name}: serve without --config (or LODCLOTH_CONFIG) would run "
                                 "config/default.toml")
        return cfg


def addr_port(addr: str) -> int:
    m = re.fullmatch(r"(.+):(\d+)", addr)
    require(m is not None, f"'{addr}' is not HOST:PORT")
    return int(m.group(2))


@dataclass
class Compose:
    path: Path
    data: dict
    image: Image
    services: dict[str, Service]
    secret_files: dict[str, Path]
    used_vars: set[str]


def load_compose(path: Path, secrets_dir: Path | None) -> Compose:
    raw = yaml.safe_load(path.read_text())
    require(isinstance(raw, dict) and isinstance(raw.get("services"), dict), f"{path}: no services")
    allowed = {"name", "services", "volumes", "secrets", "networks", "configs"}
    for k in raw:
        require(k in allowed or k.startswith("x-"), f"{path}: unknown top-level key {k}")
    used: set[str] = set()
    data = interpolate({k: v for k, v in raw.items() if not k.startswith("x-")}, {}, used)
    images = set()
    services: dict[str, Service] = {}
    image: Image | None = None
    for name, spec in data["services"].items():
        where = f"{path.name}: services.{name}"
        require(isinstance(spec, dict), f"{where}: not a mapping")
        require("image" in spec and "build" in spec, f"{where}: needs image and build (one image for all)")
        images.add(spec["image"])
        build = spec["build"]
        ctx = (path.parent / (build["context"] if isinstance(build, dict) else build)).resolve()
        require(ctx == REPO, f"{where}: build context {ctx} is not the repository root")
        dockerfile = ctx / (build.get("dockerfile", "Dockerfile") if isinstance(build, dict) else "Dockerfile")
        require(dockerfile.is_file(), f"{where}: {dockerfile} does not exist")
        image = dockerfile_image(dockerfile)
        require(spec.get("restart") in ("unless-stopped", "always", "on-failure"), f"{where}: no restart policy")
        entry = spec.get("entrypoint", image.entrypoint)
        cmd = spec.get("command", image.cmd if "entrypoint" not in spec else [])
        for what, v in (("entrypoint", entry), ("command", cmd)):
            require(isinstance(v, list) and all(isinstance(x, str) for x in v),
                    f"{where}: {what} must be a list of strings (exec form)")
        env = dict(image.env)
        environment = spec.get("environment", {})
        require(isinstance(environment, dict), f"{where}: environment must be a mapping")
        for k, v in environment.items():
            require(isinstance(v, str), f"{where}: environment {k} must be a string (quote true/false), got {v!r}")
            env[k] = v
        services[name] = Service(name, spec, list(entry) + list(cmd), env)
    require(len(images) == 1, f"{path.name}: the services name several images {images}")
    secret_files: dict[str, Path] = {}
    for sname, s in (data.get("secrets") or {}).items():
        require(isinstance(s, dict) and "file" in s, f"{path.name}: secrets.{sname} needs a file")
        # Files of deploy/compose/secrets/, which make-secrets.sh writes: here into secrets_dir.
        host = (path.parent / s["file"]).resolve()
        require(host.is_relative_to(COMPOSE_DIR / "secrets"),
                f"{path.name}: secrets.{sname}: {s['file']} is not in deploy/compose/secrets/ (make-secrets.sh)")
        require(secrets_dir is not None, f"{path.name}: secrets without a secrets directory")
        secret_files[sname] = secrets_dir / host.relative_to(COMPOSE_DIR / "secrets")
    return Compose(path, data, image, services, secret_files, used)


# ---------------------------------------------------------------------------
# Static checks
# ---------------------------------------------------------------------------

_help_cache: dict[str, str] = {}


def help_text(sub: str) -> str:
    if sub not in _help_cache:
        r = subprocess.run([str(BIN), sub, "--help"], capture_output=True, text=True, timeout=30)
        require(r.returncode == 0, f"lodcloth {sub} --help failed: {r.stderr}")
        _help_cache[sub] = r.stdout
    return _help_cache[sub]


def env_names(sub: str) -> set[str]:
    return set(re.findall(r"\[env: ([A-Z0-9_]+)", help_text(sub)))


def parse_duration(s: str) -> float:
    total = 0.0
    for num, unit in re.findall(r"(\d+(?:\.\d+)?)(ms|h|m|s)", s):
        total += float(num) * {"ms": 0.001, "s": 1, "m": 60, "h": 3600}[unit]
    require(total > 0, f"bad duration {s!r}")
    return total


def endpoint_ports(endpoints: list[str]) -> set[int]:
    ports = set()
    for e in endpoints:
        m = re.fullmatch(r"[a-z]+/.*:(\d+)", e)
        require(m is not None, f"'{e}' is not a zenoh endpoint")
        ports.add(int(m.group(1)))
    return ports


def udp_ports(endpoints: list[str]) -> set[int]:
    """The ports of the endpoints that run over UDP."""
    return endpoint_ports([e for e in endpoints if e.split("/", 1)[0] in ("quic", "udp")])


def container_file(c: Compose, s: Service, path: str) -> tuple[Path, str]:
    """Where a path the service reads comes from: (host file, kind)."""
    p = path if path.startswith("/") else c.image.workdir.rstrip("/") + "/" + path
    best = None
    for target, host, kind in s.mounts:
        if p == target or p.startswith(target.rstrip("/") + "/"):
            if best is None or len(target) > len(best[0]):
                best = (target, host, kind)
    if best:
        target, host, kind = best
        return (host / p[len(target):].lstrip("/")) if p != target else host, kind
    for copied in c.image.copies:
        if p == copied or p.startswith(copied + "/"):
            rel = p[len(c.image.workdir.rstrip("/")) + 1:]
            return REPO / rel, "image"
    raise CheckError(f"services.{s.name}: {path} is neither mounted, a secret nor in the image")


def static_checks(c: Compose) -> None:
    name = c.path.name
    default_instances = {i["name"] for i in tomllib.loads((REPO / "config/default.toml").read_text())["instances"]}
    # Every published port's host side defaults to the loopback.
    for v in sorted(c.used_vars):
        require(v.startswith("LODCLOTH_"), f"{name}: interpolates ${v}, expected LODCLOTH_* names")
    host_ports = set()
    named_volumes = c.data.get("volumes") or {}
    volume_users: dict[str, str] = {}
    for s in c.services.values():
        where = f"{name}: services.{s.name}"
        spec = s.spec
        sub = s.subcommand
        require(sub in ("serve", "router", "view", "foxglove"), f"{where}: runs `{sub}`, not a lodcloth service")
        # Options of the command exist in the built binary.
        help_sub = help_text(sub)
        for w in s.argv[s.argv.index(sub) + 1:]:
            if w.startswith("--"):
                require(re.search(rf"(^|\s){re.escape(w.split('=')[0])}[\s<]", help_sub) is not None,
                        f"{where}: lodcloth {sub} has no option {w}")
        # Environment: read by the subcommand, by the health check's `lodcloth health`, or by the
        # compose file's own shell snippets (which must then use them).
        known = env_names(sub) | env_names("health")
        scripts = " ".join(s.argv) + " " + " ".join(spec.get("healthcheck", {}).get("test", []))
        for k in s.env:
            if k in s.spec.get("environment", {}):
                if k.startswith("LODCLOTH_") and k not in SCRIPT_VARS:
                    require(k in known, f"{where}: {k} is read by neither lodcloth {sub} nor lodcloth health")
                else:
                    require(k in SCRIPT_VARS and f"${k}" in scripts, f"{where}: {k} is not used")
        # Mounts.
        for m in spec.get("volumes", []):
            require(isinstance(m, str), f"{where}: volumes in short syntax expected")
            parts = m.split(":")
            src, target = parts[0], parts[1]
            mode = parts[2] if len(parts) > 2 else "rw"
            if src.startswith((".", "/")):
                host = (c.path.parent / src).resolve()
                require(host.exists(), f"{where}: mounts {src}, which does not exist")
                require(host.is_relative_to(REPO), f"{where}: mounts {src} from outside the repository")
                require(mode == "ro", f"{where}: bind mount {src} should be read-only")
                s.mounts.append((target, host, "mount"))
            else:
                require(src in named_volumes, f"{where}: volume {src} is not declared")
                require(src not in volume_users, f"{where}: volume {src} is shared with {volume_users.get(src)}")
                volume_users[src] = s.name
                s.mounts.append((target, Path(src), "volume"))
        for sec in spec.get("secrets", []):
            sname = sec if isinstance(sec, str) else sec["source"]
            target = sec if isinstance(sec, str) else sec.get("target", sname)
            require(sname in c.secret_files, f"{where}: secret {sname} is not declared")
            host = c.secret_files[sname]
            require(host.is_file(), f"{where}: secret {sname}: {host} does not exist")
            s.mounts.append((target if target.startswith("/") else f"/run/secrets/{target}", host, "secret"))
        # Health check: every service has its own (the image's checks a daemon on tcp/127.0.0.1:7450,
        # which no service here listens on).
        hc = spec.get("healthcheck")
        require(isinstance(hc, dict) and isinstance(hc.get("test"), list) and hc["test"][0] in ("CMD", "CMD-SHELL"),
                f"{where}: needs its own healthcheck (exec form)")
        for k in ("interval", "timeout", "start_period", "start_interval"):
            if k in hc:
                parse_duration(hc[k])
        # Ports: HOST_IP:HOST_PORT:CONTAINER_PORT on the loopback by default, unique host ports.
        for p in spec.get("ports", []):
            m = re.fullmatch(r"(\d+\.\d+\.\d+\.\d+):(\d+):(\d+)(/tcp|/udp)?", str(p))
            require(m is not None, f"{where}: port {p} should be HOST_IP:HOST_PORT:CONTAINER_PORT")
            require(m.group(1) == "127.0.0.1", f"{where}: port {p} is not bound to 127.0.0.1 by default")
            require(m.group(2) not in host_ports, f"{where}: host port {m.group(2)} is published twice")
            host_ports.add(m.group(2))
        # depends_on.
        for dep, cond in (spec.get("depends_on") or {}).items():
            require(dep in c.services, f"{where}: depends on unknown service {dep}")
            condition = cond.get("condition")
            require(condition in ("service_started", "service_healthy", "service_completed_successfully"),
                    f"{where}: depends_on.{dep}: bad condition {condition}")
    # depends_on has no cycle.
    order(c)

    # What each service listens on, and what the files it reads hold.
    daemons: dict[str, tuple[Service, dict]] = {}
    for s in c.services.values():
        where = f"{name}: services.{s.name}"
        sub = s.subcommand
        if sub == "router":
            listen = s.option("--listen") or s.env.get("LODCLOTH_ROUTER_LISTEN") or "tcp/0.0.0.0:7447"
            s.listens = endpoint_ports(listen.split(","))
            s.udp_listens = udp_ports(listen.split(","))
            zc = s.option("--zenoh-config")
            if zc:
                host, _ = container_file(c, s, zc)
                require(host.is_file(), f"{where}: {zc} does not exist")
                for ref in re.findall(r'"(/[^"]+)"', strip_json5_comments(host.read_text())):
                    f, _ = container_file(c, s, ref)
                    require(f.is_file(), f"{where}: {zc} names {ref}, which does not exist")
        elif sub == "serve":
            cfg = s.serve_config()
            host, kind = container_file(c, s, cfg)
            require(host.is_file(), f"{where}: {cfg} does not exist")
            conf = tomllib.loads(host.read_text())
            z = conf.get("zenoh", {})
            listen = s.env.get("LODCLOTH_LISTEN", "").split(",") if s.env.get("LODCLOTH_LISTEN") else z.get("listen", [])
            s.listens = endpoint_ports(listen)
            s.udp_listens = udp_ports(listen)
            # `serve --http ADDR` (LODCLOTH_HTTP): /metrics and /healthz.
            http = s.setting("--http", "LODCLOTH_HTTP")
            if http:
                s.listens.add(addr_port(http))
            if "LODCLOTH_CONNECT" in s.env:
                require(z.get("connect") == s.env["LODCLOTH_CONNECT"].split(","),
                        f"{where}: {cfg} connects to {z.get('connect')}, LODCLOTH_CONNECT to {s.env['LODCLOTH_CONNECT']}")
            for ref in [i["scene"] for i in conf.get("instances", [])] + [
                z.get("config_file"), *(z.get("tls", {}).values())
            ]:
                if isinstance(ref, str):
                    f, _ = container_file(c, s, ref)
                    require(f.is_file(), f"{where}: {cfg} names {ref}, which does not exist")
            for ref in (s.env.get("LODCLOTH_CACHE_DIR", conf.get("cache")),
                        s.env.get("LODCLOTH_SNAPSHOT_DIR", conf.get("snapshots", {}).get("dir"))):
                _, k = container_file(c, s, ref)
                require(k == "volume", f"{where}: {ref} is not on the daemon's volume")
            names = [i["name"] for i in conf.get("instances", [])]
            s.instances = names
            if "OWNED_INSTANCES" in s.env:  # the health check's list
                owned = s.env["OWNED_INSTANCES"].split()
                require(sorted(owned) == sorted(names),
                        f"{where}: OWNED_INSTANCES {owned} is not the instances of {cfg} {names}")
            daemons[s.name] = (s, conf)
        elif sub == "view":
            addr = s.setting("--listen", "LODCLOTH_VIEW_LISTEN", "127.0.0.1:8080")
            s.listens = {addr_port(addr)}
            require(addr.rsplit(":", 1)[0] == "0.0.0.0", f"{where}: the view must listen on 0.0.0.0 to be published")
        elif sub == "foxglove":
            s.listens = {int(s.option("--port", "8765"))}
            require(s.option("--host") == "0.0.0.0", f"{where}: the bridge must listen on 0.0.0.0 to be published")
        for p in s.spec.get("ports", []):
            cport = int(str(p).split(":")[-1].split("/")[0])
            require(cport in s.listens, f"{where}: publishes {cport}, which it does not listen on ({s.listens})")
            udp = str(p).endswith("/udp")
            require(udp == (cport in s.udp_listens),
                    f"{where}: publishes {p}, but {cport} is a {'UDP' if cport in s.udp_listens else 'TCP'} "
                    f"listener (QUIC runs over UDP: publish it as …:{cport}/udp)")
    # Client endpoints name a service and a port it listens on.
    for s in c.services.values():
        for e in s.env.get("LODCLOTH_CONNECT", "").split(",") if s.env.get("LODCLOTH_CONNECT") else []:
            m = re.fullmatch(r"[a-z]+/([^:]+):(\d+)", e)
            require(m is not None and m.group(1) in c.services, f"{name}: {s.name}: LODCLOTH_CONNECT={e} names no service")
            require(int(m.group(2)) in c.services[m.group(1)].listens,
                    f"{name}: {s.name} connects to {e}, where nothing listens")
    # The daemons split config/default.toml's instances between them, under one prefix.
    require(len(daemons) >= 2, f"{name}: fewer than two daemons")
    seen: dict[str, str] = {}
    prefixes = set()
    for dname, (s, conf) in daemons.items():
        prefixes.add(conf.get("prefix", "lodcloth"))
        for i in conf.get("instances", []):
            require(i["name"] not in seen, f"{name}: {i['name']} is owned by both {seen.get(i['name'])} and {dname}")
            seen[i["name"]] = dname
    require(len(prefixes) == 1, f"{name}: the daemons use different prefixes {prefixes}")
    require(set(seen) == default_instances,
            f"{name}: the daemons own {sorted(seen)}, config/default.toml has {sorted(default_instances)}")
    log(f"{name}: static checks passed ({len(c.services)} services; instances by daemon: "
        + "; ".join(f"{d}: {' '.join(i['name'] for i in conf['instances'])}" for d, (_, conf) in daemons.items())
        + ")")


def strip_json5_comments(text: str) -> str:
    """JSON5 without its // comments (a // inside a string stays)."""
    out = []
    for line in text.splitlines():
        in_string = False
        for i, ch in enumerate(line):
            if ch == '"' and (i == 0 or line[i - 1] != "\\"):
                in_string = not in_string
            elif not in_string and line.startswith("//", i):
                line = line[:i]
                break
        out.append(line)
    return "\n".join(out)


def order(c: Compose) -> list[str]:
    """The services in depends_on order (dependencies first); fails on a cycle."""
    done: list[str] = []
    visiting: set[str] = set()

    def visit(n: str) -> None:
        if n in done:
            return
        require(n not in visiting, f"{c.path.name}: depends_on cycle through {n}")
        visiting.add(n)
        for dep in (c.services[n].spec.get("depends_on") or {}):
            visit(dep)
        visiting.discard(n)
        done.append(n)

    for n in c.services:
        visit(n)
    return done


def compare_secure_configs(plain: Compose, secure: Compose) -> None:
    """The secure daemons run the plain ones' config but for [zenoh]."""
    for name, s in secure.services.items():
        if s.subcommand != "serve":
            continue
        p = plain.services.get(name)
        require(p is not None and p.subcommand == "serve", f"compose.secure.yaml: {name} has no plain counterpart")
        a = tomllib.loads(container_file(plain, p, p.serve_config())[0].read_text())
        b = tomllib.loads(container_file(secure, s, s.serve_config())[0].read_text())
        a.pop("zenoh", None)
        b.pop("zenoh", None)
        require(a == b, f"{name}: the secure config differs from the plain one outside [zenoh]")
    require(set(plain.services) == set(secure.services), "the two compose files have different services")
    log("the secure daemons' configs equal the plain ones outside [zenoh]")


# ---------------------------------------------------------------------------
# Running a compose file as local processes
# ---------------------------------------------------------------------------


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class Topology:
    """One compose file's services as local processes."""

    def __init__(self, c: Compose, variant: str):
        self.c = c
        self.dir = OUT / variant
        shutil.rmtree(self.dir, ignore_errors=True)
        (self.dir / "logs").mkdir(parents=True)
        self.bindir = OUT / "bin"
        self.bindir.mkdir(parents=True, exist_ok=True)
        link = self.bindir / "lodcloth"
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(BIN)
        self.ports = {(s.name, p): free_port() for s in c.services.values() for p in s.listens}
        self.procs: dict[str, subprocess.Popen] = {}
        self.configs: dict[str, Path] = {}  # serve's config as run, per daemon
        self.base_env = {
            "PATH": f"{self.bindir}:/usr/local/bin:/usr/bin:/bin",
            "HOME": str(self.dir),
            "LANG": "C.UTF-8",
            "RUST_BACKTRACE": "0",
        }

    # -- translation ------------------------------------------------------

    def port(self, service: str, port: int) -> int:
        require((service, port) in self.ports, f"nothing in {service} listens on {port}")
        return self.ports[(service, port)]

    def host_path(self, s: Service, p: str) -> str:
        f, kind = container_file(self.c, s, p)
        if kind == "volume":
            vol = [t for t in s.mounts if t[2] == "volume" and (p == t[0] or p.startswith(t[0] + "/"))][0]
            base = self.dir / "volumes" / str(vol[1])
            return str(base / p[len(vol[0]):].lstrip("/"))
        return str(f)

    def translate(self, s: Service, text: str) -> str:
        """A string of the container's world in the local one: endpoints, addresses, paths."""
        own = {"0.0.0.0", "127.0.0.1", "localhost", "[::]"}

        def endpoint(m: re.Match) -> str:
            proto, host, port = m.group(1), m.group(2), int(m.group(3))
            target = s.name if host in own else host
            if target not in self.c.services:
                return m.group(0)
            return f"{proto}/127.0.0.1:{self.port(target, port)}"

        text = re.sub(r"\b(tcp|tls|udp|quic)/([A-Za-z0-9_.\-]+|\[::\]):(\d+)", endpoint, text)
        text = re.sub(r"/dev/tcp/127\.0\.0\.1/(\d+)",
                      lambda m: f"/dev/tcp/127.0.0.1/{self.port(s.name, int(m.group(1)))}", text)
        # Absolute container paths under a mount, a secret or a volume.
        targets = sorted({t[0] for t in s.mounts}, key=len, reverse=True)
        for t in targets:
            text = re.sub(re.escape(t) + r"(?=[\"'/\s:,]|$)", lambda m: self.host_path(s, t), text)
        return text

    def addr(self, s: Service, addr: str) -> str:
        """A socket address the service binds (HOST:PORT) on its local port."""
        return f"127.0.0.1:{self.port(s.name, addr_port(addr))}"

    def translated_file(self, s: Service, container_path: str, serve_config: bool) -> str:
        src, _ = container_file(self.c, s, container_path)
        text = self.translate(s, src.read_text())
        if serve_config:
            require(re.search(r"^precompute = true$", text, re.M) is not None,
                    f"{container_path}: expected `precompute = true`")
            text = re.sub(r"^precompute = true$", "precompute = false  # .ci/compose_check.py", text, flags=re.M)
        dest = self.dir / s.name / Path(container_path).name
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(text)
        if serve_config:
            self.configs[s.name] = dest
        return str(dest)

    def argv(self, s: Service) -> list[str]:
        out = []
        sub = s.subcommand
        a = s.argv
        i = 0
        while i < len(a):
            w = a[i]
            nxt = a[i + 1] if i + 1 < len(a) else None
            if w == "--config" and sub == "serve":
                out += [w, self.translated_file(s, nxt, True)]
                i += 2
                continue
            if w == "--zenoh-config":
                out += [w, self.translated_file(s, nxt, False)]
                i += 2
                continue
            if (sub, w) in (("view", "--listen"), ("serve", "--http")):
                out += [w, self.addr(s, nxt)]
                i += 2
                continue
            if sub == "foxglove" and w == "--host":
                out += [w, "127.0.0.1"]
                i += 2
                continue
            if sub == "foxglove" and w == "--port":
                out += [w, str(self.port(s.name, int(nxt)))]
                i += 2
                continue
            out.append(self.translate(s, w))
            i += 1
        return out

    def env(self, s: Service) -> dict[str, str]:
        env = dict(self.base_env)
        for k, v in s.env.items():
            if k in ("LODCLOTH_HTTP", "LODCLOTH_VIEW_LISTEN"):
                env[k] = self.addr(s, v)
            elif k == "LODCLOTH_CONFIG" and s.subcommand == "serve":
                env[k] = str(self.configs.get(s.name) or self.translated_file(s, v, True))
            else:
                env[k] = self.translate(s, v)
        return env

    # -- processes --------------------------------------------------------

    def start(self, s: Service) -> None:
        argv = self.argv(s)
        logf = open(self.dir / "logs" / f"{s.name}.log", "w")
        log(f"start {s.name}: {' '.join(argv)}")
        self.procs[s.name] = subprocess.Popen(argv, cwd=REPO, env=self.env(s), stdout=logf, stderr=subprocess.STDOUT,
                                              stdin=subprocess.DEVNULL)

    def healthy(self, s: Service) -> tuple[bool, str]:
        hc = s.spec["healthcheck"]
        test = [self.translate(s, w) for w in hc["test"]]
        argv = test[1:] if test[0] == "CMD" else ["sh", "-c", test[1]]
        try:
            r = subprocess.run(argv, cwd=REPO, env=self.env(s), capture_output=True, text=True,
                               timeout=parse_duration(hc.get("timeout", "30s")))
        except subprocess.TimeoutExpired:
            return False, "timed out"
        return r.returncode == 0, (r.stdout + r.stderr).strip()[-400:]

    def wait_healthy(self, s: Service, limit: float = 120.0) -> None:
        hc = s.spec["healthcheck"]
        every = parse_duration(hc.get("start_interval", "1s"))
        deadline = time.monotonic() + limit
        tries = 0
        while True:
            proc = self.procs[s.name]
            require(proc.poll() is None, f"{s.name} exited with {proc.returncode} before it was healthy "
                                         f"(log: {self.dir / 'logs' / (s.name + '.log')})\n{self.tail(s.name)}")
            ok, out = self.healthy(s)
            tries += 1
            if ok:
                log(f"{s.name} healthy (health check passed on try {tries})")
                return
            require(time.monotonic() < deadline,
                    f"{s.name} not healthy within {limit:.0f} s; last health check said: {out}\n{self.tail(s.name)}")
            time.sleep(every)

    def up(self) -> None:
        """Start in depends_on order, waiting for each condition; then every service must be healthy."""
        started: list[str] = []
        healthy: set[str] = set()
        for n in order(self.c):
            s = self.c.services[n]
            for dep, cond in (s.spec.get("depends_on") or {}).items():
                require(dep in started, f"{n} before its dependency {dep}")
                if cond["condition"] == "service_healthy" and dep not in healthy:
                    self.wait_healthy(self.c.services[dep])
                    healthy.add(dep)
            self.start(s)
            started.append(n)
        for n in started:
            if n not in healthy:
                self.wait_healthy(self.c.services[n])
        for n in started:  # and still healthy, all at once
            ok, out = self.healthy(self.c.services[n])
            require(ok, f"{n} is no longer healthy: {out}")
        log(f"all {len(started)} services up and healthy")

    def tail(self, name: str, lines: int = 15) -> str:
        p = self.dir / "logs" / f"{name}.log"
        return "\n".join(p.read_text(errors="replace").splitlines()[-lines:]) if p.exists() else ""

    def down(self, require_clean: bool = True) -> None:
        """SIGTERM in reverse depends_on order (dependents first), each must exit 0."""
        problems = []
        for n in reversed(order(self.c)):
            proc = self.procs.pop(n, None)
            if proc is None:
                continue
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
            grace = parse_duration(self.c.services[n].spec.get("stop_grace_period", "10s"))
            try:
                rc = proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
                problems.append(f"{n} did not stop within {grace:.0f} s of SIGTERM")
                continue
            if rc != 0:
                problems.append(f"{n} exited with {rc} after SIGTERM\n{self.tail(n)}")
            else:
                log(f"{n} stopped cleanly (exit 0)")
        if require_clean:
            require(not problems, "; ".join(problems))

    def kill_all(self) -> None:
        for name in self.procs:
            log(f"--- last lines of {name}'s log ({self.dir / 'logs' / (name + '.log')}):\n{self.tail(name)}")
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        self.procs.clear()

    # -- the CLI on the host --------------------------------------------------

    def router_endpoint(self, proto: str) -> str:
        s = self.c.services["router"]
        published = int(str(s.spec["ports"][0]).split(":")[-1].split("/")[0])
        return f"{proto}/127.0.0.1:{self.port('router', published)}"

    def cli(self, args: list[str], env: dict[str, str], timeout: float = 60, check: bool = True
            ) -> subprocess.CompletedProcess:
        full = dict(self.base_env)
        full.update(env)
        try:
            r = subprocess.run([str(BIN)] + args, cwd=REPO, env=full, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired as e:
            raise CheckError(f"lodcloth {' '.join(args)}: no result within {timeout:.0f} s") from e
        if check:
            require(r.returncode == 0, f"lodcloth {' '.join(args)} failed ({r.returncode}):\n{r.stdout}{r.stderr}")
        return r


def list_instances(out: str) -> dict[str, tuple[str, str]]:
    """`lodcloth list` output: instance → (level, daemon id)."""
    rows = {}
    for line in out.splitlines()[1:]:
        f = line.split()
        if len(f) >= 6 and "(alive," not in line:
            rows[f[0]] = (f[2], f[-1])
    return rows


def wait_for(what: str, probe, limit: float = 60.0, every: float = 0.5):
    deadline = time.monotonic() + limit
    last = None
    while True:
        try:
            result = probe()
            if result:
                return result
        except CheckError as e:
            last = e
        require(time.monotonic() < deadline, f"{what} not within {limit:.0f} s{': ' + str(last) if last else ''}")
        time.sleep(every)


def owned(c: Compose) -> dict[str, list[str]]:
    return {s.name: s.instances for s in c.services.values() if s.subcommand == "serve"}


def exercise(t: Topology, client_env: dict[str, str], secure: dict | None) -> None:
    """What the deployment is for, asserted through the router with the CLI."""
    by_daemon = owned(t.c)
    every = sorted(i for v in by_daemon.values() for i in v)
    # 1. `list` through the router sees the instances of both daemons, each daemon's under one id.
    def listed():
        r = t.cli(["list"], client_env, check=False)
        rows = list_instances(r.stdout)
        return rows if r.returncode == 0 and sorted(rows) == every else None
    rows = wait_for("every instance in `lodcloth list`", listed)
    ids = {d: {rows[i][1] for i in insts} for d, insts in by_daemon.items()}
    for d, got in ids.items():
        require(len(got) == 1, f"the instances of {d} are listed under several daemons: {got}")
    require(len({next(iter(v)) for v in ids.values()}) == len(ids), f"two daemons share an id: {ids}")
    log(f"list through the router: {len(rows)} instances from {len(ids)} daemons "
        + ", ".join(f"{d}={next(iter(v))[:8]}" for d, v in ids.items()))
    # 2. One instance of each daemon: its metrics (watch) and its states (record).
    for d, insts in by_daemon.items():
        r = t.cli(["watch", insts[0], "--count", "3"], client_env, timeout=60)
        lines = [ln for ln in r.stdout.splitlines()[2:] if ln.strip()]
        require(len(lines) == 3, f"watch {insts[0]}: expected 3 metrics lines, got {r.stdout}")
        out = t.dir / f"record-{insts[-1]}.lct"
        r = t.cli(["record", insts[-1], "--seconds", "2", "--out", str(out)], client_env, timeout=60)
        m = re.search(r"(\d+) frames of", r.stdout)
        require(m is not None and int(m.group(1)) >= 2, f"record {insts[-1]}: {r.stdout}")
        log(f"{d}: watch {insts[0]} got 3 metrics messages; record {insts[-1]} got {m.group(1)} states in 2 s")
    # 3. The view's API lists every instance, alive.
    view = t.c.services["view"]
    vport = t.port("view", int(str(view.spec["ports"][0]).split(":")[-1]))

    def view_lists():
        with urllib.request.urlopen(f"http://127.0.0.1:{vport}/api/instances", timeout=5) as resp:
            got = json.load(resp)
        alive = sorted(x["name"] for x in got if x.get("alive"))
        return got if alive == every else None
    wait_for("every instance alive in the view's /api/instances", view_lists, limit=30)
    log(f"view /api/instances lists all {len(every)} instances alive")
    # 4. A switch of an instance daemon-b owns is answered (by daemon-b).
    target = "sphere" if "sphere" in by_daemon["daemon-b"] else by_daemon["daemon-b"][0]
    level = "85" if target == "sphere" else "16x16"
    switch = ["switch", target, level, "--method", "same", "--timeout", "120"]
    if secure:
        r = t.cli(switch[:-1] + ["8"], secure["observer"], timeout=60, check=False)
        require(r.returncode != 0, f"an observer's switch of {target} succeeded:\n{r.stdout}")
        require("no reply" in r.stderr, f"an observer's switch of {target} failed otherwise: {r.stderr}")
        log(f"an observer's switch of {target} got no reply (the router's policy)")
        op = secure["operator"]
    else:
        op = client_env
    r = t.cli(switch, op, timeout=150)
    log(f"switch: {r.stdout.splitlines()[0]}")
    after = list_instances(t.cli(["list"], client_env).stdout)
    want = level + "pts" if target == "sphere" else level
    require(after[target][0] == want, f"{target} is at {after[target][0]} after the switch, not {want}")
    require(after[target][1] == next(iter(ids["daemon-b"])), f"{target} moved to another daemon: {after[target]}")
    # 5. Each daemon's operations endpoint (LODCLOTH_HTTP): /healthz judges
    # exactly its own instances healthy, /metrics counts the switch above on
    # the daemon that did it.
    for d, insts in by_daemon.items():
        s = t.c.services[d]
        http = s.env.get("LODCLOTH_HTTP")
        if not http:
            continue
        base = f"http://{t.addr(s, http)}"
        with urllib.request.urlopen(base + "/healthz", timeout=5) as resp:
            health = json.load(resp)
        require(resp.status == 200 and health["status"] == "ok", f"{d} /healthz: {health}")
        require(sorted(i["instance"] for i in health["instances"]) == sorted(insts),
                f"{d} /healthz judges {[i['instance'] for i in health['instances']]}, it owns {insts}")
        with urllib.request.urlopen(base + "/metrics", timeout=5) as resp:
            text = resp.read().decode()
        switches = f'lodcloth_switches_total{{instance="{target}"}} 1'
        require((switches in text) == (target in insts), f"{d} /metrics: {switches!r} {'missing' if target in insts else 'present'}")
        log(f"{d}: /healthz ok for {', '.join(insts)}; /metrics counts {'the' if target in insts else 'no'} switch")
    # 6. An operator touches a cloth of daemon-b's (the wind input; an
    # observer's gets no reply, secured), and a recorder started after it
    # gets that input from the daemon's episode log (`episode_inputs`).
    cloth = next(i for i in by_daemon["daemon-b"] if i != "sphere")
    wind = ["input", cloth, "wind", "--velocity", "1.5,0,0.5"]
    if secure:
        r = t.cli(wind, secure["observer"], timeout=60, check=False)
        require(r.returncode != 0 and "no reply" in r.stderr,
                f"an observer's input to {cloth} was not refused:\n{r.stdout}{r.stderr}")
        log(f"an observer's input to {cloth} got no reply (the router's policy)")
    r = t.cli(wind, op, timeout=60)
    log(f"input: {r.stdout.strip().splitlines()[0] if r.stdout.strip() else '(answered)'}")
    out = t.dir / f"record-{cloth}-touched.lct"
    r = t.cli(["record", cloth, "--seconds", "1", "--out", str(out)], client_env, timeout=60)
    m = re.search(r"with (\d+) inputs \((\d+) from before the recording began\)", r.stdout)
    require(m is not None and int(m.group(2)) >= 1 and "warning" not in r.stderr,
            f"record {cloth} after an input did not get it from the daemon:\n{r.stdout}{r.stderr}")
    log(f"record {cloth} after the input: {m.group(2)} input(s) from before it began")
    if secure:
        for label, env in secure["refused"].items():
            r = t.cli(["list"], env, timeout=60, check=False)
            require(r.returncode != 0 and "Unable to connect" in r.stderr + r.stdout,
                    f"a session with {label} was admitted:\n{r.stdout}{r.stderr}")
            log(f"a session with {label} is not admitted")


def run_plain(c: Compose) -> None:
    t = Topology(c, "plain")
    try:
        t.up()
        env = {"LODCLOTH_CONNECT": t.router_endpoint("tcp"), "LODCLOTH_CLIENT_MODE": "true"}
        exercise(t, env, None)
        t.down()
    except BaseException:
        t.kill_all()
        raise
    check_volumes(t)


def run_secure(c: Compose, secrets: Path) -> None:
    t = Topology(c, "secure")
    try:
        t.up()
        base = {"LODCLOTH_CONNECT": t.router_endpoint("quic"), "LODCLOTH_CLIENT_MODE": "true",
                "LODCLOTH_TLS_CA": str(secrets / "ca.pem")}

        def who(cert: str | None, user: str | None, password: str | None = None) -> dict[str, str]:
            env = dict(base)
            if cert:
                env |= {"LODCLOTH_TLS_CERT": str(secrets / f"{cert}.pem"), "LODCLOTH_TLS_KEY": str(secrets / f"{cert}.key")}
            if user:
                env |= {"LODCLOTH_USER": user,
                        "LODCLOTH_PASSWORD": password or (secrets / f"{user}.password").read_text().strip()}
            return env

        observer = who("viewer", "observer")
        roles = {
            "observer": observer,
            "operator": who("operator", "operator"),
            "refused": {
                "no client certificate": who(None, "operator"),
                "a wrong password": who("operator", "operator", "not-the-password"),
                "no account": who("viewer", None),
            },
        }
        exercise(t, observer, roles)
        t.down()
    except BaseException:
        t.kill_all()
        raise
    check_volumes(t)


def check_volumes(t: Topology) -> None:
    """The daemons wrote their caches and shutdown snapshots on their own volumes."""
    for s in t.c.services.values():
        if s.subcommand != "serve":
            continue
        conf = tomllib.loads(t.configs[s.name].read_text())
        env = t.env(s)
        snaps = Path(env.get("LODCLOTH_SNAPSHOT_DIR", conf["snapshots"]["dir"]))
        cache = Path(env.get("LODCLOTH_CACHE_DIR", conf["cache"]))
        require(cache.is_dir(), f"{s.name}: no cache directory {cache}")
        for i in s.instances:
            require((REPO / snaps / f"{i}.snapshot").is_file(), f"{s.name}: no snapshot of {i} in {snaps}")
        require(str(snaps).startswith(str(t.dir / "volumes")), f"{s.name}: snapshots outside its volume: {snaps}")
    log(f"{t.dir.name}: each daemon left its cache and its instances' snapshots on its own volume")


def main() -> int:
    # SIGTERM (CI's timeout, a user) unwinds like an error: the started processes are killed.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--static-only", action="store_true", help="skip running the topologies")
    ap.add_argument("--no-secure-run", action="store_true", help="run only the plain topology")
    args = ap.parse_args()
    require(BIN.is_file(), f"{BIN} is missing: build it first (cargo build --release)")
    OUT.mkdir(parents=True, exist_ok=True)
    secrets = OUT / "secrets"
    shutil.rmtree(secrets, ignore_errors=True)
    r = subprocess.run(["bash", str(COMPOSE_DIR / "make-secrets.sh"), str(secrets)], capture_output=True, text=True)
    require(r.returncode == 0, f"make-secrets.sh failed: {r.stdout}{r.stderr}")
    plain = load_compose(COMPOSE_DIR / "compose.yaml", None)
    secure = load_compose(COMPOSE_DIR / "compose.secure.yaml", secrets)
    static_checks(plain)
    static_checks(secure)
    compare_secure_configs(plain, secure)
    if args.static_only:
        return 0
    log(PRECOMPUTE_NOTE)
    run_plain(plain)
    if not args.no_secure_run:
        run_secure(secure, secrets)
    log(f"compose check passed in {time.monotonic() - T0:.1f} s")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except CheckError as e:
        log(f"FAILED: {e}")
        sys.exit(1)
