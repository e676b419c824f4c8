"""The device servers a location file's drivers need, and a probe that asks them without harm.

:func:`device_endpoints` lists, from services.toml, the TCP servers the drivers connect to (each
driver class says where with its ``device(params)`` class method,
:class:`~services.devices.endpoint.DeviceEndpoint`): ``petrobot up`` probes them before starting a
node, ``petrobot sim`` serves its world's on their ports.

:func:`probe` asks one server whether it is there the way an ordinary client would, and leaves at
once: a camera server is asked for its info map (``{"op": "info"}``, answered ``{"info": ...}``), a
socketcand gateway greets first (``< hi >``) and is left before any bus is opened; a Zenoh router
waits for its client to speak first, so it is only connected to and left. A probe never takes a
frame, opens the bus or opens a Zenoh session, so it changes nothing in the world it probes (a
camera client counts once it grabs frames; a bus client once it opens the bus).
"""

from __future__ import annotations

import socket
from collections.abc import Iterable

from services.devices.endpoint import DeviceEndpoint
from services.devices.framegrabber import MAX_HEADER
from services.errors import PetrobotError, ProtocolError
from services.location import DriverSpec, Location
from services.protocol.framing import pack_map, recv_frame, unpack_map

__all__ = ["device_endpoints", "probe"]

_GREETING = b"< hi >"


def device_endpoints(location: Location, nodes: Iterable[str] | None = None) -> list[tuple[DriverSpec, DeviceEndpoint]]:
    """The device servers of the drivers of ``nodes`` (default: every node), in file order.

    A driver whose impl cannot be imported is left out (the node itself says what is wrong with
    it when it starts), as is one that needs no device server (no ``device`` method, or one that
    returns ``None``: a camera read through OpenCV).
    """
    from services.action import import_impl

    wanted = None if nodes is None else set(nodes)
    out = []
    for spec in location.drivers.values():
        if wanted is not None and spec.node not in wanted:
            continue
        try:
            cls = import_impl(spec.impl)
        except PetrobotError:
            continue
        device = getattr(cls, "device", None)
        endpoint = None if device is None else device(dict(spec.params))
        if endpoint is not None:
            out.append((spec, endpoint))
    return out


def probe(endpoint: DeviceEndpoint, timeout_s: float = 0.5) -> str | None:
    """Ask the device server at ``endpoint`` whether it is there, as its protocol allows.

    Returns:
        ``None`` if it answered as its protocol says; otherwise why not, in words (``connection
        refused``, ``timed out``, ``no socketcand greeting``...).
    """
    try:
        with socket.create_connection((endpoint.host, endpoint.port), timeout=timeout_s) as sock:
            sock.settimeout(timeout_s)
            if endpoint.protocol == "socketcand":
                return _greeted(sock)
            if endpoint.protocol == "zenoh":
                return None  # the router accepted the connection; the session would start with our InitSyn
            sock.sendall(pack_map({"op": "info"}, MAX_HEADER))
            reply = unpack_map(recv_frame(sock, MAX_HEADER))
            return None if "info" in reply else f"no camera info in the answer ({sorted(reply)[:4]})"
    except TimeoutError:
        return "timed out"
    except ProtocolError as exc:
        return f"not a camera server: {exc}"
    except OSError as exc:
        return exc.strerror or str(exc)


def _greeted(sock: socket.socket) -> str | None:
    got = b""
    while len(got) < len(_GREETING):
        chunk = sock.recv(len(_GREETING) - len(got))
        if not chunk:
            return "closed without the socketcand greeting"
        got += chunk
    return None if got == _GREETING else f"not a socketcand gateway (it said {got!r})"
