"""A Python client of ``lodcloth serve``: list its instances, watch their
states and metrics, switch their level of detail, over Eclipse Zenoh.

    from lodcloth_client import Client, positions

    with Client.open(connect=["tcp/127.0.0.1:7450"]) as client:
        print([i.instance for i in client.instances()])
        for state in client.states("hanging", count=3):
            print(state.frame, state.time, len(positions(state)))
        print(client.switch("hanging", "24x24", timeout=300).seconds)

The messages are the wire contract's (``proto/lodcloth/v1/lodcloth.proto``),
generated into :mod:`lodcloth_client.v1` and shipped with the package: no
protoc is needed to install or run it. The command line is ``lodcloth-py``
(or ``python -m lodcloth_client``).
"""

from . import keys, v1
from .client import Client, Subscription, Watch
from .codec import (
    LevelLike,
    code_name,
    control_request,
    decode,
    grab_request,
    impulse_request,
    move_pin_request,
    move_request,
    release_request,
    wind_request,
    encoding_of,
    level_str,
    make_level,
    material_uv,
    optional,
    pack_vec3,
    parse_level,
    percent,
    positions,
    refusal,
    schema_of,
    switch_request,
    unpack_vec3,
    v_coefficients,
)
from .errors import (
    ConnectError,
    DecodeError,
    LodclothError,
    NoDataError,
    NoReplyError,
    RefusedError,
    ZenohError,
)
from .options import DEFAULT_ENDPOINT, ConnectOptions

__version__ = "0.1.0"

__all__ = [
    "__version__",
    "v1",
    "keys",
    "Client",
    "Watch",
    "Subscription",
    "ConnectOptions",
    "DEFAULT_ENDPOINT",
    "LodclothError",
    "ConnectError",
    "ZenohError",
    "NoReplyError",
    "RefusedError",
    "DecodeError",
    "NoDataError",
    "LevelLike",
    "code_name",
    "control_request",
    "grab_request",
    "impulse_request",
    "move_pin_request",
    "move_request",
    "release_request",
    "wind_request",
    "decode",
    "encoding_of",
    "level_str",
    "make_level",
    "optional",
    "material_uv",
    "pack_vec3",
    "parse_level",
    "percent",
    "positions",
    "refusal",
    "schema_of",
    "switch_request",
    "unpack_vec3",
    "v_coefficients",
]
