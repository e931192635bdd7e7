"""The execution layer: one scheduler vocabulary, and Dask addresses with a deadline that
covers the handshake (a silent peer, an HTTP server, garbage: one ProblemError, exit 2)."""

from __future__ import annotations

import argparse
import http.server
import os
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from optmodels import montecarlo as mc
from optmodels.core import ProblemError
from optmodels.execution import as_scheduler, scheduler_argument
from tests.test_cli import OPTMODELS


def test_one_vocabulary() -> None:
    assert as_scheduler("w", None) == "serial"
    assert as_scheduler("w", None, default="processes") == "processes"
    assert as_scheduler("w", " processes ") == "processes"
    assert as_scheduler("w", "tcp://127.0.0.1:8786") == "tcp://127.0.0.1:8786"
    for bad in ("local", "dask", "threads", "localhost:8786", "tcp://", 3):
        with pytest.raises(ProblemError, match=r"^my where: expected 'serial'"):
            as_scheduler("my where", bad)
    assert scheduler_argument("serial") == "serial"
    with pytest.raises(argparse.ArgumentTypeError):
        scheduler_argument("local")


@pytest.fixture
def silent_peer() -> Iterator[str]:
    """Accepts TCP connections and never says a word."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    held: list[socket.socket] = []
    stop = threading.Event()

    def loop() -> None:
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(srv.accept()[0])
            except OSError:
                continue

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    stop.set()
    t.join(2)
    for c in held:
        c.close()
    srv.close()


@pytest.fixture
def garbage_peer() -> Iterator[str]:
    """Answers every connection with bytes that misread as a huge Dask frame length."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    stop = threading.Event()

    def loop() -> None:
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                c = srv.accept()[0]
            except OSError:
                continue
            c.sendall(b"\xff" * 64)
            c.close()

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    stop.set()
    t.join(2)
    srv.close()


@pytest.fixture
def http_peer() -> Iterator[str]:
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    yield f"tcp://127.0.0.1:{srv.server_address[1]}"
    srv.shutdown()
    srv.server_close()


@pytest.mark.parametrize("peer", ["silent_peer", "garbage_peer", "http_peer"])
def test_run_on_a_peer_that_is_not_dask(peer: str, request: pytest.FixtureRequest) -> None:
    address = request.getfixturevalue(peer)
    t0 = time.monotonic()
    with pytest.raises(ProblemError, match=r"montecarlo.run scheduler: .*[Dd]ask"):
        mc.run(mc.TrajectoriesEta(q=2, n=3), 4, 0, scheduler=address, connect_timeout=1.0)
    assert time.monotonic() - t0 < 5.0


def test_fit_tracks_on_a_silent_peer(silent_peer: str) -> None:
    from optmodels.biasfield import fit_tracks
    from optmodels.scenarios import radar_network

    sc = radar_network(3, n_aircraft=2, duration=120.0)
    t0 = time.monotonic()
    with pytest.raises(ProblemError, match=r"fit_tracks scheduler: .*no Dask handshake"):
        fit_tracks(sc.plots, sc.radars, scheduler=silent_peer)
    assert time.monotonic() - t0 < 15.0  # the default 10 s deadline


@pytest.mark.parametrize("peer", ["silent_peer", "http_peer"])
def test_cli_montecarlo_on_a_peer_that_is_not_dask(
    peer: str, request: pytest.FixtureRequest
) -> None:
    address = request.getfixturevalue(peer)
    t0 = time.monotonic()
    proc = subprocess.run(
        [str(OPTMODELS), "montecarlo", "trajectories-eta", "--trials", "2", "--scheduler", address],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ},
    )
    assert proc.returncode == 2, proc.stderr
    assert "Dask" in proc.stderr and "Traceback" not in proc.stderr
    assert time.monotonic() - t0 < 30.0  # 10 s deadline plus start-up


def test_dask_address_without_distributed_is_bad_input(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A Dask address where ``distributed`` is not installed (a bare ``pip install .``) is
    one ProblemError with the install hint in the API, and exit 2 in the CLI (was exit 3,
    "internal error: ModuleNotFoundError")."""
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)  # find_spec -> None
    with pytest.raises(ProblemError, match=r"optmodels\[distributed\]"):
        as_scheduler("montecarlo.run scheduler", "tcp://127.0.0.1:8786")
    with pytest.raises(argparse.ArgumentTypeError, match="not installed"):
        scheduler_argument("tcp://127.0.0.1:8786")
    code = (
        "import sys; sys.modules['distributed'] = None\n"
        "from optmodels.cli import main\n"
        "sys.exit(main(['montecarlo', 'plane-angle', '--trials', '2', '--scheduler', "
        "'tcp://127.0.0.1:8786', '--checkpoint', sys.argv[1], '--json']))"
    )
    r = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "c.jsonl")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    assert "pip install 'optmodels[distributed]'" in r.stdout + r.stderr
    assert "Traceback" not in r.stderr


def _square(x: int) -> int:
    return x * x


def test_dask_keeps_a_bounded_number_of_tasks_in_flight() -> None:
    """On Dask, at most DASK_IN_FLIGHT tasks per worker thread are submitted and not yet
    handed over (their arguments on the scheduler, their results on the workers), and
    every task's result still arrives once, under its own index."""
    import distributed  # in the test extra (pyproject): must be here, never skipped

    from optmodels.execution import engine

    got: dict[int, int] = {}
    submitted: list[int] = []
    most = 0
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        submit = client.submit

        def counting(*args: object, **kw: object) -> object:
            nonlocal most
            submitted.append(1)
            most = max(most, len(submitted) - len(got))
            return submit(*args, **kw)

        client.submit = counting  # type: ignore[method-assign]
        engine.execute(
            _square,
            [(k,) for k in range(40)],
            on_result=lambda k, r: got.__setitem__(k, r),
            scheduler=client,
        )
    assert got == {k: k * k for k in range(40)}
    assert len(submitted) == 40
    assert most == engine.DASK_IN_FLIGHT * 2  # the bound, reached
