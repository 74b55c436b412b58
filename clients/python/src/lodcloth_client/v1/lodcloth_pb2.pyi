from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Level(_message.Message):
    __slots__ = ("nx", "ny", "points", "vertices")
    NX_FIELD_NUMBER: _ClassVar[int]
    NY_FIELD_NUMBER: _ClassVar[int]
    POINTS_FIELD_NUMBER: _ClassVar[int]
    VERTICES_FIELD_NUMBER: _ClassVar[int]
    nx: int
    ny: int
    points: int
    vertices: int
    def __init__(self, nx: _Optional[int] = ..., ny: _Optional[int] = ..., points: _Optional[int] = ..., vertices: _Optional[int] = ...) -> None: ...

class Coefficients(_message.Message):
    __slots__ = ("structural_k", "structural_c", "shear_k", "shear_c", "bend_k", "bend_c", "structural_v_k", "structural_v_c", "bend_v_k", "bend_v_c")
    STRUCTURAL_K_FIELD_NUMBER: _ClassVar[int]
    STRUCTURAL_C_FIELD_NUMBER: _ClassVar[int]
    SHEAR_K_FIELD_NUMBER: _ClassVar[int]
    SHEAR_C_FIELD_NUMBER: _ClassVar[int]
    BEND_K_FIELD_NUMBER: _ClassVar[int]
    BEND_C_FIELD_NUMBER: _ClassVar[int]
    STRUCTURAL_V_K_FIELD_NUMBER: _ClassVar[int]
    STRUCTURAL_V_C_FIELD_NUMBER: _ClassVar[int]
    BEND_V_K_FIELD_NUMBER: _ClassVar[int]
    BEND_V_C_FIELD_NUMBER: _ClassVar[int]
    structural_k: float
    structural_c: float
    shear_k: float
    shear_c: float
    bend_k: float
    bend_c: float
    structural_v_k: float
    structural_v_c: float
    bend_v_k: float
    bend_v_c: float
    def __init__(self, structural_k: _Optional[float] = ..., structural_c: _Optional[float] = ..., shear_k: _Optional[float] = ..., shear_c: _Optional[float] = ..., bend_k: _Optional[float] = ..., bend_c: _Optional[float] = ..., structural_v_k: _Optional[float] = ..., structural_v_c: _Optional[float] = ..., bend_v_k: _Optional[float] = ..., bend_v_c: _Optional[float] = ...) -> None: ...

class State(_message.Message):
    __slots__ = ("instance", "frame", "time", "level", "coefficient_version", "positions", "episode", "stepped_unix_nanos", "transition", "simulation_positions", "normals", "reference_positions", "collider_positions")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    COEFFICIENT_VERSION_FIELD_NUMBER: _ClassVar[int]
    POSITIONS_FIELD_NUMBER: _ClassVar[int]
    EPISODE_FIELD_NUMBER: _ClassVar[int]
    STEPPED_UNIX_NANOS_FIELD_NUMBER: _ClassVar[int]
    TRANSITION_FIELD_NUMBER: _ClassVar[int]
    SIMULATION_POSITIONS_FIELD_NUMBER: _ClassVar[int]
    NORMALS_FIELD_NUMBER: _ClassVar[int]
    REFERENCE_POSITIONS_FIELD_NUMBER: _ClassVar[int]
    COLLIDER_POSITIONS_FIELD_NUMBER: _ClassVar[int]
    instance: str
    frame: int
    time: float
    level: Level
    coefficient_version: int
    positions: bytes
    episode: int
    stepped_unix_nanos: int
    transition: bool
    simulation_positions: bytes
    normals: bytes
    reference_positions: bytes
    collider_positions: bytes
    def __init__(self, instance: _Optional[str] = ..., frame: _Optional[int] = ..., time: _Optional[float] = ..., level: _Optional[_Union[Level, _Mapping]] = ..., coefficient_version: _Optional[int] = ..., positions: _Optional[bytes] = ..., episode: _Optional[int] = ..., stepped_unix_nanos: _Optional[int] = ..., transition: bool = ..., simulation_positions: _Optional[bytes] = ..., normals: _Optional[bytes] = ..., reference_positions: _Optional[bytes] = ..., collider_positions: _Optional[bytes] = ...) -> None: ...

class Metrics(_message.Message):
    __slots__ = ("instance", "frame", "time", "level", "method", "predicted_error", "live_error", "step_cost_us", "real_time_factor", "overruns", "kinetic_energy", "potential_energy", "max_strain", "coefficient_version", "paused", "dt", "steps", "lag_resets", "divergences", "rollbacks", "halted", "inputs", "touched", "live_error_time", "predicted_error_under_input")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    PREDICTED_ERROR_FIELD_NUMBER: _ClassVar[int]
    LIVE_ERROR_FIELD_NUMBER: _ClassVar[int]
    STEP_COST_US_FIELD_NUMBER: _ClassVar[int]
    REAL_TIME_FACTOR_FIELD_NUMBER: _ClassVar[int]
    OVERRUNS_FIELD_NUMBER: _ClassVar[int]
    KINETIC_ENERGY_FIELD_NUMBER: _ClassVar[int]
    POTENTIAL_ENERGY_FIELD_NUMBER: _ClassVar[int]
    MAX_STRAIN_FIELD_NUMBER: _ClassVar[int]
    COEFFICIENT_VERSION_FIELD_NUMBER: _ClassVar[int]
    PAUSED_FIELD_NUMBER: _ClassVar[int]
    DT_FIELD_NUMBER: _ClassVar[int]
    STEPS_FIELD_NUMBER: _ClassVar[int]
    LAG_RESETS_FIELD_NUMBER: _ClassVar[int]
    DIVERGENCES_FIELD_NUMBER: _ClassVar[int]
    ROLLBACKS_FIELD_NUMBER: _ClassVar[int]
    HALTED_FIELD_NUMBER: _ClassVar[int]
    INPUTS_FIELD_NUMBER: _ClassVar[int]
    TOUCHED_FIELD_NUMBER: _ClassVar[int]
    LIVE_ERROR_TIME_FIELD_NUMBER: _ClassVar[int]
    PREDICTED_ERROR_UNDER_INPUT_FIELD_NUMBER: _ClassVar[int]
    instance: str
    frame: int
    time: float
    level: Level
    method: str
    predicted_error: float
    live_error: float
    step_cost_us: float
    real_time_factor: float
    overruns: int
    kinetic_energy: float
    potential_energy: float
    max_strain: float
    coefficient_version: int
    paused: bool
    dt: float
    steps: int
    lag_resets: int
    divergences: int
    rollbacks: int
    halted: str
    inputs: int
    touched: bool
    live_error_time: float
    predicted_error_under_input: float
    def __init__(self, instance: _Optional[str] = ..., frame: _Optional[int] = ..., time: _Optional[float] = ..., level: _Optional[_Union[Level, _Mapping]] = ..., method: _Optional[str] = ..., predicted_error: _Optional[float] = ..., live_error: _Optional[float] = ..., step_cost_us: _Optional[float] = ..., real_time_factor: _Optional[float] = ..., overruns: _Optional[int] = ..., kinetic_energy: _Optional[float] = ..., potential_energy: _Optional[float] = ..., max_strain: _Optional[float] = ..., coefficient_version: _Optional[int] = ..., paused: bool = ..., dt: _Optional[float] = ..., steps: _Optional[int] = ..., lag_resets: _Optional[int] = ..., divergences: _Optional[int] = ..., rollbacks: _Optional[int] = ..., halted: _Optional[str] = ..., inputs: _Optional[int] = ..., touched: bool = ..., live_error_time: _Optional[float] = ..., predicted_error_under_input: _Optional[float] = ...) -> None: ...

class LevelInfo(_message.Message):
    __slots__ = ("level", "predicted_error", "dt", "ready", "predicted_error_under_input")
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    PREDICTED_ERROR_FIELD_NUMBER: _ClassVar[int]
    DT_FIELD_NUMBER: _ClassVar[int]
    READY_FIELD_NUMBER: _ClassVar[int]
    PREDICTED_ERROR_UNDER_INPUT_FIELD_NUMBER: _ClassVar[int]
    level: Level
    predicted_error: float
    dt: float
    ready: bool
    predicted_error_under_input: float
    def __init__(self, level: _Optional[_Union[Level, _Mapping]] = ..., predicted_error: _Optional[float] = ..., dt: _Optional[float] = ..., ready: bool = ..., predicted_error_under_input: _Optional[float] = ...) -> None: ...

class InstanceInfo(_message.Message):
    __slots__ = ("instance", "scene", "description", "level", "reference", "levels", "method", "integrator", "dt", "coefficients", "coefficient_version", "triangles", "pinned", "publish_hz", "o_max", "shadow_reference", "paused", "kind", "simulation_points", "cloud_points", "rest_positions", "halted", "colliders", "material_uv")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    SCENE_FIELD_NUMBER: _ClassVar[int]
    DESCRIPTION_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    REFERENCE_FIELD_NUMBER: _ClassVar[int]
    LEVELS_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    INTEGRATOR_FIELD_NUMBER: _ClassVar[int]
    DT_FIELD_NUMBER: _ClassVar[int]
    COEFFICIENTS_FIELD_NUMBER: _ClassVar[int]
    COEFFICIENT_VERSION_FIELD_NUMBER: _ClassVar[int]
    TRIANGLES_FIELD_NUMBER: _ClassVar[int]
    PINNED_FIELD_NUMBER: _ClassVar[int]
    PUBLISH_HZ_FIELD_NUMBER: _ClassVar[int]
    O_MAX_FIELD_NUMBER: _ClassVar[int]
    SHADOW_REFERENCE_FIELD_NUMBER: _ClassVar[int]
    PAUSED_FIELD_NUMBER: _ClassVar[int]
    KIND_FIELD_NUMBER: _ClassVar[int]
    SIMULATION_POINTS_FIELD_NUMBER: _ClassVar[int]
    CLOUD_POINTS_FIELD_NUMBER: _ClassVar[int]
    REST_POSITIONS_FIELD_NUMBER: _ClassVar[int]
    HALTED_FIELD_NUMBER: _ClassVar[int]
    COLLIDERS_FIELD_NUMBER: _ClassVar[int]
    MATERIAL_UV_FIELD_NUMBER: _ClassVar[int]
    instance: str
    scene: str
    description: str
    level: Level
    reference: Level
    levels: _containers.RepeatedCompositeFieldContainer[LevelInfo]
    method: str
    integrator: str
    dt: float
    coefficients: Coefficients
    coefficient_version: int
    triangles: _containers.RepeatedScalarFieldContainer[int]
    pinned: _containers.RepeatedScalarFieldContainer[int]
    publish_hz: float
    o_max: float
    shadow_reference: bool
    paused: bool
    kind: str
    simulation_points: _containers.RepeatedScalarFieldContainer[int]
    cloud_points: int
    rest_positions: bytes
    halted: str
    colliders: _containers.RepeatedCompositeFieldContainer[Collider]
    material_uv: bytes
    def __init__(self, instance: _Optional[str] = ..., scene: _Optional[str] = ..., description: _Optional[str] = ..., level: _Optional[_Union[Level, _Mapping]] = ..., reference: _Optional[_Union[Level, _Mapping]] = ..., levels: _Optional[_Iterable[_Union[LevelInfo, _Mapping]]] = ..., method: _Optional[str] = ..., integrator: _Optional[str] = ..., dt: _Optional[float] = ..., coefficients: _Optional[_Union[Coefficients, _Mapping]] = ..., coefficient_version: _Optional[int] = ..., triangles: _Optional[_Iterable[int]] = ..., pinned: _Optional[_Iterable[int]] = ..., publish_hz: _Optional[float] = ..., o_max: _Optional[float] = ..., shadow_reference: bool = ..., paused: bool = ..., kind: _Optional[str] = ..., simulation_points: _Optional[_Iterable[int]] = ..., cloud_points: _Optional[int] = ..., rest_positions: _Optional[bytes] = ..., halted: _Optional[str] = ..., colliders: _Optional[_Iterable[_Union[Collider, _Mapping]]] = ..., material_uv: _Optional[bytes] = ...) -> None: ...

class Collider(_message.Message):
    __slots__ = ("shape", "position", "axis", "radius", "half_extents", "friction", "clearance", "triangles")
    SHAPE_FIELD_NUMBER: _ClassVar[int]
    POSITION_FIELD_NUMBER: _ClassVar[int]
    AXIS_FIELD_NUMBER: _ClassVar[int]
    RADIUS_FIELD_NUMBER: _ClassVar[int]
    HALF_EXTENTS_FIELD_NUMBER: _ClassVar[int]
    FRICTION_FIELD_NUMBER: _ClassVar[int]
    CLEARANCE_FIELD_NUMBER: _ClassVar[int]
    TRIANGLES_FIELD_NUMBER: _ClassVar[int]
    shape: str
    position: Vec3
    axis: Vec3
    radius: float
    half_extents: Vec3
    friction: float
    clearance: float
    triangles: bytes
    def __init__(self, shape: _Optional[str] = ..., position: _Optional[_Union[Vec3, _Mapping]] = ..., axis: _Optional[_Union[Vec3, _Mapping]] = ..., radius: _Optional[float] = ..., half_extents: _Optional[_Union[Vec3, _Mapping]] = ..., friction: _Optional[float] = ..., clearance: _Optional[float] = ..., triangles: _Optional[bytes] = ...) -> None: ...

class InstanceSummary(_message.Message):
    __slots__ = ("instance", "scene", "level", "method", "publish_hz")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    SCENE_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    PUBLISH_HZ_FIELD_NUMBER: _ClassVar[int]
    instance: str
    scene: str
    level: Level
    method: str
    publish_hz: float
    def __init__(self, instance: _Optional[str] = ..., scene: _Optional[str] = ..., level: _Optional[_Union[Level, _Mapping]] = ..., method: _Optional[str] = ..., publish_hz: _Optional[float] = ...) -> None: ...

class InstanceList(_message.Message):
    __slots__ = ("daemon", "instances")
    DAEMON_FIELD_NUMBER: _ClassVar[int]
    INSTANCES_FIELD_NUMBER: _ClassVar[int]
    daemon: str
    instances: _containers.RepeatedCompositeFieldContainer[InstanceSummary]
    def __init__(self, daemon: _Optional[str] = ..., instances: _Optional[_Iterable[_Union[InstanceSummary, _Mapping]]] = ...) -> None: ...

class SwitchRequest(_message.Message):
    __slots__ = ("level", "max_error", "method", "at_once")
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    MAX_ERROR_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    AT_ONCE_FIELD_NUMBER: _ClassVar[int]
    level: Level
    max_error: float
    method: str
    at_once: bool
    def __init__(self, level: _Optional[_Union[Level, _Mapping]] = ..., max_error: _Optional[float] = ..., method: _Optional[str] = ..., at_once: bool = ...) -> None: ...

class SwitchReply(_message.Message):
    __slots__ = ("instance", "previous", "level", "method", "coefficients", "predicted_error", "dt", "seconds", "cached", "coefficient_version", "frame", "refining", "predicted_error_under_input")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    PREVIOUS_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    COEFFICIENTS_FIELD_NUMBER: _ClassVar[int]
    PREDICTED_ERROR_FIELD_NUMBER: _ClassVar[int]
    DT_FIELD_NUMBER: _ClassVar[int]
    SECONDS_FIELD_NUMBER: _ClassVar[int]
    CACHED_FIELD_NUMBER: _ClassVar[int]
    COEFFICIENT_VERSION_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    REFINING_FIELD_NUMBER: _ClassVar[int]
    PREDICTED_ERROR_UNDER_INPUT_FIELD_NUMBER: _ClassVar[int]
    instance: str
    previous: Level
    level: Level
    method: str
    coefficients: Coefficients
    predicted_error: float
    dt: float
    seconds: float
    cached: bool
    coefficient_version: int
    frame: int
    refining: bool
    predicted_error_under_input: float
    def __init__(self, instance: _Optional[str] = ..., previous: _Optional[_Union[Level, _Mapping]] = ..., level: _Optional[_Union[Level, _Mapping]] = ..., method: _Optional[str] = ..., coefficients: _Optional[_Union[Coefficients, _Mapping]] = ..., predicted_error: _Optional[float] = ..., dt: _Optional[float] = ..., seconds: _Optional[float] = ..., cached: bool = ..., coefficient_version: _Optional[int] = ..., frame: _Optional[int] = ..., refining: bool = ..., predicted_error_under_input: _Optional[float] = ...) -> None: ...

class ControlRequest(_message.Message):
    __slots__ = ("action",)
    class Action(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        ACTION_UNSPECIFIED: _ClassVar[ControlRequest.Action]
        ACTION_PAUSE: _ClassVar[ControlRequest.Action]
        ACTION_RESUME: _ClassVar[ControlRequest.Action]
        ACTION_RESET: _ClassVar[ControlRequest.Action]
    ACTION_UNSPECIFIED: ControlRequest.Action
    ACTION_PAUSE: ControlRequest.Action
    ACTION_RESUME: ControlRequest.Action
    ACTION_RESET: ControlRequest.Action
    ACTION_FIELD_NUMBER: _ClassVar[int]
    action: ControlRequest.Action
    def __init__(self, action: _Optional[_Union[ControlRequest.Action, str]] = ...) -> None: ...

class ControlReply(_message.Message):
    __slots__ = ("instance", "paused", "frame")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    PAUSED_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    instance: str
    paused: bool
    frame: int
    def __init__(self, instance: _Optional[str] = ..., paused: bool = ..., frame: _Optional[int] = ...) -> None: ...

class Error(_message.Message):
    __slots__ = ("code", "message")
    class Code(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        CODE_UNSPECIFIED: _ClassVar[Error.Code]
        CODE_BAD_REQUEST: _ClassVar[Error.Code]
        CODE_UNKNOWN_INSTANCE: _ClassVar[Error.Code]
        CODE_LEVEL_NOT_ALLOWED: _ClassVar[Error.Code]
        CODE_UNSTABLE: _ClassVar[Error.Code]
        CODE_ESTIMATION_FAILED: _ClassVar[Error.Code]
        CODE_UNAVAILABLE: _ClassVar[Error.Code]
        CODE_NO_LEVEL_MEETS_ERROR: _ClassVar[Error.Code]
        CODE_BUSY: _ClassVar[Error.Code]
    CODE_UNSPECIFIED: Error.Code
    CODE_BAD_REQUEST: Error.Code
    CODE_UNKNOWN_INSTANCE: Error.Code
    CODE_LEVEL_NOT_ALLOWED: Error.Code
    CODE_UNSTABLE: Error.Code
    CODE_ESTIMATION_FAILED: Error.Code
    CODE_UNAVAILABLE: Error.Code
    CODE_NO_LEVEL_MEETS_ERROR: Error.Code
    CODE_BUSY: Error.Code
    CODE_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    code: Error.Code
    message: str
    def __init__(self, code: _Optional[_Union[Error.Code, str]] = ..., message: _Optional[str] = ...) -> None: ...

class Vec3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Patch(_message.Message):
    __slots__ = ("u", "v", "radius")
    U_FIELD_NUMBER: _ClassVar[int]
    V_FIELD_NUMBER: _ClassVar[int]
    RADIUS_FIELD_NUMBER: _ClassVar[int]
    u: float
    v: float
    radius: float
    def __init__(self, u: _Optional[float] = ..., v: _Optional[float] = ..., radius: _Optional[float] = ...) -> None: ...

class InputRequest(_message.Message):
    __slots__ = ("grab", "move", "release", "release_all", "move_pin", "wind", "scene_wind", "impulse")
    class Grab(_message.Message):
        __slots__ = ("id", "at", "target", "stiffness", "damping")
        ID_FIELD_NUMBER: _ClassVar[int]
        AT_FIELD_NUMBER: _ClassVar[int]
        TARGET_FIELD_NUMBER: _ClassVar[int]
        STIFFNESS_FIELD_NUMBER: _ClassVar[int]
        DAMPING_FIELD_NUMBER: _ClassVar[int]
        id: int
        at: Patch
        target: Vec3
        stiffness: float
        damping: float
        def __init__(self, id: _Optional[int] = ..., at: _Optional[_Union[Patch, _Mapping]] = ..., target: _Optional[_Union[Vec3, _Mapping]] = ..., stiffness: _Optional[float] = ..., damping: _Optional[float] = ...) -> None: ...
    class Move(_message.Message):
        __slots__ = ("id", "target")
        ID_FIELD_NUMBER: _ClassVar[int]
        TARGET_FIELD_NUMBER: _ClassVar[int]
        id: int
        target: Vec3
        def __init__(self, id: _Optional[int] = ..., target: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...
    class Release(_message.Message):
        __slots__ = ("id",)
        ID_FIELD_NUMBER: _ClassVar[int]
        id: int
        def __init__(self, id: _Optional[int] = ...) -> None: ...
    class ReleaseAll(_message.Message):
        __slots__ = ()
        def __init__(self) -> None: ...
    class MovePin(_message.Message):
        __slots__ = ("pin", "offset", "seconds")
        PIN_FIELD_NUMBER: _ClassVar[int]
        OFFSET_FIELD_NUMBER: _ClassVar[int]
        SECONDS_FIELD_NUMBER: _ClassVar[int]
        pin: int
        offset: Vec3
        seconds: float
        def __init__(self, pin: _Optional[int] = ..., offset: _Optional[_Union[Vec3, _Mapping]] = ..., seconds: _Optional[float] = ...) -> None: ...
    class Wind(_message.Message):
        __slots__ = ("velocity", "gust", "gust_hz")
        VELOCITY_FIELD_NUMBER: _ClassVar[int]
        GUST_FIELD_NUMBER: _ClassVar[int]
        GUST_HZ_FIELD_NUMBER: _ClassVar[int]
        velocity: Vec3
        gust: float
        gust_hz: float
        def __init__(self, velocity: _Optional[_Union[Vec3, _Mapping]] = ..., gust: _Optional[float] = ..., gust_hz: _Optional[float] = ...) -> None: ...
    class SceneWind(_message.Message):
        __slots__ = ()
        def __init__(self) -> None: ...
    class Impulse(_message.Message):
        __slots__ = ("at", "impulse")
        AT_FIELD_NUMBER: _ClassVar[int]
        IMPULSE_FIELD_NUMBER: _ClassVar[int]
        at: Patch
        impulse: Vec3
        def __init__(self, at: _Optional[_Union[Patch, _Mapping]] = ..., impulse: _Optional[_Union[Vec3, _Mapping]] = ...) -> None: ...
    GRAB_FIELD_NUMBER: _ClassVar[int]
    MOVE_FIELD_NUMBER: _ClassVar[int]
    RELEASE_FIELD_NUMBER: _ClassVar[int]
    RELEASE_ALL_FIELD_NUMBER: _ClassVar[int]
    MOVE_PIN_FIELD_NUMBER: _ClassVar[int]
    WIND_FIELD_NUMBER: _ClassVar[int]
    SCENE_WIND_FIELD_NUMBER: _ClassVar[int]
    IMPULSE_FIELD_NUMBER: _ClassVar[int]
    grab: InputRequest.Grab
    move: InputRequest.Move
    release: InputRequest.Release
    release_all: InputRequest.ReleaseAll
    move_pin: InputRequest.MovePin
    wind: InputRequest.Wind
    scene_wind: InputRequest.SceneWind
    impulse: InputRequest.Impulse
    def __init__(self, grab: _Optional[_Union[InputRequest.Grab, _Mapping]] = ..., move: _Optional[_Union[InputRequest.Move, _Mapping]] = ..., release: _Optional[_Union[InputRequest.Release, _Mapping]] = ..., release_all: _Optional[_Union[InputRequest.ReleaseAll, _Mapping]] = ..., move_pin: _Optional[_Union[InputRequest.MovePin, _Mapping]] = ..., wind: _Optional[_Union[InputRequest.Wind, _Mapping]] = ..., scene_wind: _Optional[_Union[InputRequest.SceneWind, _Mapping]] = ..., impulse: _Optional[_Union[InputRequest.Impulse, _Mapping]] = ...) -> None: ...

class InputReply(_message.Message):
    __slots__ = ("instance", "frame", "time", "grabs", "level")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    GRABS_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    instance: str
    frame: int
    time: float
    grabs: _containers.RepeatedScalarFieldContainer[int]
    level: Level
    def __init__(self, instance: _Optional[str] = ..., frame: _Optional[int] = ..., time: _Optional[float] = ..., grabs: _Optional[_Iterable[int]] = ..., level: _Optional[_Union[Level, _Mapping]] = ...) -> None: ...

class InputEvent(_message.Message):
    __slots__ = ("instance", "frame", "time", "episode", "level", "input", "idle", "seq")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    FRAME_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    EPISODE_FIELD_NUMBER: _ClassVar[int]
    LEVEL_FIELD_NUMBER: _ClassVar[int]
    INPUT_FIELD_NUMBER: _ClassVar[int]
    IDLE_FIELD_NUMBER: _ClassVar[int]
    SEQ_FIELD_NUMBER: _ClassVar[int]
    instance: str
    frame: int
    time: float
    episode: int
    level: Level
    input: InputRequest
    idle: bool
    seq: int
    def __init__(self, instance: _Optional[str] = ..., frame: _Optional[int] = ..., time: _Optional[float] = ..., episode: _Optional[int] = ..., level: _Optional[_Union[Level, _Mapping]] = ..., input: _Optional[_Union[InputRequest, _Mapping]] = ..., idle: bool = ..., seq: _Optional[int] = ...) -> None: ...

class EpisodeInputs(_message.Message):
    __slots__ = ("instance", "episode", "events", "complete")
    INSTANCE_FIELD_NUMBER: _ClassVar[int]
    EPISODE_FIELD_NUMBER: _ClassVar[int]
    EVENTS_FIELD_NUMBER: _ClassVar[int]
    COMPLETE_FIELD_NUMBER: _ClassVar[int]
    instance: str
    episode: int
    events: _containers.RepeatedCompositeFieldContainer[InputEvent]
    complete: bool
    def __init__(self, instance: _Optional[str] = ..., episode: _Optional[int] = ..., events: _Optional[_Iterable[_Union[InputEvent, _Mapping]]] = ..., complete: bool = ...) -> None: ...
