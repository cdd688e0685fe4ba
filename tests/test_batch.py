"""`handshadow batch` on a local Dask cluster (2 workers x 1 thread on 127.0.0.1): Ctrl-C keeps
what is finished and shuts the cluster down, a rerun goes on, a worker killed mid-fit loses
nothing, a second rerun fits nothing, a bad image is a failed row.

Four tiny targets (built-in examples) at --quality fast --size 64, one hand and 10 steps, so
a fit takes seconds: the test is about the batch, not about the fits' quality."""

import contextlib
import csv
import importlib.util
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import psutil
import pytest

from handshadow.batch import BatchError, Target, find_targets, is_complete, make_plan, record, run_batch
from handshadow.examples import TARGETS
from handshadow.fit import FitConfig
from tests.conftest import run_cli

PY = [sys.executable, "-m", "handshadow.cli"]
NAMES = ("dog", "duck", "rabbit", "swan")
FIT = ["--quality", "fast", "--size", "64", "--hands", "1", "--iters", "10", "--device", "cpu"]
CONFIG = FitConfig(hands="1", size=64, quality="fast", iters=10, device="cpu")  # the same settings
LOCAL = ["--workers", "2", "--threads-per-worker", "1"]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("targets")
    for name in NAMES:
        (folder / f"{name}.png").write_bytes((TARGETS / f"{name}.png").read_bytes())
    (folder / "bad.png").write_bytes(b"not a picture")
    return folder


def _summary(out: Path) -> dict[str, dict]:
    with (out / "summary.csv").open(newline="") as f:
        return {r["name"]: r for r in csv.DictReader(f)}


def _pose_times(out: Path) -> dict[str, int]:
    return {n: (out / n / "pose.json").stat().st_mtime_ns for n in NAMES if (out / n / "pose.json").exists()}


def _nothing_half_written(out: Path) -> None:
    """Every folder in OUT holds a whole result; no staging folder is left."""
    for p in out.iterdir():
        assert p.name in ("summary.csv", "index.html", "batch.json") or (p.is_dir() and is_complete(p)), p
        assert not p.name.startswith("."), p


@pytest.fixture(scope="module")
def interrupted(inputs, tmp_path_factory):
    """Run 1, the command line: Ctrl-C as soon as the first result is in place."""
    out = tmp_path_factory.mktemp("batch") / "out"
    proc = subprocess.Popen(
        PY + ["batch", str(inputs), "--out", str(out), *LOCAL, *FIT],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        # A shell that starts jobs in the background ignores SIGINT, and children inherit that.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    cluster = {}  # pid -> command line of the batch's child processes
    deadline = time.monotonic() + 150
    while not any(is_complete(out / n) for n in NAMES):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        for child in psutil.Process(proc.pid).children(recursive=True):
            with contextlib.suppress(psutil.Error):
                cluster[child.pid] = " ".join(child.cmdline())
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    return SimpleNamespace(out=out, returncode=proc.returncode, stdout=stdout, stderr=stderr, cluster=cluster)


def test_ctrl_c_keeps_finished_results_and_shuts_the_cluster_down(interrupted):
    out = interrupted.out
    assert interrupted.returncode == 130, interrupted.stderr
    assert "Traceback" not in interrupted.stderr
    assert interrupted.stderr.strip().splitlines()[-1].startswith("handshadow: interrupted; finished results are kept")
    workers = [pid for pid, cmd in interrupted.cluster.items() if "spawn_main" in cmd]
    assert len(workers) >= 2  # the worker processes were seen ...
    assert not [pid for pid in workers if _alive(pid)]  # ... and are gone
    deadline = time.monotonic() + 10  # multiprocessing's resource tracker leaves once it sees its parent gone
    while [pid for pid in interrupted.cluster if _alive(pid)] and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [pid for pid in interrupted.cluster if _alive(pid)]
    finished = [n for n in NAMES if is_complete(out / n)]
    assert 1 <= len(finished) < len(NAMES)
    _nothing_half_written(out)
    rows = _summary(out)
    assert {n: rows[n]["status"] for n in NAMES} == {n: "done" if n in finished else "pending" for n in NAMES}
    assert rows["bad"]["status"] == "failed"


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


@pytest.fixture(scope="module")
def resumed(inputs, interrupted):
    """Run 2, the Python API, on the same folder: one worker is killed half a second into a fit."""
    out = interrupted.out
    before = _pose_times(out)
    killed = []

    def kill_the_first(name, worker, pid):
        if not killed:
            killed.append(name)
            threading.Timer(0.5, os.kill, (pid, signal.SIGKILL)).start()

    t0 = time.perf_counter()
    report = run_batch(
        find_targets([str(inputs)]),
        out,
        CONFIG,
        workers=2,
        threads_per_worker=1,
        show_progress=False,
        say=lambda line: None,
        on_start=kill_the_first,
    )
    return SimpleNamespace(out=out, report=report, before=before, killed=killed, seconds=time.perf_counter() - t0)


def test_a_rerun_goes_on_and_a_killed_worker_loses_nothing(resumed):
    out, rows = resumed.out, {r["name"]: r for r in resumed.report.rows}
    assert len(resumed.killed) == 1
    victim = rows[resumed.killed[0]]
    assert victim["status"] == "done" and victim["attempts"] == 2  # it ran again elsewhere
    for name in NAMES:
        assert is_complete(out / name)
        assert rows[name]["status"] == ("kept" if name in resumed.before else "done")
        assert rows[name]["iou"] > 0.5  # a real fit of the right target
    assert _pose_times(out) == {**_pose_times(out), **resumed.before}  # finished results were not redone
    _nothing_half_written(out)
    # The bad image: a failed row with its one-line reason; the others went on.
    assert rows["bad"]["status"] == "failed" and "bad.png is not a readable image" in rows["bad"]["error"]
    assert "\n" not in rows["bad"]["error"]
    on_disk = _summary(out)
    assert list(on_disk) == ["bad", *NAMES]  # input order
    assert list(next(iter(on_disk.values())))[:9] == [
        "name",
        "hands",
        "success",
        "iou",
        "thin_recall",
        "hd95",
        "seconds",
        "worker",
        "error",
    ]
    assert "boundary_f1" in next(iter(on_disk.values()))  # the fit's other measures follow
    for name in NAMES:
        fit = json.loads((out / name / "pose.json").read_text())["fit"]
        assert float(on_disk[name]["iou"]) == fit["iou"] and on_disk[name]["worker"].startswith("tcp://127.0.0.1:")
    page = (out / "index.html").read_text()
    assert page.index("bad.png is not a readable image") < min(
        page.index(f'href="{n}/"') for n in NAMES
    )  # failures first
    for name in NAMES:
        for picture in ("target.png", "shadow.png", "overlay.png"):
            assert f'src="{name}/{picture}"' in page


def test_a_second_rerun_fits_nothing(resumed, inputs):
    out = resumed.out
    before, rows_before = _pose_times(out), _summary(out)
    res = subprocess.run(PY + ["batch", str(inputs), "--out", str(out), *FIT], capture_output=True, text=True)
    assert res.returncode == 1, res.stderr  # every target tried, one could not be read
    assert "0 to fit, 4 already done" in res.stdout and "cluster" not in res.stdout
    assert res.stdout.strip().splitlines()[-1].startswith("SUMMARY n=4 failed=1 ")
    assert _pose_times(out) == before
    rows = _summary(out)
    assert {n: rows[n]["status"] for n in NAMES} == dict.fromkeys(NAMES, "kept")
    assert {n: (rows[n]["iou"], rows[n]["worker"]) for n in NAMES} == {
        n: (rows_before[n]["iou"], rows_before[n]["worker"]) for n in NAMES
    }


def _fake_result(folder: Path, fit: dict | None = None) -> None:
    """The files of a finished one-hand fit (empty but for pose.json)."""
    folder.mkdir(parents=True)
    for name in ("target.png", "shadow.png", "overlay.png", "scene.json", "hands.glb", "scene.png", "progress.gif"):
        (folder / name).write_bytes(b"")
    (folder / "guide.png").write_bytes(b"")
    (folder / "right.obj").write_bytes(b"")
    pose = {"hands": [{"side": "right"}], "fit": {"iou": 0.9, "interrupted": False, **(fit or {})}}
    (folder / "pose.json").write_text(json.dumps(pose))


def test_what_counts_as_done(tmp_path):
    settings = {"quality": "fast"}
    names = ("whole", "no_guide", "interrupted", "no_pose", "other")
    _fake_result(tmp_path / "whole")
    _fake_result(tmp_path / "no_guide")
    (tmp_path / "no_guide" / "guide.png").unlink()
    _fake_result(tmp_path / "interrupted", {"interrupted": True})
    _fake_result(tmp_path / "no_pose")
    (tmp_path / "no_pose" / "pose.json").unlink()
    targets = [Target(n, f"{n}.png") for n in names]
    plan = make_plan(targets, tmp_path, settings)
    assert [t.name for t in plan.done] == ["whole"]
    assert [t.name for t in plan.todo] == ["no_guide", "interrupted", "no_pose", "other"]
    assert [t.name for t in make_plan(targets, tmp_path, settings, force=True).todo] == list(names)
    # A result this batch made with other settings is not mixed in silently.
    record(tmp_path, "whole", {"quality": "best"})
    with pytest.raises(BatchError, match="quality 'best' there, 'fast' here.*--force"):
        make_plan(targets, tmp_path, settings)
    assert len(make_plan(targets, tmp_path, settings, force=True).todo) == len(names)


def test_inputs_folders_globs_files_and_examples(tmp_path):
    (tmp_path / "a").mkdir()
    for name in ("x.png", "y.JPG", ".hidden.png", "notes.txt"):
        (tmp_path / "a" / name).write_bytes(b"")
    (tmp_path / "z.bmp").write_bytes(b"")
    found = find_targets([str(tmp_path / "a"), str(tmp_path / "*.bmp"), "dog", str(tmp_path / "a" / "x.png")])
    assert [t.name for t in found] == ["x", "y", "z", "dog"]  # x.png given twice counts once
    assert find_targets([str(tmp_path / "a" / "notes.txt")])[0].name == "notes"  # named on its own: tried


@pytest.mark.parametrize(
    "args, message",
    [
        (["{tmp}/nothing"], "no such image, folder or example"),
        (["{tmp}/*.gif"], "no image matches"),
        (["{tmp}/empty"], "no images"),
        (["{tmp}/a/dog.png", "{tmp}/b/dog.png"], "two targets are named 'dog'"),
        (["dog", "--workers", "0"], "--workers must be positive"),
        (["dog", "--scheduler", "tcp://127.0.0.1:1", "--threads-per-worker", "2"], "sizes the local cluster"),
        (["dog", "--scheduler", "nowhere"], "cannot reach a Dask scheduler at nowhere"),
        (["dog", "--size", "8"], "--size must be between"),
        (["dog", "--hops", "-1"], "--hops must be between 0 and 20"),
        (["dog", "--seed", "-3"], "--seed must be a whole number"),
        pytest.param(
            ["dog", "--dashboard"],
            "--dashboard needs bokeh",
            marks=pytest.mark.skipif(importlib.util.find_spec("bokeh") is not None, reason="bokeh is installed"),
        ),
    ],
)
def test_bad_inputs_and_options_fail_cleanly(tmp_path, args, message):
    (tmp_path / "empty").mkdir()
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "dog.png").write_bytes((TARGETS / "dog.png").read_bytes())
    out = tmp_path / "out"
    argv = [a.replace("{tmp}", str(tmp_path)) for a in args]
    res = run_cli(["batch", *argv, "--out", str(out)])
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith("handshadow: error: ") and res.stderr.count("\n") == 1, res.stderr
    assert message in res.stderr
    assert not out.exists() or not any(p.is_dir() for p in out.iterdir())  # no result folder, whole or half


def test_a_refusal_ends_the_process_itself_with_one_line(tmp_path):
    """The refusals above run in this process; one runs as a user meets it."""
    out = tmp_path / "out"
    res = subprocess.run(PY + ["batch", "dog", "--workers", "0", "--out", str(out)], capture_output=True, text=True)
    assert res.returncode == 2 and res.stderr == "handshadow: error: --workers must be positive, got 0\n", res.stderr
    assert not out.exists()


def _worker_environ() -> dict:
    from distributed import get_worker

    profiling = "profile" in get_worker().periodic_callbacks  # the stack sampler
    return {**{k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS")}, "profiling": profiling}


def test_local_workers_keep_glibcs_dynamic_mmap_threshold_and_do_not_profile():
    # Dask starts its workers with MALLOC_TRIM_THRESHOLD_ set, which turns glibc's dynamic mmap
    # threshold off: a fit ran 1.3 times slower in such a worker. The local cluster leaves it out
    # and keeps the rest of Dask's worker environment; without a dashboard, no stack sampler.
    from handshadow.batch import open_cluster

    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ
    with open_cluster(None, 1, 1, dashboard=False, quiet_logs=True) as (client, _):
        environ = client.submit(_worker_environ, pure=False).result()
    assert environ == {"MALLOC_TRIM_THRESHOLD_": None, "OMP_NUM_THREADS": "1", "profiling": False}


def _log_from_worker(message: str) -> None:
    import logging

    logging.getLogger("distributed.worker").error(message)


@pytest.mark.parametrize("quiet", [True, False])
def test_quiet_workers_keep_their_errors_off_the_terminal(capfd, quiet):
    # After a Ctrl-C a worker may log a heartbeat the scheduler no longer answers, as an ERROR
    # with its traceback: quiet (the default), only what is critical reaches the terminal.
    from handshadow.batch import open_cluster

    with open_cluster(None, 1, 1, dashboard=False, quiet_logs=quiet) as (client, _):
        client.run(_log_from_worker, "a worker's error, logged")
    assert ("a worker's error, logged" in capfd.readouterr().err) is not quiet
