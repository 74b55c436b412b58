"""The client: a zenoh session speaking the lodcloth wire contract.

    from lodcloth_client import Client

    with Client.open(connect=["tcp/127.0.0.1:7450"]) as client:
        for summary in client.instances():
            print(summary.instance, summary.scene)
        with client.watch("hanging", metrics=False) as states:
            for state in itertools.islice(states, 3):
                print(state.frame, len(positions(state)))
        reply = client.switch("hanging", "24x24", timeout=300)

Every method raises a :class:`~lodcloth_client.errors.LodclothError`
subclass on failure: :class:`RefusedError` (the daemon said no, with its
code and message), :class:`NoReplyError`, :class:`NoDataError`,
:class:`DecodeError`, :class:`ConnectError`, :class:`ZenohError`.
"""

from __future__ import annotations

import dataclasses
import logging
import queue
import threading
from typing import Callable, Iterator, List, Optional, Sequence, Tuple, Type, TypeVar, Union, cast

import zenoh
from google.protobuf.message import Message

from . import keys, v1
from .codec import (
    LevelLike,
    control_request,
    decode,
    encoding_of,
    grab_request,
    move_request,
    refusal,
    release_request,
    switch_request,
)
from .errors import ConnectError, LodclothError, NoDataError, NoReplyError, ZenohError
from .options import ConnectOptions

__all__ = ["Client", "Watch", "Subscription"]

log = logging.getLogger("lodcloth_client")

M = TypeVar("M", bound=Message)

#: Seconds a query waits for its replies unless told otherwise (the Rust client's).
DEFAULT_TIMEOUT = 10.0
#: A switch to an unprepared level estimates it first: minutes on a small machine.
DEFAULT_SWITCH_TIMEOUT = 600.0


class Client:
    """A connected client of one or more lodcloth daemons.

    Open one with :meth:`open` (it owns its zenoh session and closes it), or
    wrap a session of your own with ``Client(session)``. Use it as a context
    manager, or call :meth:`close`. Methods may be called from any thread.
    """

    def __init__(self, session: "zenoh.Session", prefix: str = keys.DEFAULT_PREFIX, timeout: float = DEFAULT_TIMEOUT):
        self.session = session
        self.prefix = prefix
        #: Seconds a query (list, info, control, health) waits by default.
        self.timeout = timeout
        self._owned = False

    @classmethod
    def open(
        cls, options: Optional[ConnectOptions] = None, *, timeout: float = DEFAULT_TIMEOUT, **option_overrides
    ) -> "Client":
        """Open a zenoh session per ``options`` (default: a peer connected to
        ``tcp/127.0.0.1:7450``); keyword arguments set single options, e.g.
        ``Client.open(connect=["tcp/10.0.0.5:7450"], client_mode=True)``.
        Environment variables are read only by :meth:`ConnectOptions.from_env`.
        Raises :class:`ConnectError`."""
        overrides = {k: v for k, v in option_overrides.items() if v is not None}
        options = dataclasses.replace(options or ConnectOptions(), **overrides)
        config = options.zenoh_config()
        try:
            session = zenoh.open(config)
        except zenoh.ZError as e:
            raise ConnectError(
                f"cannot open a zenoh session to {', '.join(options.connect) or 'multicast peers'}: {e}"
            ) from None
        client = cls(session, options.prefix, timeout)
        client._owned = True
        return client

    def close(self) -> None:
        """Close the session if this client opened it."""
        if self._owned and not self.session.is_closed():
            self.session.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ----------------------------------------------------------------------
    # queries

    def _query(
        self, key: str, timeout: float, request: Optional[Message] = None
    ) -> Tuple[List["zenoh.Sample"], List["zenoh.ReplyError"]]:
        """Every reply to ``key`` within ``timeout`` s: (ok samples, error replies)."""
        ok: List[zenoh.Sample] = []
        errors: List[zenoh.ReplyError] = []
        try:
            replies = self.session.get(
                key,
                target=zenoh.QueryTarget.ALL,
                # Several daemons answer <prefix>/instances on the same key: keep every reply.
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=float(timeout),
                payload=None if request is None else request.SerializeToString(),
                encoding=None if request is None else zenoh.Encoding(encoding_of(request)),
            )
            # The handler ends when every queryable has answered, or at the timeout.
            for reply in replies:
                if reply.ok is not None:
                    ok.append(reply.ok)
                elif reply.err is not None:
                    errors.append(reply.err)
        except zenoh.ZError as e:
            raise ZenohError(f"query {key}: {e}") from None
        return ok, errors

    def _request(self, cls: Type[M], key: str, timeout: float, request: Optional[Message] = None) -> M:
        """The first successful reply to ``key`` as a ``cls``; else the first
        refusal raised; else :class:`NoReplyError`."""
        ok, errors = self._query(key, timeout, request)
        if ok:
            return decode(cls, ok[0].payload.to_bytes(), str(ok[0].encoding), key)
        detail = ""
        for err in errors:
            refused = refusal(err.payload.to_bytes(), str(err.encoding), key)
            if refused is not None:
                raise refused
            detail = detail or err.payload.to_bytes().decode("utf-8", "replace")
        raise NoReplyError(key, timeout, detail)

    def list(self, timeout: Optional[float] = None) -> List["v1.InstanceList"]:
        """One ``InstanceList`` per daemon that answered within ``timeout``
        (empty when none did)."""
        key = keys.instances(self.prefix)
        ok, errors = self._query(key, self.timeout if timeout is None else timeout)
        for err in errors:
            log.warning("error reply from %s: %s", key, err.payload.to_bytes().decode("utf-8", "replace"))
        return [decode(v1.InstanceList, s.payload.to_bytes(), str(s.encoding), key) for s in ok]

    def instances(self, timeout: Optional[float] = None) -> List["v1.InstanceSummary"]:
        """Every instance of every daemon that answered, in one list."""
        return [i for lst in self.list(timeout) for i in lst.instances]

    def alive(self, timeout: Optional[float] = None) -> List[str]:
        """Names of the instances whose liveliness tokens are present, sorted."""
        names = set()
        try:
            replies = self.session.liveliness().get(
                keys.alive(self.prefix, "*"), timeout=float(self.timeout if timeout is None else timeout)
            )
            for reply in replies:
                if reply.ok is not None:
                    name = keys.alive_instance(self.prefix, str(reply.ok.key_expr))
                    if name:
                        names.add(name)
        except zenoh.ZError as e:
            raise ZenohError(f"liveliness query: {e}") from None
        return sorted(names)

    def info(self, instance: str, timeout: Optional[float] = None) -> "v1.InstanceInfo":
        """The instance's ``InstanceInfo`` (levels, coefficients, mesh...)."""
        return self._request(
            v1.InstanceInfo, keys.info(self.prefix, instance), self.timeout if timeout is None else timeout
        )

    def episode_inputs(self, instance: str, timeout: Optional[float] = None) -> "v1.EpisodeInputs":
        """Every input that took effect in ``instance``'s latest episode with
        inputs so far (``EpisodeInputs``): with ``on_input`` from before it
        was called, a session's whole input log (merge by ``seq``)."""
        return self._request(
            v1.EpisodeInputs,
            keys.episode_inputs(self.prefix, instance),
            self.timeout if timeout is None else timeout,
        )

    def switch(
        self,
        instance: str,
        level: Optional[LevelLike] = None,
        *,
        max_error: Optional[float] = None,
        method: Optional[str] = None,
        at_once: bool = False,
        timeout: float = DEFAULT_SWITCH_TIMEOUT,
    ) -> "v1.SwitchReply":
        """Switch ``instance`` to ``level`` (``"16x16"``, ``300`` points,
        ``(nx, ny)`` or a ``Level``) or to the cheapest allowed level whose
        predicted error is at most ``max_error`` (0.05 = 5 %). An unprepared
        level waits for its reference and a scored estimate, hence the long
        default ``timeout``; a ``fit`` not made yet is replaced by the better
        of ``same`` and ``bcd`` while the fit is made (``reply.refining``:
        it follows in place if it predicts less). With ``at_once`` the level
        goes live at once with the scene's own coefficients
        (``reply.refining``) and the estimate follows in place.
        Raises :class:`RefusedError` (e.g. ``CODE_LEVEL_NOT_ALLOWED``,
        ``CODE_UNKNOWN_INSTANCE``, ``CODE_NO_LEVEL_MEETS_ERROR``,
        ``CODE_BUSY``) or :class:`NoReplyError`."""
        request = switch_request(level, max_error=max_error, method=method, at_once=at_once)
        return self._request(v1.SwitchReply, keys.switch(self.prefix, instance), timeout, request)

    def control(self, instance: str, action: Union[str, int], timeout: Optional[float] = None) -> "v1.ControlReply":
        """``"pause"``, ``"resume"`` or ``"reset"`` (start the scene over
        from rest at the current level) an instance."""
        return self._request(
            v1.ControlReply,
            keys.control(self.prefix, instance),
            self.timeout if timeout is None else timeout,
            control_request(action),
        )

    def input(self, instance: str, request: "v1.InputRequest", timeout: Optional[float] = None) -> "v1.InputReply":
        """Send one ``InputRequest`` (see :func:`grab_request` and its
        siblings); the reply names the step after which it took effect and
        the grabs held. Raises :class:`RefusedError` naming the field
        (``CODE_BAD_REQUEST``), ``CODE_UNSTABLE`` for a grab too stiff for
        the level's dt, or ``CODE_BUSY`` above the daemon's input rate."""
        return self._request(
            v1.InputReply,
            keys.input(self.prefix, instance),
            self.timeout if timeout is None else timeout,
            request,
        )

    def grab(
        self,
        instance: str,
        u: float,
        v: float,
        target: Optional[Sequence[float]] = None,
        *,
        id: int = 1,
        stiffness: float = 20.0,
        damping: float = 0.2,
        radius: float = 0.02,
    ) -> "v1.InputReply":
        """Grab the cloth at material point (``u``, ``v``) and pull it to
        ``target`` (see :func:`grab_request`); :meth:`move` drags it,
        :meth:`release` lets go."""
        return self.input(
            instance, grab_request(u, v, target, id=id, stiffness=stiffness, damping=damping, radius=radius)
        )

    def move(self, instance: str, target: Sequence[float], *, id: int = 1) -> "v1.InputReply":
        """Move grab ``id``'s target."""
        return self.input(instance, move_request(target, id=id))

    def release(self, instance: str, id: Optional[int] = None) -> "v1.InputReply":
        """Let go of grab ``id`` (every grab when None)."""
        return self.input(instance, release_request(id))

    def pause(self, instance: str) -> "v1.ControlReply":
        """Stop stepping ``instance`` (see :meth:`control`)."""
        return self.control(instance, "pause")

    def resume(self, instance: str) -> "v1.ControlReply":
        """Resume a paused or halted ``instance`` (see :meth:`control`)."""
        return self.control(instance, "resume")

    def reset(self, instance: str) -> "v1.ControlReply":
        """Start ``instance``'s scene over from rest (see :meth:`control`)."""
        return self.control(instance, "reset")

    def health(self, instance: Optional[str] = None, timeout: float = 3.0) -> List["v1.InstanceInfo"]:
        """What ``lodcloth health`` checks: every instance of every daemon
        (or just ``instance``) answers its ``info``. Returns their infos;
        raises :class:`NoReplyError` when no daemon answers, or the failing
        instance's error."""
        if instance is not None:
            names = [instance]
        else:
            names = [i.instance for i in self.instances(timeout)]
            if not names:
                raise NoReplyError(keys.instances(self.prefix), timeout)
        return [self.info(n, timeout) for n in names]

    # ----------------------------------------------------------------------
    # publications

    def watch(
        self,
        instance: str,
        *,
        states: bool = True,
        metrics: bool = True,
        timeout: Optional[float] = 5.0,
        max_queue: int = 1000,
    ) -> "Watch":
        """Subscribe to an instance's ``State`` and/or ``Metrics`` (``"*"``:
        every instance); iterate the returned :class:`Watch` for the decoded
        messages in arrival order. Iteration raises :class:`NoDataError`
        after ``timeout`` s without a message (None: wait forever). Close it
        (or use it as a context manager) to unsubscribe."""
        return Watch(self, instance, states=states, metrics=metrics, timeout=timeout, max_queue=max_queue)

    def states(
        self, instance: str, count: Optional[int] = None, timeout: Optional[float] = 5.0
    ) -> Iterator["v1.State"]:
        """The next ``count`` (None: endless) states of ``instance``; the
        subscription ends with the iteration."""
        with self.watch(instance, metrics=False, timeout=timeout) as w:
            yield from _take(w, count)  # type: ignore[misc]

    def metrics(
        self, instance: str, count: Optional[int] = None, timeout: Optional[float] = 5.0
    ) -> Iterator["v1.Metrics"]:
        """The next ``count`` (None: endless) metrics of ``instance``."""
        with self.watch(instance, states=False, timeout=timeout) as w:
            yield from _take(w, count)  # type: ignore[misc]

    def on_state(
        self,
        instance: str,
        callback: Callable[["v1.State"], object],
        on_error: Optional[Callable[[LodclothError], object]] = None,
    ) -> "Subscription":
        """Call ``callback`` with every decoded ``State`` of ``instance``
        (``"*"``: every instance), on a zenoh thread: keep it short. An
        undecodable message goes to ``on_error`` (default: logged)."""
        return Subscription(self, keys.state(self.prefix, instance), v1.State, callback, on_error)

    def on_metrics(
        self,
        instance: str,
        callback: Callable[["v1.Metrics"], object],
        on_error: Optional[Callable[[LodclothError], object]] = None,
    ) -> "Subscription":
        """Call ``callback`` with every decoded ``Metrics`` of ``instance``
        (see :meth:`on_state`)."""
        return Subscription(self, keys.metrics(self.prefix, instance), v1.Metrics, callback, on_error)

    def on_input(
        self,
        instance: str,
        callback: Callable[["v1.InputEvent"], object],
        on_error: Optional[Callable[[LodclothError], object]] = None,
    ) -> "Subscription":
        """Call ``callback`` with every ``InputEvent`` of ``instance``: each
        input that took effect, from any client or the daemon's idle rule, in
        order (see :meth:`on_state`)."""
        return Subscription(self, keys.inputs(self.prefix, instance), v1.InputEvent, callback, on_error)


def _take(watch: "Watch", count: Optional[int]) -> Iterator[Message]:
    if count is not None and count < 1:
        return
    for n, message in enumerate(watch, 1):
        yield message
        if count is not None and n >= count:
            return


class Subscription:
    """A callback subscription (:meth:`Client.on_state`,
    :meth:`Client.on_metrics`); :meth:`close` it, or use it as a context
    manager."""

    def __init__(
        self,
        client: Client,
        key: str,
        cls: Type[M],
        callback: Callable[[M], object],
        on_error: Optional[Callable[[LodclothError], object]],
    ):
        self.key = key

        def handle(sample: "zenoh.Sample") -> None:
            try:
                message = decode(cls, sample.payload.to_bytes(), str(sample.encoding), str(sample.key_expr))
            except LodclothError as e:
                if on_error is not None:
                    on_error(e)
                else:
                    log.warning("%s", e)
                return
            try:
                callback(message)
            except Exception:  # noqa: BLE001 - a callback's bug must not kill zenoh's thread
                log.exception("callback on %s raised", key)

        try:
            self._subscriber: Optional[zenoh.Subscriber] = client.session.declare_subscriber(key, handle)
        except zenoh.ZError as e:
            raise ZenohError(f"subscribing to {key}: {e}") from None

    def close(self) -> None:
        """Unsubscribe (idempotent)."""
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None

    def __enter__(self) -> "Subscription":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Watch:
    """An iterator over an instance's decoded ``State`` and ``Metrics``
    messages (:meth:`Client.watch`). Messages are queued as they arrive; when
    the consumer falls more than ``max_queue`` behind, new ones are dropped
    (counted in :attr:`dropped`) rather than blocking zenoh."""

    def __init__(
        self,
        client: Client,
        instance: str,
        *,
        states: bool = True,
        metrics: bool = True,
        timeout: Optional[float] = 5.0,
        max_queue: int = 1000,
    ):
        if not (states or metrics):
            raise ValueError("watch needs states, metrics or both")
        self.instance = instance
        self.timeout = timeout
        #: Messages dropped because the consumer fell behind.
        self.dropped = 0
        self._inbox: "queue.Queue[Tuple[Type[Message], str, bytes, str]]" = queue.Queue(maxsize=max_queue)
        self._lock = threading.Lock()
        self._subscribers = []
        self.keys: List[str] = []
        wanted: List[Tuple[str, Type[Message]]] = []
        if states:
            wanted.append((keys.state(client.prefix, instance), v1.State))
        if metrics:
            wanted.append((keys.metrics(client.prefix, instance), v1.Metrics))
        try:
            for key, cls in wanted:
                self.keys.append(key)
                self._subscribers.append(client.session.declare_subscriber(key, self._enqueue(cls)))
        except zenoh.ZError as e:
            self.close()
            raise ZenohError(f"subscribing to {key}: {e}") from None

    def _enqueue(self, cls: Type[Message]) -> Callable[["zenoh.Sample"], None]:
        def callback(sample: "zenoh.Sample") -> None:
            # zenoh's thread: hand the raw bytes over, decode in the consumer's.
            try:
                self._inbox.put_nowait((cls, str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding)))
            except queue.Full:
                with self._lock:
                    self.dropped += 1

        return callback

    def __iter__(self) -> "Watch":
        return self

    def __next__(self) -> Union["v1.State", "v1.Metrics"]:
        if not self._subscribers:
            raise StopIteration
        try:
            cls, key, payload, encoding = self._inbox.get(timeout=self.timeout)
        except queue.Empty:
            raise NoDataError(self.keys, self.timeout or 0.0) from None
        return cast(Union[v1.State, v1.Metrics], decode(cls, payload, encoding, key))

    def close(self) -> None:
        """Unsubscribe (idempotent); iteration then stops."""
        for sub in self._subscribers:
            sub.undeclare()
        self._subscribers = []

    def __enter__(self) -> "Watch":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
