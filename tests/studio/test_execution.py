"""One execution layer: the same units on this process, local processes or a Dask cluster give the
same files; a Dask worker killed mid-frame costs only its frame; ``studio fit --scheduler``
against a real ``dask scheduler`` and two ``dask worker`` processes on the loopback interface."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from studio.execution import ExecutionError, open_runner, parse_scheduler, run_chains
from studio.fit import FitError, fit_session

from prockit import descendants, kill_and_time
from test_fit_session import TINY, make_session

distributed = pytest.importorskip("distributed", reason="Dask not installed (pip install .[dask])")

FRAMES = 4
#: What a frame's result must repeat, whoever fits it (timings differ, of course).
SAME = ("gender", "shape", "pose", "joints", "costs", "quality", "silhouette_agreement", "run")


def _results(session: Path) -> dict[int, dict]:
    return {int(p.stem): json.loads(p.read_text()) for p in sorted((session / "fit").glob("[0-9]*.json"))}


def _numbers(obj, path=""):
    """Leaves of a JSON object by path: floats and everything else."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _numbers(v, f"{path}/{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _numbers(v, f"{path}/{i}")
    else:
        yield path, obj


def _assert_same(a: dict, b: dict) -> None:
    """Same frames, same results, bit for bit (least-squares polish on: OpenCV's exact distance
    transform rounded by an ulp with its thread count until :func:`studio.cost.chamfer._exact_roots`;
    without it a worker's frame 2 came out at shape[0] −21.29043 and this process's at −21.29011)."""
    assert sorted(a) == sorted(b) == list(range(FRAMES))
    for f in a:
        for k in SAME:
            left, right = dict(_numbers(a[f][k])), dict(_numbers(b[f][k]))
            assert left.keys() == right.keys(), f"frame {f}: {k} differs in its fields"
            for leaf, v in left.items():
                assert right[leaf] == v, f"frame {f}: {k}{leaf}"


@pytest.fixture(scope="module")
def local_fit(tmp_path_factory):
    """A tiny 4-frame session fitted by 2 local processes, and a clean copy of it before the fit."""
    root = tmp_path_factory.mktemp("exec")
    make_session(root / "clean", n_frames=FRAMES)
    shutil.copytree(root / "clean", root / "local")
    summary = fit_session(root / "local", gender="female", options=TINY, workers=2, chain_length=2)
    assert summary["chains"] == [[0, 1], [2, 3]] and summary["executor"] == "2 local processes"
    return root, _results(root / "local")


def _fresh(root: Path, name: str) -> Path:
    shutil.copytree(root / "clean", root / name)
    return root / name


def test_scheduler_addresses_are_checked():
    assert parse_scheduler(None) is None and parse_scheduler(" local:3 ") == ("local", 3)
    assert parse_scheduler("tcp://10.0.0.5:8786") == ("address", "tcp://10.0.0.5:8786")
    for bad in ("local:0", "local:x", "10.0.0.5:8786", "tcp://10.0.0.5", "http://h:1"):
        with pytest.raises(ExecutionError, match="--scheduler"):
            parse_scheduler(bad)
    with pytest.raises(ExecutionError, match="workers: expected an integer >= 1, got 0"):
        with open_runner(0):
            pass
    with pytest.raises(ExecutionError, match="cannot reach the Dask scheduler"):
        with open_runner(scheduler="tcp://127.0.0.1:9", timeout=2):
            pass


def _double(spec, item, previous):
    return spec * item + (previous or 0)


def test_chains_pass_each_result_to_the_next_unit():
    seen = []
    with open_runner(1) as runner:
        out = run_chains(runner, _double, [[1, 2, 3], [], [10]], spec=2, starts=[100, None, 5],
                         progress=lambda d, n: seen.append((d, n)))
    assert out == [[102, 106, 112], [], [25]] and seen[-1] == (4, 4) and len(seen) == 4


def test_a_local_cluster_fits_and_segments_exactly_as_local_processes(local_fit, tmp_path):
    """2-worker LocalCluster, 2 local processes and this process alone: every frame's shape, pose,
    joints, costs and quality bit for bit; segmentation labels too."""
    from rigs.imageio import read_image
    from studio.segment import SegmentOptions, segment_session
    from studio.segment.synthetic import write_session

    root, reference = local_fit
    session = _fresh(root, "local-cluster")
    done = []
    summary = fit_session(session, gender="female", options=TINY, scheduler="local:2", chain_length=2,
                          progress=lambda d, n: done.append(d))
    assert summary["executor"].startswith("dask tcp://127.0.0.1:") and summary["chains"] == [[0, 1], [2, 3]]
    assert done == [1, 2, 3, 4]
    _assert_same(_results(session), reference)
    serial = _fresh(root, "serial")  # the plan does not depend on the runner: one process, same files
    assert fit_session(serial, gender="female", options=TINY, workers=1, chain_length=2)["executor"] == "this process"
    _assert_same(_results(serial), reference)
    # frames as independent units: labels from the cluster equal those of this process
    a = write_session(tmp_path / "a", size=(96, 72), frames=4)
    b = write_session(tmp_path / "b", size=(96, 72), frames=4)
    segment_session(a, SegmentOptions(overlay_every=0), workers=1)
    segment_session(b, SegmentOptions(overlay_every=0), scheduler="local:2")
    for cam in ("cam0", "cam1", "cam2"):
        for i in range(4):
            rel = Path("segmentation") / cam / f"{i:06d}.png"
            assert np.array_equal(read_image(a / rel), read_image(b / rel)), rel


def _kill_one_busy_worker(client, killed: list, stop: threading.Event) -> None:
    pids = client.run(os.getpid)
    while not stop.is_set():
        busy = [w for w, tasks in client.processing().items() if tasks]
        if busy:
            time.sleep(0.5)  # well inside the unit (a tiny frame takes 1-3 s)
            os.kill(pids[busy[0]], signal.SIGKILL)
            killed.append(pids[busy[0]])
            return
        time.sleep(0.05)


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of 2 worker processes on 127.0.0.1 and a client of it (closed after the module)."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0") as c, distributed.Client(c, set_as_default=False) as client:
        yield c, client


def test_a_killed_dask_worker_loses_only_its_frame(local_fit, cluster):
    """SIGKILL one of two workers in the middle of a frame: the scheduler runs that frame again
    on a worker (the nanny's replacement or the other); every frame is there once, as if nothing
    had happened."""
    root, reference = local_fit
    session = _fresh(root, "killed")
    killed, stop = [], threading.Event()
    lc, client = cluster
    killer = threading.Thread(target=_kill_one_busy_worker, args=(client, killed, stop))
    killer.start()
    try:
        summary = fit_session(session, gender="female", options=TINY, scheduler=lc.scheduler_address, chain_length=2)
    finally:
        stop.set()
        killer.join(timeout=10)
    assert len(killed) == 1, "no worker was busy long enough to be killed"
    assert summary["frames"] == list(range(FRAMES))
    names = sorted(p.name for p in (session / "fit").glob("[0-9]*.json"))
    assert names == [f"{f:06d}.json" for f in range(FRAMES)]
    _assert_same(_results(session), reference)


def _start(args: list[str], log: Path) -> subprocess.Popen:
    with open(log, "wb") as fh:
        return subprocess.Popen([sys.executable, "-m", *args], stdout=fh, stderr=subprocess.STDOUT,
                                start_new_session=True)


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:  # each in its own session: the group holds the worker its nanny started
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=10)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process groups")
def test_studio_fit_on_a_dask_scheduler_and_two_workers(local_fit, tmp_path, capsys):
    from studio.cli import main
    import studio.cli.commands.fit as fit_cmd

    root, reference = local_fit
    session = _fresh(root, "cli")
    file = tmp_path / "scheduler.json"
    procs = [_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", str(file)], tmp_path / "scheduler.log")]
    try:
        t0 = time.monotonic()
        while not file.is_file() and time.monotonic() - t0 < 30:
            assert procs[0].poll() is None, (tmp_path / "scheduler.log").read_text()
            time.sleep(0.1)
        address = json.loads(file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for k in range(2):
            procs.append(_start(["distributed.cli.dask_worker", address, "--host", "127.0.0.1", "--nthreads", "1",
                                 "--no-dashboard", "--name", f"w{k}"], tmp_path / f"worker{k}.log"))
        with distributed.Client(address, timeout=30, set_as_default=False) as client:
            client.wait_for_workers(2, timeout=60)
        quick = {k: v for k, v in TINY.to_dict().items() if k != "levels"}
        old = fit_cmd.QUICK
        fit_cmd.QUICK = quick
        try:
            code = main(["fit", str(session), "--gender", "female", "--quick", "--scheduler", address,
                         "--chain-length", "2"])
        finally:
            fit_cmd.QUICK = old
        out = capsys.readouterr().out
        assert code == 0 and f"on dask {address}" in out and "fitted 4 frame(s)" in out
        seq = json.loads((session / "fit" / "sequence.json").read_text())
        assert seq["chains"] == [[0, 1], [2, 3]] and seq["executor"] == f"dask {address}"
        assert len(_results(session)) == FRAMES
    finally:
        _stop(procs)
    assert all(p.poll() is not None for p in procs)
    assert main(["fit", str(session), "--scheduler", "tcp://nowhere"]) == 1
    assert "expected a Dask scheduler address tcp://HOST:PORT" in capsys.readouterr().err


def test_a_failing_unit_names_its_frame_through_the_cluster(local_fit, cluster):
    root, _ = local_fit
    session = _fresh(root, "broken")
    (session / "segmentation" / "cam1" / "000002.png").write_bytes(b"not a png")
    t0 = time.monotonic()
    with pytest.raises(Exception, match="000002"):
        fit_session(session, gender="female", options=TINY, scheduler=cluster[0].scheduler_address, chain_length=2)
    print(f"failed and cluster closed in {time.monotonic() - t0:.1f} s")
    with pytest.raises(FitError, match="workers: expected an integer >= 1"):
        fit_session(session, gender="female", workers=0)
    with pytest.raises(FitError, match="chain_length: expected an integer >= 1"):
        fit_session(session, gender="female", chain_length=0)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_local_cluster_workers_die_with_a_killed_command(local_fit):
    """``studio fit --scheduler local:2`` SIGKILLed mid-fit: its cluster's worker processes are gone
    within 5 s (the worker plugin ties them to the command, as local worker pools are)."""
    root, _ = local_fit
    session = _fresh(root, "killed-parent")
    proc = subprocess.Popen([sys.executable, "-m", "studio", "fit", str(session), "--gender", "female", "--quick",
                             "--scheduler", "local:2", "--chain-length", "2"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    seen: set[int] = set()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 60 and len(seen) < 2:  # the cluster's two workers are up
        seen |= descendants(proc.pid)
        assert proc.poll() is None, "the fit ended before it could be killed"
        time.sleep(0.05)
    time.sleep(1.0)
    seen |= descendants(proc.pid)
    assert len(seen) >= 2, f"no worker processes seen ({seen})"
    gone, leftover = kill_and_time(proc, seen)
    assert not leftover and gone < 5.0, f"processes {leftover} alive {gone:.1f} s after the command was killed"
