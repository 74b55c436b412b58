"""How a client joins zenoh: the same options, defaults and environment
variables as the Rust CLI's (``lodcloth list --help``)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import List, Mapping, Optional, Union

import zenoh

from .errors import ConnectError
from .keys import DEFAULT_PREFIX

__all__ = ["DEFAULT_ENDPOINT", "ConnectOptions"]

#: The default config's listen endpoint (loopback).
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7450"

PathLike = Union[str, "os.PathLike[str]"]

_TRUE = {"1", "true", "yes", "on", "y"}
_FALSE = {"", "0", "false", "no", "off", "n"}


@dataclass
class ConnectOptions:
    """Where and how to reach a daemon.

    ``connect``: zenoh endpoints of daemons or routers (a client connects to
    every one, so several daemons are seen at once); empty: discover peers by
    multicast. ``client_mode``: zenoh ``client`` mode, one connection through
    a router (re-established when the router restarts), instead of a peer.
    ``user``/``password``: for a daemon that authenticates. ``tls_ca``: PEM of
    the CA that signed the daemon's certificate (``quic/`` and ``tls/`` endpoints);
    ``tls_cert``/``tls_key``: this client's certificate and key, for a
    daemon that requires mTLS.
    """

    connect: List[str] = field(default_factory=lambda: [DEFAULT_ENDPOINT])
    prefix: str = DEFAULT_PREFIX
    client_mode: bool = False
    user: Optional[str] = None
    password: Optional[str] = field(default=None, repr=False)
    tls_ca: Optional[PathLike] = None
    tls_cert: Optional[PathLike] = None
    tls_key: Optional[PathLike] = None

    @classmethod
    def from_env(cls, environ: Optional[Mapping[str, str]] = None, **overrides) -> "ConnectOptions":
        """Options from the environment variables the Rust CLI reads:
        ``LODCLOTH_CONNECT`` (comma separated), ``LODCLOTH_CLIENT_MODE``,
        ``LODCLOTH_USER``, ``LODCLOTH_PASSWORD``, ``LODCLOTH_TLS_CA``,
        ``LODCLOTH_TLS_CERT``, ``LODCLOTH_TLS_KEY``; keyword arguments that
        are not None override them."""
        env = os.environ if environ is None else environ
        values: dict = {}
        if "LODCLOTH_CONNECT" in env:
            values["connect"] = split_endpoints(env["LODCLOTH_CONNECT"])
        if "LODCLOTH_CLIENT_MODE" in env:
            flag = env["LODCLOTH_CLIENT_MODE"].strip().lower()
            if flag not in _TRUE | _FALSE:
                raise ConnectError(f"LODCLOTH_CLIENT_MODE={env['LODCLOTH_CLIENT_MODE']!r} is neither true nor false")
            values["client_mode"] = flag in _TRUE
        for name, var in [
            ("user", "LODCLOTH_USER"),
            ("password", "LODCLOTH_PASSWORD"),
            ("tls_ca", "LODCLOTH_TLS_CA"),
            ("tls_cert", "LODCLOTH_TLS_CERT"),
            ("tls_key", "LODCLOTH_TLS_KEY"),
        ]:
            if env.get(var):
                values[name] = env[var]
        known = {f.name for f in fields(cls)}
        for name, value in overrides.items():
            if name not in known:
                raise TypeError(f"ConnectOptions has no option {name!r}")
            if value is not None:
                values[name] = value
        return cls(**values)

    def problems(self) -> List[str]:
        """What is inconsistent or missing, by option name (empty: fine)."""
        p = []
        if isinstance(self.connect, str):
            p.append("connect must be a list of endpoints, not a string")
        if (self.user is None) != (self.password is None):
            p.append("user and password go together")
        if (self.tls_cert is None) != (self.tls_key is None):
            p.append("tls_cert and tls_key go together")
        for name in ("tls_ca", "tls_cert", "tls_key"):
            f = getattr(self, name)
            if f is not None and not Path(f).is_file():
                p.append(f"{name}: {f} is not a readable file")
        if self.client_mode and not self.connect:
            p.append("client mode needs an endpoint to connect to")
        if not self.prefix or self.prefix.endswith("/") or any(c in self.prefix for c in "*$?#"):
            p.append(f"prefix {self.prefix!r} is not a plain key expression")
        return p

    def zenoh_config(self) -> "zenoh.Config":
        """The zenoh session config of these options (see the Rust
        ``client_config``): peer or client mode, listening on nothing,
        multicast scouting off when endpoints are given, credentials and
        certificates set. Raises :class:`ConnectError` listing the problems."""
        problems = self.problems()
        if problems:
            raise ConnectError("; ".join(problems))
        c = zenoh.Config()

        def put(key: str, value) -> None:
            try:
                c.insert_json5(key, json.dumps(value))
            except zenoh.ZError as e:
                raise ConnectError(f"zenoh config {key}: {e}") from None

        put("mode", "client" if self.client_mode else "peer")
        put("listen/endpoints", [])
        if self.connect:
            put("connect/endpoints", list(self.connect))
            put("scouting/multicast/enabled", False)
        tls = "transport/link/tls"
        if self.tls_ca is not None:
            put(f"{tls}/root_ca_certificate", os.fspath(self.tls_ca))
        if self.tls_cert is not None and self.tls_key is not None:
            put(f"{tls}/connect_certificate", os.fspath(self.tls_cert))
            put(f"{tls}/connect_private_key", os.fspath(self.tls_key))
            # The client side of mTLS: present the certificate.
            put(f"{tls}/enable_mtls", True)
        if self.user is not None and self.password is not None:
            put("transport/auth/usrpwd/user", self.user)
            put("transport/auth/usrpwd/password", self.password)
        return c


def split_endpoints(text: str) -> List[str]:
    """``"tcp/a:1, tcp/b:2"`` -> ``["tcp/a:1", "tcp/b:2"]`` (empty parts dropped)."""
    return [e.strip() for e in text.split(",") if e.strip()]
