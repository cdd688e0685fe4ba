"""`handshadow batch`: many targets fitted on a Dask cluster, one result folder each.

The data goes one way: inputs -> targets -> plan (what is already done) -> tasks on the
cluster -> result folders, summary.csv and index.html. No tensor code here.

Who writes what. The client (the process that runs the batch) reads each target image and
ships its bytes with the task; a worker fits it in its own scratch folder and sends the
folder's files back; the client writes them into ``OUT/NAME/`` (``ResultFolder``: the folder
appears whole, by one rename, or not at all). Workers therefore need handshadow installed but
no disk shared with the client, and a worker that dies mid-task leaves nothing behind in OUT:
Dask runs the task again on another worker.

Resuming. A folder counts as done when its pose.json holds a finished fit (not interrupted)
and every file a fit writes is there; a rerun skips those unless ``force``. OUT/batch.json
records the fit settings, so a rerun with other settings is refused instead of mixing results.

One fit per worker at a time: a local cluster gives each worker one unit of the ``fit``
resource and each task asks for it, so a worker of T threads runs one fit with T torch
threads. Workers of an existing cluster do the same when started with ``--resources fit=1``;
otherwise each of their threads runs a fit with one torch thread.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import glob
import html
import io
import json
import logging
import os
import statistics
import time
import urllib.parse
import uuid
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from handshadow.errors import HandshadowError

log = logging.getLogger(__name__)

EXTENSIONS = (".png", ".jpg", ".jpeg", ".gif", ".bmp")
#: Files every fit writes, besides one <side>.obj per hand.
RESULT_FILES = (
    "target.png",
    "shadow.png",
    "overlay.png",
    "scene.json",
    "pose.json",
    "hands.glb",
    "scene.png",
    "progress.gif",
    "guide.png",
)
#: summary.csv's first columns; the fit's other measures (pose.json "fit") follow.
FIRST_COLUMNS = ("name", "hands", "success", "iou", "thin_recall", "hd95", "seconds", "worker", "error")
BATCH_COLUMNS = ("status", "attempts", "task_s", "source")
OWN_FILES = ("summary.csv", "index.html", "batch.json")
FIT_RESOURCE = "fit"
EVENT_TOPIC = "handshadow-batch"
CONNECT_TIMEOUT_S = 20
WORKER_MEMORY_BYTES = 2 * 1024**3  # a default fit at 256 px peaks near 1 GiB; room for 'best'


class BatchError(HandshadowError):
    """Inputs, output folder or cluster that a batch cannot use."""


@dataclasses.dataclass(frozen=True)
class Target:
    """One target of a batch: ``name`` is its result folder's name (the file's stem) and
    ``source`` the image as given (a path, or a built-in example name)."""

    name: str
    source: str


@dataclasses.dataclass(frozen=True)
class Plan:
    """``todo``: targets to fit; ``done``: targets whose folder is complete and kept."""

    todo: tuple[Target, ...]
    done: tuple[Target, ...]


@dataclasses.dataclass
class BatchReport:
    """The rows of summary.csv in input order (dicts: FIRST_COLUMNS, BATCH_COLUMNS, then the
    fit's other measures) and where they were written."""

    out: Path
    rows: list[dict]
    interrupted: bool = False

    def put(self, row: dict) -> None:
        """Replace the row of the same name."""
        self.rows = [row if r["name"] == row["name"] else r for r in self.rows]

    @property
    def fitted(self) -> list[dict]:
        return [r for r in self.rows if r["status"] in ("done", "kept")]

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] == "failed"]

    def medians(self) -> dict:
        """n (results), success (share), median_iou and median_s over the results."""
        rows = self.fitted
        nan = float("nan")
        return {
            "n": len(rows),
            "median_iou": statistics.median(r["iou"] for r in rows) if rows else nan,
            "success": sum(bool(r["success"]) for r in rows) / len(rows) if rows else nan,
            "median_s": statistics.median(r["seconds"] for r in rows) if rows else nan,
        }


# --- inputs -> targets -------------------------------------------------------------------


def find_targets(inputs: Iterable[str]) -> list[Target]:
    """Targets from INPUTs: an image file, a folder (its images, not hidden, sorted), a glob
    (quoted, so the shell leaves it alone) or a built-in example name. The same file given
    twice counts once; two targets with one name are refused (their folders would clash)."""
    from handshadow import examples

    found: dict[str, Target] = {}
    for text in inputs:
        path = Path(text)
        if path.is_dir() or path.is_file():
            sources = _expand(path)
        elif glob.has_magic(text):
            sources = [s for match in sorted(glob.glob(text)) for s in _expand(Path(match), explicit=False)]
            if not sources:
                raise BatchError(f"no image matches {text} ({', '.join(EXTENSIONS)})")
        elif examples.target_path(text).is_file():
            sources = [text]
        else:
            raise BatchError(f"no such image, folder or example: {text}")
        for source in sources:
            target = Target(Path(source).stem, source)
            key = str(Path(source).resolve()) if Path(source).exists() else source
            found.setdefault(key, target)
    targets = list(found.values())
    by_name: dict[str, Target] = {}
    for t in targets:
        if t.name in by_name:
            raise BatchError(
                f"two targets are named {t.name!r} ({by_name[t.name].source} and {t.source}); rename one or run them into different --out folders"
            )
        if t.name in OWN_FILES:
            raise BatchError(f"a target may not be named {t.name!r} (the batch writes that file)")
        by_name[t.name] = t
    return targets


def _expand(path: Path, explicit: bool = True) -> list[str]:
    if path.is_dir():
        images = sorted(str(p) for p in path.iterdir() if p.suffix.lower() in EXTENSIONS and not p.name.startswith("."))
        if not images and explicit:
            raise BatchError(f"no images ({', '.join(EXTENSIONS)}) in folder {path}")
        return images
    # A file named on its own is a target whatever its name (an unreadable one is a failed row).
    return [str(path)] if explicit or path.suffix.lower() in EXTENSIONS else []


# --- what is done -----------------------------------------------------------------------


def is_complete(folder: Path) -> bool:
    """True when the folder holds a finished fit: pose.json with an uninterrupted "fit"
    section, and every file a fit writes (one <side>.obj per hand in pose.json)."""
    try:
        pose = json.loads((folder / "pose.json").read_text())
        fit, hands = pose["fit"], pose["hands"]
        sides = [h["side"] for h in hands]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    if not isinstance(fit, dict) or fit.get("interrupted", False):
        return False
    return all((folder / name).is_file() for name in (*RESULT_FILES, *(f"{s}.obj" for s in sides)))


def make_plan(targets: list[Target], out: Path, settings: dict, force: bool = False) -> Plan:
    """Which targets to fit: all with ``force``, else those without a complete folder.

    A complete folder that this batch recorded (OUT/batch.json) with other fit settings is
    refused unless ``force``, rather than mixed with new results; one it has no record of (made
    by ``handshadow fit``, say) is kept."""
    recorded = read_record(out)
    done, other = [], []
    for t in targets:
        if force or not is_complete(out / t.name):
            continue
        before = recorded.get(t.name, settings)
        (done if before == settings else other).append((t, before))
    if other:
        t, before = other[0]
        diff = ", ".join(
            f"{k} {before.get(k)!r} there, {settings.get(k)!r} here"
            for k in sorted(set(before) | set(settings))
            if before.get(k) != settings.get(k)
        )
        raise BatchError(
            f"{len(other)} of these targets ({t.name}, ...) have results in {out} fitted with other settings ({diff}); use another --out, or --force to redo them"
        )
    kept = {t for t, _ in done}
    return Plan(todo=tuple(t for t in targets if t not in kept), done=tuple(t for t in targets if t in kept))


def settings_of(config, invert: bool | None) -> dict:
    """The fit settings that make results comparable (not the device or where MANO lives), as
    batch.json stores them (tuples become lists)."""
    d = dataclasses.asdict(config)
    for k in ("device", "mano_dir", "time_limit_s"):
        d.pop(k, None)
    return json.loads(json.dumps({**d, "invert": invert}))


def read_record(out: Path) -> dict[str, dict]:
    """name -> fit settings of each result the batch wrote into OUT (OUT/batch.json)."""
    try:
        results = json.loads((out / "batch.json").read_text())["results"]
        return {k: v for k, v in results.items() if isinstance(v, dict)}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def record(out: Path, name: str, settings: dict) -> None:
    """Note in OUT/batch.json that OUT/NAME/ was fitted with these settings."""
    results = {**read_record(out), name: settings}
    _write_atomic(out / "batch.json", json.dumps({"format": "handshadow.batch/1", "results": results}, indent=1) + "\n")


# --- on a worker ---------------------------------------------------------------------------


def fit_task(name: str, source: str, suffix: str, image: bytes, config, invert: bool | None, run: str) -> dict:
    """Runs on a Dask worker: fit one target in the worker's scratch space and return the
    result folder's files (name -> bytes), or the one-line error of an expected failure."""
    import tempfile

    import torch  # only to set its thread count
    from distributed import get_worker

    from handshadow.cli import resolve_device
    from handshadow.pipeline import fit_to_folder

    worker = get_worker()
    key = worker.get_current_task()
    worker.log_event(EVENT_TOPIC, {"run": run, "name": name, "worker": worker.address, "pid": os.getpid()})
    one_at_a_time = worker.state.total_resources.get(FIT_RESOURCE, 0) >= 1
    torch.set_num_threads(worker.state.nthreads if one_at_a_time else 1)

    def cancelled() -> bool:  # the client gave up on this task (Ctrl-C, or it went away)
        ts = worker.state.tasks.get(key)
        return ts is None or ts.state in ("cancelled", "released", "forgotten")

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="handshadow-", dir=worker.local_directory) as tmp:
        image_path = Path(tmp) / f"target{suffix}"
        image_path.write_bytes(image)
        try:
            config = dataclasses.replace(config, device=resolve_device(config.device))
            folder, result, _ = fit_to_folder(
                str(image_path), Path(tmp) / "result", config, invert=invert, show_progress=False, stop=cancelled
            )
            files = {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}
        except HandshadowError as exc:
            return {"error": str(exc).replace(str(image_path), source), "worker": worker.address}
    return {
        "files": files,
        "interrupted": result.interrupted,
        "worker": worker.address,
        "task_s": round(time.perf_counter() - t0, 1),
    }


# --- the cluster ---------------------------------------------------------------------------


def local_cluster_size(workers: int | None, threads_per_worker: int | None) -> tuple[int, int]:
    """(workers, threads each) for a local cluster: by default one thread per worker and as
    many workers as the CPU cores and the memory (2 GiB a worker) allow."""
    import psutil

    threads = threads_per_worker or 1
    if workers:
        return workers, threads
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    by_memory = psutil.virtual_memory().total // WORKER_MEMORY_BYTES
    return max(1, min(cores // threads, by_memory)), threads


@contextlib.contextmanager
def open_cluster(
    scheduler: str | None, workers: int | None, threads_per_worker: int | None, dashboard: bool, quiet_logs: bool
) -> Iterator[tuple[object, str]]:
    """(Dask client, a line that describes the cluster). Without ``scheduler``, a LocalCluster
    on 127.0.0.1 that is shut down on leaving, however that happens."""
    import dask
    from distributed import Client

    level = logging.ERROR if quiet_logs else logging.WARNING
    logging.getLogger("distributed").setLevel(level)
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, ValueError, TypeError) as exc:
            raise BatchError(f"cannot reach a Dask scheduler at {scheduler}: {_one_line(exc)}") from None
        with client:
            n = len(client.nthreads())
            link = f", dashboard {client.dashboard_link}" if dashboard else ""
            waiting = " (the batch waits for workers to join)" if n == 0 else ""
            yield client, f"Dask scheduler {scheduler}: {n} worker{'s' * (n != 1)}{link}{waiting}"
        return
    n, threads = local_cluster_size(workers, threads_per_worker)
    with (
        dask.config.set(worker_settings(dashboard)),
        # A worker logs each heartbeat the scheduler no longer answers as an ERROR with its
        # traceback: after a Ctrl-C, when the scheduler goes first. Quiet, the workers log only
        # what is critical; a task's own error reaches the batch as its result.
        _local_cluster(n, threads, dashboard, logging.CRITICAL if quiet_logs else level) as cluster,
        Client(cluster) as client,
    ):
        link = f", dashboard {client.dashboard_link}" if dashboard else ""
        yield client, f"local Dask cluster: {n} workers x {threads} thread{'s' * (threads > 1)} on 127.0.0.1{link}"


def worker_settings(dashboard: bool) -> dict:
    """Dask settings of the local workers: their environment (:func:`worker_environ`) and,
    without a dashboard to show it, no statistical profiler (it samples every task's stack
    every 10 ms, and cost a fit about a tenth of its time)."""
    return {"distributed.nanny.pre-spawn-environ": worker_environ(), "distributed.worker.profile.enabled": dashboard}


def worker_environ() -> dict:
    """The environment a local worker process starts with: Dask's, without the glibc malloc
    trim threshold it sets. That setting turns off glibc's dynamic mmap threshold, so every
    large temporary tensor is mapped and unmapped afresh: a fit ran 1.3 times slower in a
    worker than in a plain process (docs/architecture.md)."""
    import dask

    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return environ


def _local_cluster(n: int, threads: int, dashboard: bool, level: int):
    from distributed import LocalCluster

    return LocalCluster(
        n_workers=n,
        threads_per_worker=threads,
        processes=True,
        host="127.0.0.1",
        scheduler_port=0,
        dashboard_address="127.0.0.1:8787" if dashboard else "127.0.0.1:0",  # 0: a free port, health checks only
        scheduler_kwargs={"dashboard": dashboard},
        resources={FIT_RESOURCE: 1},
        silence_logs=level,
    )


# --- the batch -------------------------------------------------------------------------------


def run_batch(
    targets: list[Target],
    out: str | Path,
    config,
    *,
    invert: bool | None = None,
    force: bool = False,
    workers: int | None = None,
    threads_per_worker: int | None = None,
    scheduler: str | None = None,
    dashboard: bool = False,
    show_progress: bool = True,
    say: Callable[[str], None] = print,
    on_row: Callable[[dict], None] | None = None,
    on_start: Callable[[str, str, int], None] | None = None,
) -> BatchReport:
    """Fit every target into ``out/NAME/`` on a Dask cluster and write out/summary.csv and
    out/index.html (rewritten after each result, so they are current at any moment).

    ``config`` is a FitConfig; its device is resolved on each worker ('auto': CUDA where the
    worker has it). ``say`` gets one line per finished target and about the cluster;
    ``on_row(row)`` is called for each new row, ``on_start(name, worker, pid)`` when a worker
    starts a target (again if it is rerun after a worker died). No cluster is started when
    there is nothing to fit. Ctrl-C cancels what is running, keeps what is finished (summary
    included), shuts a local cluster down and raises KeyboardInterrupt; a rerun goes on."""
    if dashboard:
        try:
            import bokeh  # noqa: F401
        except ImportError:
            raise BatchError("--dashboard needs bokeh: pip install 'bokeh>=3.1'") from None
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise BatchError(f"output path {out} exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BatchError(f"cannot write to {out}: {exc.strerror}") from None
    settings = settings_of(config, invert)
    plan = make_plan(targets, out, settings, force)
    previous = _read_summary(out / "summary.csv")
    kept = {t: _result_row(t, out / t.name, "kept", previous.get(t.name, {})) for t in plan.done}
    report = BatchReport(out, [kept[t] if t in kept else _pending_row(t) for t in targets])
    jobs = []
    for t in plan.todo:
        try:
            jobs.append((t, *_read_target(t, invert)))
        except HandshadowError as exc:
            report.put(_failed_row(t, str(exc)))
    say(
        f"{len(targets)} targets: {len(jobs)} to fit, {len(plan.done)} already done"
        + (" (--force redoes them)" if plan.done else "")
        + (f", {len(plan.todo) - len(jobs)} unreadable" if len(plan.todo) > len(jobs) else "")
    )
    for row in report.failed:
        say(_row_line(row))
        if on_row is not None:
            on_row(row)
    if not jobs:
        write_summary(report)
        return report
    bar = _progress_bar(len(targets), len(targets) - len(jobs), show_progress)
    try:
        _fit_on_cluster(
            jobs,
            report,
            config,
            invert,
            settings,
            cluster=(scheduler, workers, threads_per_worker, dashboard),
            say=say if bar is None else _above(bar, say),
            on_row=on_row,
            on_start=on_start,
            bar=bar,
        )
    except KeyboardInterrupt:
        report.interrupted = True
        write_summary(report)
        raise
    finally:
        if bar is not None:
            bar.close()
    return report


def _fit_on_cluster(jobs, report: BatchReport, config, invert, settings, cluster, say, on_row, on_start, bar) -> None:
    """Submit one task per job, write each result as it comes (any order), cancel the rest
    on the way out."""
    from distributed import as_completed

    run = uuid.uuid4().hex[:8]
    starts: Counter = Counter()

    def on_event(event) -> None:  # (time, message) from fit_task, on the client's event loop
        msg = event[1]
        if isinstance(msg, dict) and msg.get("run") == run:
            starts[msg["name"]] += 1
            log.info("%s started on %s (pid %s)", msg["name"], msg["worker"], msg["pid"])
            if on_start is not None:
                on_start(msg["name"], msg["worker"], msg["pid"])

    with open_cluster(*cluster, quiet_logs=not log.isEnabledFor(logging.INFO)) as (client, about):
        say(about)
        write_summary(report)
        client.subscribe_topic(EVENT_TOPIC, on_event)
        resources = {FIT_RESOURCE: 1} if _has_fit_resource(client) else None
        futures = {}
        for t, suffix, image in jobs:
            args = (t.name, t.source, suffix, image, config, invert, run)
            key = f"handshadow-fit-{t.name}-{run}"
            futures[client.submit(fit_task, *args, key=key, pure=False, resources=resources)] = t
        try:
            for future in as_completed(futures):
                t = futures[future]
                row = _collect(t, future, report.out, starts[t.name], settings)
                future.release()
                report.put(row)
                write_summary(report)
                say(_row_line(row))
                if on_row is not None:
                    on_row(row)
                if bar is not None:
                    bar.update(1)
        finally:
            client.cancel([f for f in futures if not f.done()])


def _read_target(t: Target, invert: bool | None) -> tuple[str, bytes]:
    """(suffix, bytes) of a target's image, checked here so an unreadable one fails at once."""
    from handshadow import examples
    from handshadow.target import load_target

    path = examples.target_path(t.source)
    load_target(path, 64, 64, invert)
    try:
        return path.suffix, path.read_bytes()
    except OSError as exc:
        raise BatchError(f"cannot read {t.source}: {exc.strerror}") from None


def _has_fit_resource(client) -> bool:
    """Whether any worker offers the ``fit`` resource (else tasks must not ask for it)."""
    return client.run_on_scheduler(
        lambda dask_scheduler: any(ws.resources.get(FIT_RESOURCE, 0) >= 1 for ws in dask_scheduler.workers.values())
    )


def _collect(t: Target, future, out: Path, starts: int, settings: dict) -> dict:
    """A finished task -> its row; a result is written into out/NAME/ whole."""
    from distributed.scheduler import KilledWorker

    from handshadow.export.files import ResultFolder

    attempts = max(1, starts)
    try:
        res = future.result()
    except KilledWorker:
        return _failed_row(t, f"its worker died {attempts} times (out of memory?); see the workers' logs", attempts)
    except Exception as exc:  # a bug in a fit: the batch goes on, the row says what happened
        return _failed_row(t, f"{type(exc).__name__}: {_one_line(exc)}", attempts)
    extra = {"worker": res.get("worker", ""), "attempts": attempts}
    if "error" in res:
        return _failed_row(t, res["error"], **extra)
    if res["interrupted"]:
        return _failed_row(t, "interrupted on its worker; nothing written", **extra)
    with ResultFolder(out / t.name, force=True) as folder:
        for name, data in res["files"].items():
            (folder / name).write_bytes(data)
        folder.commit()
    record(out, t.name, settings)
    return _result_row(t, out / t.name, "done", {**extra, "task_s": res["task_s"]})


# --- rows, summary.csv, index.html ------------------------------------------------------------


def _result_row(t: Target, folder: Path, status: str, batch: dict) -> dict:
    """A row from the folder's pose.json "fit" section (every measure in it, new ones too)."""
    fit = json.loads((folder / "pose.json").read_text())["fit"]
    row = {k: "" for k in FIRST_COLUMNS + BATCH_COLUMNS}
    row.update(fit)
    row.update(
        name=t.name,
        error="",
        status=status,
        source=t.source,
        worker=batch.get("worker", ""),
        attempts=batch.get("attempts", ""),
        task_s=batch.get("task_s", ""),
    )
    return row


def _failed_row(t: Target, error: str, attempts: int | str = "", worker: str = "") -> dict:
    row = {k: "" for k in FIRST_COLUMNS + BATCH_COLUMNS}
    row.update(name=t.name, error=error, status="failed", source=t.source, attempts=attempts, worker=worker)
    return row


def _pending_row(t: Target) -> dict:
    return {**_failed_row(t, ""), "status": "pending"}


def _read_summary(path: Path) -> dict[str, dict]:
    """name -> row of an earlier summary.csv (for the worker that made a kept result)."""
    try:
        with path.open(newline="") as f:
            return {r["name"]: r for r in csv.DictReader(f) if r.get("name")}
    except (OSError, csv.Error, KeyError):
        return {}


def columns(rows: list[dict]) -> list[str]:
    """FIRST_COLUMNS, BATCH_COLUMNS, then every other key in the order first met."""
    cols = list(FIRST_COLUMNS + BATCH_COLUMNS)
    for r in rows:
        cols += [k for k in r if k not in cols]
    return cols


def write_summary(report: BatchReport) -> None:
    """out/summary.csv and out/index.html, each replaced whole."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns(report.rows), restval="", lineterminator="\n")
    writer.writeheader()
    writer.writerows(report.rows)
    _write_atomic(report.out / "summary.csv", buf.getvalue())
    _write_atomic(report.out / "index.html", index_html(report))


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.parent / f".{path.name}.partial-{os.getpid()}"
    tmp.write_text(text)
    os.replace(tmp, path)


def _sort_key(row: dict) -> tuple:
    """Failures first (errors, then fits short of the success test), worst IoU first."""
    rank = 0 if row["status"] in ("failed", "pending") else 1 if not row["success"] else 2
    return rank, row["iou"] if isinstance(row["iou"], float) else 0.0, row["name"]


_MEASURES = {"iou": "IoU", "thin_recall": "thin parts", "hd95": "HD95", "hands": "hands", "seconds": "fit s"}
_NOT_SHOWN = set(FIRST_COLUMNS) | set(BATCH_COLUMNS) | {"success", "interrupted"}


def index_html(report: BatchReport) -> str:
    """A contact sheet page: per row target, shadow and overlay, the measures, a link to the
    folder; failures first. Images are the result folders' own files (relative links)."""
    m = report.medians()
    esc = html.escape
    head = (
        f"{m['n']} of {len(report.rows)} fitted, success {m['success']:.0%}, median IoU {m['median_iou']:.3f}, "
        f"median {m['median_s']:.1f} s a fit; {len(report.failed)} failed"
        if m["n"]
        else f"no results yet; {len(report.failed)} failed"
    )
    if report.interrupted:
        head += " (interrupted: run the batch again to go on)"
    body = []
    for row in sorted(report.rows, key=_sort_key):
        name = esc(row["name"])
        href = esc(urllib.parse.quote(f"{row['name']}/"), quote=True)
        if row["status"] in ("failed", "pending"):
            state = "failed" if row["status"] == "failed" else "not run"
            body.append(
                f'<tr class="failed"><td><b>{name}</b><br>{state}</td>'
                f'<td colspan="3" class="error">{esc(str(row["error"]) or "not fitted yet")}</td>'
                f"<td>{esc(str(row['source']))}</td></tr>"
            )
            continue
        images = "".join(
            f'<td><a href="{href}"><img src="{href}{f}" alt="{f}" loading="lazy"></a></td>'
            for f in ("target.png", "shadow.png", "overlay.png")
        )
        measures = "<br>".join(f"{label} {_fmt(row.get(k), k)}" for k, label in _MEASURES.items())
        others = ", ".join(f"{esc(k)} {esc(_fmt(v))}" for k, v in row.items() if k not in _NOT_SHOWN and v != "")
        verdict = "success" if row["success"] else "short of the success test"
        body.append(
            f'<tr class="{"ok" if row["success"] else "miss"}"><td><a href="{href}"><b>{name}</b></a><br>{verdict}'
            f"<br><small>{esc(str(row['worker']))}</small></td>{images}<td>{measures}<br><small>{others}</small></td></tr>"
        )
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>handshadow batch: {esc(str(report.out))}</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; }}
table {{ border-collapse: collapse; }}
td, th {{ border-top: 1px solid #ccc; padding: 6px 10px; vertical-align: top; text-align: left; }}
img {{ width: 160px; height: 160px; object-fit: contain; image-rendering: pixelated; border: 1px solid #ddd; }}
tr.failed td:first-child, tr.miss td:first-child {{ border-left: 6px solid #c83c3c; }}
tr.ok td:first-child {{ border-left: 6px solid #3caa3c; }}
.error {{ color: #a00; font-family: monospace; }}
</style></head><body>
<h1>handshadow batch</h1>
<p>{esc(head)}. Failures first; each name links to its result folder. Overlay: grey both, red extra shadow, blue missing.</p>
<table>
<tr><th>name</th><th>target</th><th>shadow</th><th>overlay</th><th>measures</th></tr>
{chr(10).join(body)}
</table></body></html>
"""


def _fmt(v, key: str = "") -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.3f}" if abs(v) < 10 and not key.endswith("seconds") else f"{v:.1f}"
    return str(v)


def _row_line(row: dict) -> str:
    """One line a person reads as a target finishes."""
    if row["status"] == "failed":
        return f"{row['name']:20s} FAILED  {row['error']}"
    verdict = "success" if row["success"] else "miss"
    where = f"  {row['worker']}" if row["worker"] else ""
    again = f"  (attempt {row['attempts']})" if isinstance(row["attempts"], int) and row["attempts"] > 1 else ""
    return (
        f"{row['name']:20s} {verdict:7s} IoU {row['iou']:.3f}  thin {row['thin_recall']:.2f}  HD95 {row['hd95']:.3f}"
        f"  {row['seconds']:6.1f} s{where}{again}"
    )


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _progress_bar(total: int, initial: int, show: bool):
    import sys

    if not show or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc="batch", unit="target", leave=False)


def _above(bar, say: Callable[[str], None]) -> Callable[[str], None]:
    """Lines printed above the progress bar instead of through it."""
    return lambda line: bar.write(line) if say is print else say(line)
