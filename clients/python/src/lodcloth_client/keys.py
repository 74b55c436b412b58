"""Every key expression of the service (the table in the header of
``proto/lodcloth/v1/lodcloth.proto``). ``prefix`` is ``lodcloth`` unless the
daemon is configured otherwise; ``instance`` may be ``*`` where a wildcard
makes sense (subscribing to every instance)."""

from __future__ import annotations

from typing import Optional

__all__ = [
    "DEFAULT_PREFIX",
    "state",
    "metrics",
    "info",
    "switch",
    "control",
    "input",
    "inputs",
    "episode_inputs",
    "instances",
    "alive",
    "instance_of",
    "alive_instance",
]

DEFAULT_PREFIX = "lodcloth"


def state(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/state``: ``State`` at the instance's publish rate."""
    return f"{prefix}/{instance}/state"


def metrics(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/metrics``: ``Metrics`` at the daemon's metrics rate."""
    return f"{prefix}/{instance}/metrics"


def info(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/info``: queryable answering ``InstanceInfo``."""
    return f"{prefix}/{instance}/info"


def switch(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/switch``: ``SwitchRequest`` -> ``SwitchReply``."""
    return f"{prefix}/{instance}/switch"


def control(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/control``: ``ControlRequest`` -> ``ControlReply``."""
    return f"{prefix}/{instance}/control"


def input(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/input``: ``InputRequest`` -> ``InputReply``."""
    return f"{prefix}/{instance}/input"


def inputs(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/inputs``: ``InputEvent`` for every input that took effect."""
    return f"{prefix}/{instance}/inputs"


def episode_inputs(prefix: str, instance: str) -> str:
    """``<prefix>/<instance>/episode_inputs``: queryable answering ``EpisodeInputs``
    (every input of the latest episode with inputs, so far)."""
    return f"{prefix}/{instance}/episode_inputs"


def instances(prefix: str) -> str:
    """``<prefix>/instances``: one ``InstanceList`` per daemon."""
    return f"{prefix}/instances"


def alive(prefix: str, instance: str) -> str:
    """``<prefix>/alive/<instance>``: liveliness token while the instance runs."""
    return f"{prefix}/alive/{instance}"


def instance_of(prefix: str, leaf: str, key: str) -> Optional[str]:
    """The instance named by a concrete key ``<prefix>/<instance>/<leaf>``
    (e.g. the key of a sample from a ``*`` subscription); None for other
    shapes, wildcards included."""
    head = prefix + "/"
    tail = "/" + leaf
    if not (key.startswith(head) and key.endswith(tail)):
        return None
    name = key[len(head) : len(key) - len(tail)]
    if not name or any(c in name for c in "/*$"):
        return None
    return name


def alive_instance(prefix: str, key: str) -> Optional[str]:
    """The instance named by a liveliness key ``<prefix>/alive/<instance>``."""
    head = prefix + "/alive/"
    name = key[len(head) :] if key.startswith(head) else ""
    return name or None
