"""Building and reading the contract's messages; nothing here needs a daemon.

* zenoh encodings: every message travels as
  ``application/protobuf;lodcloth.v1.<Message>`` (:func:`encoding_of`,
  :func:`schema_of`), and :func:`decode` checks that schema.
* levels: ``"16x16"`` for a grid cloth, ``"300"`` or ``"300pts"`` for a
  point-sampled surface (:func:`parse_level`, :func:`level_str`).
* packed coordinates: ``State.positions`` and its siblings are
  little-endian f32 ``x y z`` triples (:func:`unpack_vec3`,
  :func:`pack_vec3`, :func:`positions`). With numpy,
  ``numpy.frombuffer(state.positions, "<f4").reshape(-1, 3)`` is the same
  without a copy.
* refusals: an error reply carries ``lodcloth.v1.Error``
  (:func:`refusal`).
"""

from __future__ import annotations

import math
import struct
from typing import Iterable, List, Optional, Sequence, Tuple, Type, TypeVar, Union

from google.protobuf.message import DecodeError as _ProtobufDecodeError
from google.protobuf.message import Message

from . import v1
from .errors import DecodeError, RefusedError

__all__ = [
    "grab_request",
    "move_request",
    "release_request",
    "wind_request",
    "impulse_request",
    "move_pin_request",
    "MEDIA_TYPE",
    "LevelLike",
    "encoding_of",
    "schema_of",
    "decode",
    "refusal",
    "code_name",
    "make_level",
    "parse_level",
    "level_str",
    "unpack_vec3",
    "pack_vec3",
    "positions",
    "optional",
    "percent",
    "v_coefficients",
    "switch_request",
    "control_request",
    "ACTIONS",
]

#: The media type of every lodcloth payload; the schema follows a ``;``.
MEDIA_TYPE = "application/protobuf"

M = TypeVar("M", bound=Message)

#: What names a level: a ``Level`` message, ``"NXxNY"``, ``"N"``/``"Npts"``
#: (surface points), an ``int`` (surface points) or an ``(nx, ny)`` tuple.
LevelLike = Union["v1.Level", str, int, Tuple[int, int]]

Vec3 = Tuple[float, float, float]


def encoding_of(message: Union[Message, Type[Message], str]) -> str:
    """The zenoh encoding of a message (instance, class or bare name):
    ``application/protobuf;lodcloth.v1.SwitchRequest``."""
    if isinstance(message, str):
        name = message if "." in message else f"{v1.PACKAGE}.{message}"
    else:
        name = message.DESCRIPTOR.full_name
    return f"{MEDIA_TYPE};{name}"


def schema_of(encoding: Optional[str]) -> Optional[str]:
    """The schema of an ``application/protobuf;<schema>`` encoding (the
    message's full name), or None for any other encoding or none at all."""
    if not encoding:
        return None
    media, _, schema = str(encoding).partition(";")
    if media.strip() != MEDIA_TYPE or not schema.strip():
        return None
    return schema.strip()


def decode(cls: Type[M], payload: bytes, encoding: Optional[str] = None, key: str = "") -> M:
    """``payload`` as a ``cls`` message.

    When ``encoding`` names a protobuf schema it must be ``cls``'s: a
    mismatch (another message on the key) raises :class:`DecodeError`
    rather than decoding garbage. So does an undecodable payload.
    """
    expected = cls.DESCRIPTOR.full_name
    schema = schema_of(encoding)
    if schema is not None and schema != expected:
        raise DecodeError(key or "?", f"it carries {schema}, expected {expected}")
    try:
        return cls.FromString(bytes(payload))
    except _ProtobufDecodeError as e:
        raise DecodeError(key or "?", f"not a {expected}: {e}") from None


def code_name(code: int) -> str:
    """The name of an ``Error.Code`` (``CODE_BUSY``), or ``code N`` for a
    code newer than this package."""
    try:
        return v1.Error.Code.Name(code)
    except ValueError:
        return f"code {code}"


def refusal(payload: bytes, encoding: Optional[str], key: str = "") -> Optional[RefusedError]:
    """The daemon's refusal carried by an error reply, as a
    :class:`RefusedError`; None when the error reply is not a
    ``lodcloth.v1.Error`` (zenoh's own, e.g. its query timeout, is a
    ``zenoh/string``)."""
    enc = str(encoding) if encoding is not None else ""
    if not enc.startswith(MEDIA_TYPE):
        return None
    schema = schema_of(enc)
    if schema is not None and schema != v1.Error.DESCRIPTOR.full_name:
        return None
    try:
        err = v1.Error.FromString(bytes(payload))
    except _ProtobufDecodeError:
        return None
    return RefusedError(key or "?", err.code, code_name(err.code), err.message, err)


def make_level(nx: int = 0, ny: int = 0, points: int = 0, vertices: int = 0) -> "v1.Level":
    """A ``Level``: a grid of ``nx`` x ``ny`` nodes, a surface on ``points``
    points, or a mesh cloth simplified to ``vertices`` vertices (exactly one)."""
    if points < 0 or nx < 0 or ny < 0 or vertices < 0:
        raise ValueError("level sizes must not be negative")
    if sum(1 for given in (points, vertices, nx or ny) if given) > 1:
        raise ValueError("a level is a grid (nx, ny), a surface (points) or a mesh (vertices), not several")
    if not points and not vertices and (nx < 1 or ny < 1):
        raise ValueError("a level needs positive sizes: nx >= 1 and ny >= 1, points >= 1 or vertices >= 1")
    return v1.Level(nx=nx, ny=ny, points=points, vertices=vertices)


def parse_level(level: LevelLike) -> "v1.Level":
    """A ``Level`` from ``"16x16"`` (a cloth), ``"300"`` or ``"300pts"`` (a
    surface's simulated points), an int (points), an ``(nx, ny)`` tuple, or
    a ``Level`` (returned as is). Raises ValueError naming the problem."""
    if isinstance(level, v1.Level):
        return level
    if isinstance(level, bool):
        raise ValueError(f"level {level!r} is not a level")
    if isinstance(level, int):
        return make_level(points=level)
    if isinstance(level, tuple):
        if len(level) != 2:
            raise ValueError(f"level {level!r}: a tuple must be (nx, ny)")
        return make_level(nx=int(level[0]), ny=int(level[1]))
    if not isinstance(level, str):
        raise ValueError(f"level {level!r} is not a level")
    text = level.strip().lower()
    try:
        if "x" in text:
            nx_text, ny_text = text.split("x")
            sizes = {"nx": int(nx_text), "ny": int(ny_text)}
        elif text.endswith("v"):
            sizes = {"vertices": int(text[:-1])}
        else:
            sizes = {"points": int(text[: -len("pts")] if text.endswith("pts") else text)}
    except ValueError:
        raise ValueError(
            f"level '{level}' is not NXxNY (a cloth, e.g. 16x16) or N (a surface's points, e.g. 300)"
        ) from None
    try:
        return make_level(**sizes)
    except ValueError as e:
        raise ValueError(f"level '{level}': {e}") from None


def level_str(level: "v1.Level") -> str:
    """A grid cloth as ``NXxNY``, a point-sampled surface as ``Npts``, a
    mesh cloth as ``Nv``."""
    if level.vertices:
        return f"{level.vertices}v"
    return f"{level.points}pts" if level.points else f"{level.nx}x{level.ny}"


def unpack_vec3(raw: bytes) -> List[Vec3]:
    """Packed little-endian f32 ``x0 y0 z0 x1 y1 z1 ...`` as ``(x, y, z)``
    tuples. Raises ValueError when the length is not a multiple of 12."""
    if len(raw) % 12:
        raise ValueError(f"{len(raw)} bytes of packed coordinates, not a multiple of 12 (3 x f32)")
    return list(struct.iter_unpack("<3f", bytes(raw)))


def material_uv(info: "v1.InstanceInfo") -> List[Tuple[float, float]]:
    """``InstanceInfo.material_uv`` as ``(u, v)`` tuples, one per node of
    the current level (grid or mesh; empty for a surface): where an
    input's patch (``u``, ``v``) names a point of the cloth. Raises
    DecodeError when the bytes are not whole pairs or do not match the
    level's rest positions."""
    raw = bytes(info.material_uv)
    where = f"info of {info.instance or '?'}"
    if len(raw) % 8:
        raise DecodeError(where, f"{len(raw)} bytes of material coordinates, not a multiple of 8 (2 x f32)")
    uv = list(struct.iter_unpack("<2f", raw))
    nodes = len(info.rest_positions) // 12
    if uv and nodes and len(uv) != nodes:
        raise DecodeError(where, f"{len(uv)} material coordinates for {nodes} nodes")
    return uv


def pack_vec3(points: Iterable[Sequence[float]]) -> bytes:
    """The inverse of :func:`unpack_vec3` (values are rounded to f32)."""
    out = bytearray()
    for p in points:
        if len(p) != 3:
            raise ValueError(f"point {tuple(p)!r} does not have 3 coordinates")
        out += struct.pack("<3f", *p)
    return bytes(out)


def positions(state: "v1.State") -> List[Vec3]:
    """``State.positions`` as ``(x, y, z)`` tuples, checked against the
    level: a cloth has ``nx * ny`` nodes (node ``k`` at grid column
    ``k % nx``, row ``k // nx``); a surface publishes its whole cloud."""
    try:
        pts = unpack_vec3(state.positions)
    except ValueError as e:
        raise DecodeError(f"state of {state.instance or '?'} (frame {state.frame})", str(e)) from None
    lvl = state.level
    # A mesh level has about its asked vertex count (the simplifier's tolerance).
    if not lvl.points and not lvl.vertices and len(pts) != lvl.nx * lvl.ny:
        raise DecodeError(
            f"state of {state.instance or '?'} (frame {state.frame})",
            f"{len(pts)} nodes for level {level_str(lvl)}",
        )
    return pts


def optional(message: Message, field: str) -> Optional[float]:
    """An ``optional`` field's value, or None when it is absent (e.g.
    ``Metrics.predicted_error`` before calibration)."""
    return getattr(message, field) if message.HasField(field) else None


def percent(message: Message, field: str) -> str:
    """An optional relative-error field as ``"1.23 %"``, or ``"-"``."""
    value = optional(message, field)
    return "-" if value is None else f"{100 * value:.2f} %"


def v_coefficients(c: "v1.Coefficients") -> Tuple[Tuple[float, float], Tuple[float, float]]:
    """The structural and bend ``(K, C)`` along v: the ``_v`` fields, or
    the u ones where they are absent (square cells, or an older daemon)."""
    structural = (
        (c.structural_v_k, c.structural_v_c) if c.HasField("structural_v_k") else (c.structural_k, c.structural_c)
    )
    bend = (c.bend_v_k, c.bend_v_c) if c.HasField("bend_v_k") else (c.bend_k, c.bend_c)
    return structural, bend


def switch_request(
    level: Optional[LevelLike] = None,
    *,
    max_error: Optional[float] = None,
    method: Optional[str] = None,
    at_once: bool = False,
) -> "v1.SwitchRequest":
    """A ``SwitchRequest`` for exactly one target: a ``level`` (see
    :func:`parse_level`) or ``max_error`` (relative, 0.05 = 5 %: the
    cheapest allowed level predicted within it). ``method`` (same, gkd,
    fit, follow, drape) defaults to the instance's. ``at_once``: an unprepared
    level goes live with the scene's own coefficients and the estimate
    follows in place (the reply says ``refining``); level targets only."""
    if (level is None) == (max_error is None):
        raise ValueError("a switch needs exactly one of level and max_error")
    if at_once and level is None:
        raise ValueError("at_once applies to a level target, not max_error")
    req = v1.SwitchRequest(method=method or "", at_once=at_once)
    if level is not None:
        req.level.CopyFrom(parse_level(level))
    else:
        assert max_error is not None
        if not (max_error > 0 and math.isfinite(max_error)):
            raise ValueError(f"max_error {max_error} must be a positive relative error (0.05 = 5 %)")
        req.max_error = float(max_error)
    return req


#: The control actions by name.
ACTIONS = {
    "pause": v1.ControlRequest.ACTION_PAUSE,
    "resume": v1.ControlRequest.ACTION_RESUME,
    "reset": v1.ControlRequest.ACTION_RESET,
}


def control_request(action: Union[str, int]) -> "v1.ControlRequest":
    """A ``ControlRequest``: ``"pause"``, ``"resume"``, ``"reset"`` (or the
    ``ControlRequest.Action`` value)."""
    if isinstance(action, str):
        name = action.strip().lower()
    else:
        name = next((k for k, v in ACTIONS.items() if v == action), f"{action}")
    if name not in ACTIONS:
        raise ValueError(f"action '{action}' is not one of {', '.join(ACTIONS)}")
    return v1.ControlRequest(action=ACTIONS[name])


Vec3Like = Sequence[float]


def _vec3(name: str, p: Vec3Like) -> "v1.Vec3":
    values = [float(x) for x in p]
    if len(values) != 3:
        raise ValueError(f"{name} must be three numbers x, y, z, not {p!r}")
    return v1.Vec3(x=values[0], y=values[1], z=values[2])


def grab_request(
    u: float,
    v: float,
    target: Optional[Vec3Like] = None,
    *,
    id: int = 1,
    stiffness: float = 20.0,
    damping: float = 0.2,
    radius: float = 0.02,
) -> "v1.InputRequest":
    """An ``InputRequest`` grabbing the square patch of half-side ``radius``
    metres about material point (``u``, ``v``) (0..1 across the width from
    the left, down the height from the top) with a spring of ``stiffness``
    N/m and ``damping`` N·s/m to ``target`` (x, y, z in metres; None:
    where the patch is now, so the grab starts without a jerk and
    :func:`move_request` drags it). The daemon checks the ranges and the
    level's stability."""
    req = v1.InputRequest()
    req.grab.id = id
    req.grab.at.CopyFrom(v1.Patch(u=u, v=v, radius=radius))
    if target is not None:
        req.grab.target.CopyFrom(_vec3("target", target))
    req.grab.stiffness = stiffness
    req.grab.damping = damping
    return req


def move_request(target: Vec3Like, *, id: int = 1) -> "v1.InputRequest":
    """Move grab ``id``'s target (x, y, z in metres)."""
    req = v1.InputRequest()
    req.move.id = id
    req.move.target.CopyFrom(_vec3("target", target))
    return req


def release_request(id: Optional[int] = None) -> "v1.InputRequest":
    """Let go of grab ``id``, or of every grab when ``id`` is None."""
    req = v1.InputRequest()
    if id is None:
        req.release_all.SetInParent()
    else:
        req.release.id = id
    return req


def wind_request(velocity: Optional[Vec3Like], *, gust: float = 0.0, gust_hz: float = 0.0) -> "v1.InputRequest":
    """Replace the scene's wind with ``velocity`` (m/s) scaled by
    1 + gust·sin(2π·gust_hz·t); ``velocity=None`` returns to the scene's
    own wind."""
    req = v1.InputRequest()
    if velocity is None:
        req.scene_wind.SetInParent()
    else:
        req.wind.velocity.CopyFrom(_vec3("velocity", velocity))
        req.wind.gust = gust
        req.wind.gust_hz = gust_hz
    return req


def impulse_request(u: float, v: float, impulse: Vec3Like, *, radius: float = 0.05) -> "v1.InputRequest":
    """Strike the patch about (``u``, ``v``) with ``impulse`` (N·s)."""
    req = v1.InputRequest()
    req.impulse.at.CopyFrom(v1.Patch(u=u, v=v, radius=radius))
    req.impulse.impulse.CopyFrom(_vec3("impulse", impulse))
    return req


def move_pin_request(pin: int, offset: Vec3Like, *, seconds: float = 1.0) -> "v1.InputRequest":
    """Move the scene's pin set ``pin`` to ``offset`` (m) from its script
    over ``seconds`` of simulated time."""
    req = v1.InputRequest()
    req.move_pin.pin = pin
    req.move_pin.offset.CopyFrom(_vec3("offset", offset))
    req.move_pin.seconds = seconds
    return req
