"""Where tasks run: one vocabulary for every entry point and every ``--scheduler`` flag.

:func:`as_scheduler` normalises a scheduler argument to ``"serial"`` (in this process, in
order), ``"processes"`` (a local process pool), a Dask address (``"tcp://host:8786"``,
``"inproc://..."``, ...) or a ``distributed.Client``, and refuses anything else with a
:class:`~optmodels.core.ProblemError` naming the argument. :func:`scheduler_argument` is
the same check as an ``argparse`` ``type=``. :func:`dask_client` connects to an address
with a deadline that covers the whole handshake: a ``tcp://`` peer is first probed with a
raw socket (a Dask scheduler speaks first: a length-prefixed msgpack handshake naming
``compression``, ``python`` and ``pickle-protocol``), so that a peer which accepts the
connection but never speaks (a stalled process) or speaks something else (an HTTP server,
garbage) is one clear ``ProblemError`` within ``timeout`` instead of a hang or a
``MemoryError`` from a misread frame length.
"""

from __future__ import annotations

import argparse
import importlib.util
import socket
import struct
import time
from typing import Any

from optmodels.core import ProblemError, SolverNotAvailable

__all__ = [
    "CONNECT_TIMEOUT",
    "SCHEDULERS",
    "as_scheduler",
    "dask_client",
    "probe_dask",
    "scheduler_argument",
]

#: The words of the vocabulary (besides a Dask address or a ``distributed.Client``).
SCHEDULERS = ("serial", "processes")

#: Seconds to wait for a Dask scheduler to answer (connection and handshake).
CONNECT_TIMEOUT = 10.0

_EXPECTED = "'serial', 'processes', a Dask address like tcp://host:8786 or a distributed.Client"


def _address_problem(text: str) -> str | None:
    """Why ``text`` is not a Dask address (None when it is one)."""
    scheme, sep, rest = text.partition("://")
    if not sep or not scheme or not rest or any(c.isspace() for c in text):
        return f"expected {_EXPECTED}, got {text!r}"[:200]
    if importlib.util.find_spec("distributed") is None:
        return (
            f"{text!r} is a Dask address, but Dask distributed is not installed: "
            "pip install 'optmodels[distributed]' (or use serial / processes)"
        )
    return None


def as_scheduler(where: str, value: Any, *, default: str = "serial") -> Any:
    """The scheduler ``value`` in the one vocabulary, or a ``ProblemError`` naming ``where``.

    Parameters
    ----------
    where : str
        The argument's name in messages, e.g. ``"montecarlo.run scheduler"``.
    value : None, str or distributed.Client
        ``None`` (``default``), ``"serial"``, ``"processes"``, a Dask address
        (``scheme://...``, e.g. ``tcp://host:8786``) or a ``distributed.Client`` (any
        object with ``submit`` and ``map``).
    default : str
        What ``None`` means (``"serial"`` or ``"processes"``).

    Returns
    -------
    str or distributed.Client
        ``"serial"``, ``"processes"``, the address (stripped) or the Client as given.
    """
    if value is None:
        value = default
    if isinstance(value, str):
        text = value.strip()
        if text in SCHEDULERS:
            return text
        problem = _address_problem(text)
        if problem is not None:
            raise ProblemError(f"{where}: {problem}")
        return text
    if not hasattr(value, "submit") or not hasattr(value, "map"):
        raise ProblemError(f"{where}: expected {_EXPECTED}, got {type(value).__name__}")
    return value


def scheduler_argument(text: str) -> str:
    """``argparse`` ``type=`` of every ``--scheduler`` flag (the :func:`as_scheduler`
    vocabulary, as text); a bad word is an ``argparse.ArgumentTypeError`` (exit 2)."""
    text = text.strip()
    if text in SCHEDULERS:
        return text
    problem = _address_problem(text)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def probe_dask(where: str, address: str, timeout: float) -> None:
    """Check, within ``timeout`` seconds in all, that ``tcp://host:port`` is a Dask
    scheduler: connect a raw socket and read its first frame (a Dask TCP comm starts with
    the peer's handshake: uint64 total length, uint64 frame count, the frame lengths, then
    a msgpack map with ``compression``, ``python``, ``pickle-protocol``). Other schemes
    (``inproc://``, ``tls://``, ...) are not probed.

    Raises
    ------
    ProblemError
        The peer cannot be reached, does not speak within the deadline, or speaks
        something else (``not a Dask scheduler``).
    """
    scheme, _, rest = address.partition("://")
    if scheme != "tcp":
        return
    host, sep, port_text = rest.rpartition(":")
    host = host.strip("[]")
    try:
        port = int(port_text.split("/")[0]) if sep else 8786
    except ValueError:
        raise ProblemError(
            f"{where}: {address!r} has no port number (expected tcp://host:8786)"
        ) from None
    deadline = time.monotonic() + timeout
    try:
        sock = socket.create_connection((host or "127.0.0.1", port), timeout=timeout)
    except OSError as exc:
        raise ProblemError(
            f"{where}: cannot reach the Dask scheduler at {address} "
            f"within {timeout:g} s ({type(exc).__name__}: "
            f"{str(exc)[:200]})"
        ) from None
    data = b""
    try:
        need = 8
        while len(data) < need:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError
            sock.settimeout(left)
            chunk = sock.recv(4096)
            if not chunk:
                break
            data += chunk
            if len(data) >= 8:
                total = struct.unpack("<Q", data[:8])[0]
                if not 16 <= total <= 65536:
                    break  # not a handshake frame
                need = 8 + total
    except TimeoutError:
        raise ProblemError(
            f"{where}: {address} accepts connections but sent no Dask handshake within "
            f"{timeout:g} s (received {len(data)} bytes): not a Dask scheduler, or a "
            f"stalled one"
        ) from None
    except OSError as exc:
        raise ProblemError(
            f"{where}: the connection to {address} failed during the "
            f"Dask handshake ({type(exc).__name__}: {str(exc)[:200]})"
        ) from None
    finally:
        sock.close()
    if not all(key in data for key in (b"compression", b"python", b"pickle-protocol")):
        shown = data[:40].decode("latin-1").encode("unicode_escape").decode()
        raise ProblemError(
            f"{where}: {address} is not a Dask scheduler (its first "
            f"{len(data)} bytes are no Dask handshake: {shown!r})"
        )


def dask_client(where: str, scheduler: Any, timeout: float = CONNECT_TIMEOUT) -> tuple[Any, bool]:
    """``(client, owned)``: the given ``distributed.Client`` (not owned), or a new Client
    connected to the address within ``timeout`` s (owned: close it). An address that
    cannot be reached, never speaks or is not a Dask scheduler is a ``ProblemError``
    naming ``where`` (:func:`probe_dask`)."""
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - the test extra installs it
        raise SolverNotAvailable(
            f"{where}: Dask distributed is not installed; pip install 'optmodels[distributed]'"
        ) from exc
    if isinstance(scheduler, Client):
        return scheduler, False
    probe_dask(where, scheduler, timeout)
    try:
        return Client(scheduler, timeout=timeout), True
    except (OSError, TimeoutError, ValueError) as exc:
        raise ProblemError(
            f"{where}: cannot reach the Dask scheduler at "
            f"{scheduler} within {timeout:g} s "
            f"({type(exc).__name__}: {str(exc)[:200]})"
        ) from None
