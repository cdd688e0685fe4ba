"""`handshadow app`: a local web page to make a hand shadow from an upload, a drawing or an
example, watch the fit, turn the 3D hands around, and download everything.

Three parts:

- the work, free of Gradio: sessions (`SessionStore`), a `Job` (a worker thread, a queue of
  progress snapshots, a cancel event), and the steps of a fit, a reading and a morph as plain
  functions of plain values (`read_for_page`, `fit_steps`, `morph_steps`);
- the page, `layout`: components only, no behaviour;
- `build_app`: thin wiring from the page's events to the work.

Offline and private: it binds to 127.0.0.1 unless told otherwise, Gradio's analytics and
Hugging Face telemetry are switched off (in `launch`, before Gradio is imported), fonts are
Gradio's bundled ones, and every browser session works in its own temporary folder, deleted
when the session ends and when the app stops. Gradio is an optional extra
(``pip install 'handshadow[app]'``), imported only here, only when the app starts.

Uploads go to the same reading as the command line (`target.py`): the file itself, not a
copy converted in the browser. The page shows the shape as it will be read as soon as a
picture is chosen, and every error or warning stays in the status line in words.
"""

import atexit
import dataclasses
import os
import queue
import re
import shutil
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from handshadow.errors import HandshadowError
from handshadow.scene import FIT_LAMP_TO_WALL_M, LAMP_TO_WALL_M, LAMP_TO_WALL_RANGE_M

MAX_UPLOAD = "8mb"
# The page fits as the command line does unless asked otherwise: on the 95 HSP shapes (2-core
# CPU, docs/measured.md, 2026-12-06) fast passed the success test on 61 % in a median 14 s (a near
# miss hops and tries again, up to about 3 min), default on 86 % in a median 33 to 41 s with
# its settling (a shape it fails takes up to about 7 min).
DEFAULT_QUALITY = "default"  # FitConfig.quality (a test holds them equal)
QUALITY_HELP = (
    "default: about half a minute, up to about 7 minutes for a shape it cannot reach, as the command line;"
    " fast: about 14 s, a rough first look that matches three in five shapes (up to about 4 minutes on a near miss);"
    " best: longer (a 2-core CPU)"
)
INSTALL_HINT = "the app needs Gradio, an optional extra: pip install 'handshadow[app]'"
# Set before Gradio (and the Hugging Face hub it imports) reads them: no analytics, no telemetry, offline.
OFFLINE_ENV = {
    "GRADIO_ANALYTICS_ENABLED": "False",
    "HF_HUB_DISABLE_TELEMETRY": "1",
    "HF_HUB_OFFLINE": "1",
    "GRADIO_DO_NOT_TRACK": "1",
}
PREVIEW_ROWS = 256  # height of the pictures of the target and the overlay, pixels (about)
PREVIEW_EVERY_S = 0.7  # at most one live preview per this many seconds
SIZES = ["64", "128", "256"]  # the frame's side: detail against time
READY = "Pick a shape and press **Fit**."
DRAW = "Draw a filled shape, then press **Fit**."
CANCELLING = "Cancelling: keeping the best result so far..."


class Session:
    """One browser session's folder and its cancel switch."""

    def __init__(self, root: Path):
        self.dir = Path(tempfile.mkdtemp(prefix="session-", dir=root))
        self.cancel = threading.Event()

    def new_job(self, kind: str) -> Path:
        return self.dir / f"{kind}-{uuid.uuid4().hex[:8]}"


class SessionStore:
    """Sessions by Gradio session hash; each has its own folder under one root temp dir."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="handshadow-app-"))
        self._sessions: dict[str, Session] = {}
        self._lock = threading.Lock()
        atexit.register(self.close)

    def get(self, key: str | None) -> Session:
        key = key or "local"
        with self._lock:
            if key not in self._sessions:
                self._sessions[key] = Session(self.root)
            return self._sessions[key]

    def drop(self, key: str | None) -> None:
        with self._lock:
            session = self._sessions.pop(key or "local", None)
        if session is not None:
            session.cancel.set()
            shutil.rmtree(session.dir, ignore_errors=True)

    def close(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)


class Job:
    """Work in its own thread: ``work(report, stop)`` calls ``report(update)`` as it goes and
    checks ``stop()`` (the cancel event) at every step. ``updates()`` yields what was
    reported until the work ends; ``outcome()`` is its return value, or raises its error."""

    def __init__(self, work: Callable[[Callable, Callable[[], bool]], object], cancel: threading.Event):
        self.cancel = cancel
        self._work = work
        self._queue: queue.Queue = queue.Queue()
        self._result: object = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        try:
            self._result = self._work(self._queue.put, self.cancel.is_set)
        except Exception as exc:  # shown in the page
            self._error = exc

    def start(self) -> "Job":
        self._thread.start()
        return self

    def updates(self, poll_s: float = 0.25) -> Iterator[object]:
        while self._thread.is_alive() or not self._queue.empty():
            try:
                yield self._queue.get(timeout=poll_s)
            except queue.Empty:
                continue
        self._thread.join()

    def outcome(self) -> object:
        if self._error is not None:
            raise self._error
        return self._result


@dataclasses.dataclass(frozen=True)
class FitOptions:
    """What the page's options say: hands '1', '2' or 'auto'; the rest as FitConfig."""

    hands: str = "auto"
    quality: str = DEFAULT_QUALITY
    limits: str = "anatomical"
    light: str = "point"
    size: int = 256
    invert: bool = False
    view_angle: float = 90.0  # degrees between the two lamps when a second shadow is asked for
    lamp_distance: float = FIT_LAMP_TO_WALL_M  # metres from the point lamp to the wall (one shadow only)
    hand_shape: str = ""  # the performer's build as typed (handshadow fit --hand-shape); empty: the default hand
    time_limit_s: float | None = None  # the host's bound on each fit (handshadow app --time-limit); None: none


@dataclasses.dataclass(frozen=True)
class FitUpdate:
    """One step of a fit for the page: preview (H, W, 3) uint8 or a file path or None (keep),
    status (Markdown), finished (the result's folder and zip once done, else None), and
    fraction (0..1, for the progress bar; None when not fitting)."""

    preview: object
    status: str
    finished: dict | None = None
    fraction: float | None = None


def in_words(exc: BaseException, *paths: str) -> str:
    """A one-line message for the page: uploaded files named by their own names, not their
    temporary paths, and the page's words for the command line's options."""
    message = str(exc).splitlines()[0] if str(exc) else exc.__class__.__name__
    for path in paths:
        message = message.replace(str(path), Path(path).name)
    return message.replace("use --invert", "tick Invert (in Options)")


def _drawing(editor_value):
    """The composite of a Sketchpad value, or None when nothing was drawn."""
    if editor_value is None:
        return None
    composite = editor_value.get("composite") if isinstance(editor_value, dict) else editor_value
    if composite is None:
        return None
    arr = np.asarray(composite)
    if arr.ndim == 3 and arr.shape[2] == 4:
        drawn = arr[..., 3] > 0
    else:
        grey = arr if arr.ndim == 2 else arr[..., :3].mean(-1)
        drawn = grey < 128
    return arr if drawn.any() else None


def target_source(source: str, upload: str | None, drawing, example: str | None, folder: Path) -> str:
    """What the fit reads: the uploaded file itself, the drawing saved as a PNG, or an
    example's name. Raises ValueError with a one-line message when nothing is chosen."""
    if source == "Draw":
        image = _drawing(drawing)
        if image is None:
            raise ValueError("the sketchpad is empty: draw a shape first")
        import imageio.v3 as iio

        folder.mkdir(parents=True, exist_ok=True)
        iio.imwrite(folder / "drawing.png", np.asarray(image, np.uint8))
        return str(folder / "drawing.png")
    if source == "Upload":
        if not upload:
            raise ValueError("no picture yet: upload one (PNG, JPEG, GIF, BMP, WebP ...), or pick an example")
        return str(upload)
    if not example:
        raise ValueError("pick an example")
    return example


def read_for_page(source: str | None, invert: bool = False, size: int = 256) -> tuple[np.ndarray | None, str]:
    """(the shape as the fit will read it: target.png's size x size black on white frame; the
    status line): the reading's warning, or its error in words, or that all is ready."""
    from handshadow.examples import target_path
    from handshadow.export.images import mask_image
    from handshadow.target import read_target

    if not source:
        return None, READY
    try:
        target = read_target(target_path(source), size, size, invert or None)
    except HandshadowError as exc:
        return None, f"**Cannot use this picture:** {in_words(exc, source)}"
    picture = enlarged(mask_image(target.frame))
    if target.warning:
        return picture, f"**Warning:** {target.warning} (below). Then press **Fit**."
    return picture, "The shape as it will be read is below. Press **Fit**."


def enlarged(image: np.ndarray, rows: int = PREVIEW_ROWS) -> np.ndarray:
    """A small picture (H, W[, 3]) repeated by a whole factor to about ``rows`` rows, so a
    64-pixel frame shows as large and as crisp as a 256-pixel one."""
    k = max(1, rows // image.shape[0])
    return np.repeat(np.repeat(image, k, axis=0), k, axis=1)


def fit_steps(session: Session, source: str | list[str], options: FitOptions) -> Iterator[FitUpdate]:
    """A fit for the page: a live preview while it searches, then the result's overlay, folder
    and zip. Cancel (the session's event) keeps the best so far. Errors end it with their message.
    Two sources (the front shadow and a second one, from the side) fit one pose to two views,
    the second lamp turned by options.view_angle degrees; the overlays show side by side."""
    import imageio.v3 as iio

    from handshadow.cli import parse_hand_shape, performance_lines
    from handshadow.examples import target_path
    from handshadow.export.images import overlay_preview
    from handshadow.fit import FitConfig
    from handshadow.pipeline import fit_to_folder, view_name
    from handshadow.target import read_target

    session.cancel.clear()
    folder = session.new_job("fit")
    invert = options.invert or None
    sources = [source] if isinstance(source, str) else list(source)
    try:
        targets = [read_target(target_path(s), options.size, options.size, invert) for s in sources]
    except HandshadowError as exc:
        yield FitUpdate(None, f"**Cannot use this picture:** {in_words(exc, *sources)}")
        return
    target = targets[0]
    note = "".join(f"  \n**Warning:** {t.warning}" for t in targets if t.warning)
    try:
        shape = parse_hand_shape(options.hand_shape, "anny") if options.hand_shape.strip() else {}
    except HandshadowError as exc:
        yield FitUpdate(None, f"**Cannot use this hand build:** {exc}".replace("--hand-shape: ", ""))
        return
    config = FitConfig(
        hands=options.hands,
        quality=options.quality,
        limits=options.limits,
        light=options.light,
        size=options.size,
        device="auto",
        view_angle_deg=options.view_angle,
        lamp_to_wall_m=options.lamp_distance if len(sources) == 1 else None,  # two shadows: the default
        hand_shape=shape,
        time_limit_s=options.time_limit_s,
    )

    def work(report, stop):
        return fit_to_folder(
            sources if len(sources) > 1 else sources[0],
            folder / "result",
            config,
            invert=invert,
            show_progress=False,
            progress_hook=report,
            stop=stop,
        )

    job = Job(work, session.cancel).start()
    yield FitUpdate(None, "Fitting..." + note, fraction=0.0)
    last = 0.0
    for p in job.updates():
        fraction = 1.0 if p.hop else min(1.0, p.done / max(p.total, 1))  # a hop comes after the search
        if time.perf_counter() - last > PREVIEW_EVERY_S:
            last = time.perf_counter()
            preview = overlay_preview(target.frame, p.shadow, PREVIEW_ROWS)
            again = f" (a fresh attempt, {p.attempt + 1})" if p.attempt else ""
            hop = f" close to the shape, hop {p.hop} of {p.hops}:" if p.hop else ""
            state = CANCELLING if session.cancel.is_set() else f"Fitting{again}...{hop} IoU {p.iou:.3f}"
            yield FitUpdate(preview, state + note, fraction=fraction)
    try:
        result_folder, result, lines = job.outcome()
    except Exception as exc:  # a fit's error, in words
        yield FitUpdate(None, f"**The fit stopped:** {in_words(exc, *sources)}")
        return
    yield FitUpdate(None, "Making the model to 3D-print..." + note, fraction=1.0)
    printed = printable(result_folder)
    zip_path = shutil.make_archive(str(folder / "handshadow-result"), "zip", result_folder)
    status = (
        ("Cancelled: best result so far. " if result.interrupted else "")
        + str(result.score)
        + (" (a success)" if result.success else "")
        + limit_note(result, options.time_limit_s)
        + note
        + f"  \n{printed}"
        + "\n\n"
        + "\n".join(line.strip() for line in [*performance_lines(result), *lines])
    )
    n = len(sources)
    overlays = [enlarged(iio.imread(result_folder / view_name("overlay", k, n))) for k in range(n)]
    finished = {"folder": str(result_folder), "zip": zip_path, "views": n}
    if n > 1:  # the shadows side by side, for the page only (the folder keeps one file per view)
        shadows = [iio.imread(result_folder / view_name("shadow", k, n)) for k in range(n)]
        finished["shadow"] = str(folder / "shadows.png")
        iio.imwrite(finished["shadow"], side_by_side(shadows))
    yield FitUpdate(side_by_side(overlays), status, finished)


def host_limit(time_limit_s: float) -> str:
    """The page's words for the host's bound on each fit (handshadow app --time-limit)."""
    return f"This app ends each fit after {time_limit_s:g} s"


def limit_note(result, time_limit_s: float | None) -> str:
    """The status's words when the host's time limit, not the search, ended a fit that failed
    the success test ("" otherwise)."""
    if time_limit_s is None or result.success or result.interrupted or not result.posed.fit.get("time_limited"):
        return ""
    return f"  \n{host_limit(time_limit_s)}; `handshadow fit` on your own computer searches longer."


def side_by_side(images: list[np.ndarray], gap: int = 8) -> np.ndarray:
    """Pictures of one height (H, W[, 3]) uint8 in a row, ``gap`` white pixels between them."""
    images = [np.repeat(i[..., None], 3, -1) if i.ndim == 2 else i[..., :3] for i in images]
    space = np.full((images[0].shape[0], gap, 3), 255, np.uint8)
    row = [images[0]]
    for image in images[1:]:
        row += [space, image]
    return np.concatenate(row, 1)


def printable(result_folder: Path) -> str:
    """Write print.stl (and print.3mf, print.json, print.png) into a result folder; one line
    for the page on what the zip holds."""
    from handshadow.export.printing import print_result

    try:
        report = print_result(result_folder)
    except HandshadowError as exc:
        return f"No model to 3D-print: {exc}"
    return f"The zip holds print.stl, {report.height_mm:.0f} mm tall, with print.png telling where the torch goes."


def result_files(finished: dict) -> tuple[str, ...]:
    """The result's files for the page: shadow, 3D hands, guide, pose, zip, search GIF."""
    folder = Path(finished["folder"])
    shadow = finished.get("shadow") or str(folder / "shadow.png")
    names = ("hands.glb", "guide.png", "pose.json")
    return (shadow, *(str(folder / n) for n in names), finished["zip"], str(folder / "progress.gif"))


def morph_steps(
    session: Session,
    a: str,
    b: str,
    frames: int,
    hands: str,
    size: int,
    quality: str = DEFAULT_QUALITY,
    time_limit_s: float | None = None,
):
    """A morph for the page: (video, GIF, path plot, zip, status); both ends fitted at
    ``quality``, each within ``time_limit_s`` (None: no bound). Errors: Nones and the message
    in words."""
    from handshadow.examples import target_path
    from handshadow.fit import FitConfig
    from handshadow.pipeline import interpolate_to_folder
    from handshadow.target import read_target

    folder = session.new_job("morph")
    try:
        targets = [read_target(target_path(source), 64, 64) for source in (a, b)]
        config = FitConfig(hands=hands, quality=quality, size=size, device="auto", time_limit_s=time_limit_s)
        result, report = interpolate_to_folder(a, b, folder / "result", config, frames=frames, show_progress=False)
    except HandshadowError as exc:
        return None, None, None, None, f"**Cannot morph:** {in_words(exc, a, b)}"
    except Exception as exc:  # a fit's or the path's error, in words
        return None, None, None, None, f"**The morph stopped:** {in_words(exc, a, b)}"
    zip_path = shutil.make_archive(str(folder / "handshadow-morph"), "zip", result)
    files = [str(result / n) for n in ("animation.mp4", "animation.gif", "path.png")]
    warnings = [f"**Warning ({end}):** {t.warning}  \n" for end, t in zip(("first", "last"), targets) if t.warning]
    ended = [
        part
        for part, t in zip(("the first end's fit", "the last end's fit", "the path's smoothing"), report.time_limited)
        if t
    ]
    listed = ", ".join(ended[:-1]) + " and " + ended[-1] if len(ended) > 1 else "".join(ended)
    limited = f"  \n{host_limit(time_limit_s)}: it cut {listed} short." if ended else ""
    return (*files, zip_path, "".join(warnings) + report.summary() + limited)


# -- The page ------------------------------------------------------------------------------


@dataclasses.dataclass
class ShadowTab:
    """The Shadow tab's components (Gradio objects)."""

    source: object
    example: object
    upload: object
    drawing: object
    second_source: object
    second_example: object
    second_upload: object
    view_angle: object
    reading: object
    hands: object
    quality: object
    limits: object
    light: object
    lamp_distance: object
    size: object
    invert: object
    hand_shape: object
    fit: object
    cancel: object
    status: object
    guide: object
    preview: object
    shadow: object
    model: object
    pose_file: object
    zip_file: object
    progress_gif: object
    finished: object

    def options(self) -> list:
        return [
            self.hands,
            self.quality,
            self.limits,
            self.light,
            self.lamp_distance,
            self.size,
            self.invert,
            self.view_angle,
            self.hand_shape,
        ]

    def second(self) -> list:
        return [self.second_source, self.second_upload, self.second_example]

    def results(self) -> list:
        return [self.shadow, self.model, self.guide, self.pose_file, self.zip_file, self.progress_gif]


@dataclasses.dataclass
class MorphTab:
    """The Morph tab's components: the two ends (source, example, upload each), the options,
    the button and the outputs."""

    ends: list
    frames: object
    hands: object
    size: object
    quality: object
    morph: object
    status: object
    video: object
    gif: object
    path_plot: object
    zip_file: object


def _sources(
    gr, label: str, choices: list[str], examples: list[str], value: str | None, prefix: str, chosen: str = "Example"
):
    """(source radio, example dropdown, upload) for one shape to choose; ``chosen``: the radio's
    first choice."""
    source = gr.Radio(choices, value=chosen, label=label, elem_id=f"{prefix}source")
    example = gr.Dropdown(
        examples, value=value, label="Example", visible=chosen == "Example", elem_id=f"{prefix}example"
    )
    upload = gr.Image(
        label="Your picture: a shape on a plain ground, or a photo of a shadow on a wall",
        type="filepath",
        image_mode=None,  # the file itself goes to the reading, unconverted
        sources=["upload", "clipboard"],
        visible=False,
        elem_id=f"{prefix}upload",
    )
    return source, example, upload


def _fit_options(gr) -> dict:
    """The Options accordion's components, by ShadowTab field."""
    with gr.Accordion("Options", open=False):
        return {
            "hands": gr.Radio(
                ["1", "2", "auto"],
                value="auto",
                label="Hands",
                info="auto tries both: one hand when one makes the shape, else two",
                elem_id="hands",
            ),
            "quality": gr.Radio(
                ["fast", "default", "best"],
                value=DEFAULT_QUALITY,
                label="Quality",
                info=QUALITY_HELP,
                elem_id="quality",
            ),
            "size": gr.Radio(
                SIZES,
                value="256",
                label="Detail (pixels)",
                info="the target's frame: 64 is quick and coarse; 256 as the command line",
                elem_id="size",
            ),
            "limits": gr.Radio(
                ["anatomical", "paper"],
                value="anatomical",
                label="Joint limits",
                info="anatomical: real ranges of motion; paper: Table 1 of the 2023 paper",
            ),
            "light": gr.Radio(
                ["point", "directional"],
                value="point",
                label="Light",
                info="point: a lamp (its distance below); directional: sunlight",
            ),
            "lamp_distance": gr.Slider(
                LAMP_TO_WALL_RANGE_M[0],
                LAMP_TO_WALL_RANGE_M[1],
                value=FIT_LAMP_TO_WALL_M,
                step=0.5,
                label="Lamp distance (m)",
                info="a point lamp farther from the wall: the same picture, less perspective"
                f" (one shadow; two shadows keep {LAMP_TO_WALL_M:g} m)",
                elem_id="lamp-distance",
            ),
            "invert": gr.Checkbox(value=False, label="Invert: the shape is lighter than its ground", elem_id="invert"),
            "hand_shape": gr.Textbox(
                value="",
                label="Your hands' build (optional)",
                placeholder="e.g. weight=0.8,muscle=0.7",
                info="Anny phenotype values from 0 to 1: gender, age, muscle, weight, height, proportions"
                " (0.5 each by default); a new build takes about a minute to make, once",
                elem_id="hand-shape",
            ),
        }


def _second_shadow(gr, example_names: list[str]) -> dict:
    """The optional second target: one pose casting two shadows, the second lamp to the side."""
    from handshadow.scene import VIEW_ANGLE_MAX_DEG, VIEW_ANGLE_MIN_DEG

    c = {}
    with gr.Accordion("A second shadow, from the side (optional)", open=False):
        c["second_source"], c["second_example"], c["second_upload"] = _sources(
            gr, "Second shadow", ["None", "Example", "Upload"], example_names, None, "second-", chosen="None"
        )
        c["view_angle"] = gr.Slider(
            VIEW_ANGLE_MIN_DEG,
            VIEW_ANGLE_MAX_DEG,
            value=90,
            step=5,
            label="Angle between the two lamps (degrees)",
            info="the second lamp and wall turned about the hands; 90 as in classic shadow sculptures",
            elem_id="view-angle",
        )
    return c


def _shape_column(gr, example_names: list[str]) -> dict:
    """Left: the shape, the options, Fit and Cancel, the status line, the reading, the guide."""
    c = {}
    first = example_names[0] if example_names else None
    c["source"], c["example"], c["upload"] = _sources(
        gr, "Shape", ["Example", "Upload", "Draw"], example_names, first, ""
    )
    c["drawing"] = gr.Sketchpad(
        label="Draw a filled shape (pick the brush first)",
        type="numpy",
        image_mode="RGBA",
        brush=gr.Brush(default_size=28, colors=["#000000"], color_mode="fixed"),
        canvas_size=(512, 512),
        visible=False,
        elem_id="sketchpad",
    )
    c.update(_second_shadow(gr, example_names))
    c.update(_fit_options(gr))
    with gr.Row():
        c["fit"] = gr.Button("Fit", variant="primary", elem_id="fit")
        c["cancel"] = gr.Button("Cancel", elem_id="cancel")
    c["status"] = gr.Markdown(READY, elem_id="status")
    c["reading"] = gr.Image(
        label="The shape as it will be read (target.png)",
        type="numpy",
        format="png",  # lossless: exactly what target.png will hold
        elem_id="reading",
        height=220,
    )
    c["guide"] = gr.Image(label="How to hold your hands", type="filepath", elem_id="guide")
    return c


def _result_column(gr) -> dict:
    """Right: the live preview, the shadow, the 3D hands, the files."""
    c = {}
    with gr.Row():
        c["preview"] = gr.Image(
            label="Shadow over target: grey both, red extra, blue missing",
            type="filepath",
            format="png",
            elem_id="preview",
            height=300,
        )
        c["shadow"] = gr.Image(label="The shadow", type="filepath", elem_id="shadow", height=300)
    c["model"] = gr.Model3D(
        label="3D: drag to turn. Hands, lamp (yellow) and wall",
        clear_color=(0.93, 0.94, 0.96, 1.0),
        elem_id="model3d",
        height=440,
    )
    with gr.Row():
        c["pose_file"] = gr.File(label="pose.json", elem_id="pose")
        c["zip_file"] = gr.File(label="Everything (zip)", elem_id="zip")
    with gr.Accordion("The search, step by step", open=False):
        c["progress_gif"] = gr.Image(label="progress.gif", type="filepath", elem_id="progress")
    return c


def _morph_tab(gr, example_names: list[str]) -> MorphTab:
    gr.Markdown("Two shadows in, a performance out: the poses that turn the first shadow into the second.")
    ends = []
    with gr.Row():
        for k, label in enumerate(["First shadow", "Last shadow"]):
            with gr.Column():
                value = example_names[k] if len(example_names) > k else None
                ends.append(_sources(gr, label, ["Example", "Upload"], example_names, value, f"morph{k}-"))
    with gr.Row():
        frames = gr.Slider(8, 60, value=30, step=1, label="Frames", elem_id="frames")
        hands = gr.Radio(["1", "2"], value="2", label="Hands", elem_id="morph-hands")
        size = gr.Radio(SIZES, value="256", label="Detail (pixels)", elem_id="morph-size")
        quality = gr.Radio(
            ["fast", "default", "best"], value=DEFAULT_QUALITY, label="Quality of the ends", elem_id="morph-quality"
        )
        morph = gr.Button("Morph", variant="primary", elem_id="morph")
    status = gr.Markdown(
        "Pick two shapes and press **Morph** (several minutes: two fits and the path; fast ends take one or two).",
        elem_id="morph-status",
    )
    with gr.Row():
        video = gr.Video(label="Animation", elem_id="video")
        gif = gr.Image(label="Animation (GIF)", type="filepath", elem_id="morph-gif")
    return MorphTab(
        ends=ends,
        frames=frames,
        hands=hands,
        size=size,
        quality=quality,
        morph=morph,
        status=status,
        video=video,
        gif=gif,
        path_plot=gr.Image(label="Path", type="filepath", elem_id="path-plot"),
        zip_file=gr.File(label="Everything (zip)", elem_id="morph-zip"),
    )


def layout(gr, example_names: list[str], time_limit_s: float | None = None) -> tuple[ShadowTab, MorphTab]:
    """The page's components, inside an open gr.Blocks; no behaviour. ``time_limit_s``: the
    host's bound on each fit, said under the title (None: nothing said)."""
    gr.Markdown(
        "# handshadow\n"
        "Make a shadow with your hands. **1.** Choose a shape: an example, your own picture (a photo of a "
        "shadow on a wall works too), or a drawing. **2.** Press **Fit** and watch the hands find it. "
        "**3.** Turn the 3D hands around, read how to hold them, and try it with a lamp and a wall."
        + (f" {host_limit(time_limit_s)}." if time_limit_s else ""),
        elem_id="intro",
    )
    with gr.Tab("Shadow"):
        with gr.Row():
            with gr.Column(scale=2, min_width=320):
                left = _shape_column(gr, example_names)
            with gr.Column(scale=3, min_width=420):
                right = _result_column(gr)
        shadow_tab = ShadowTab(**left, **right, finished=gr.State(None))
    with gr.Tab("Morph"):
        morph_tab = _morph_tab(gr, example_names)
    return shadow_tab, morph_tab


# -- Wiring --------------------------------------------------------------------------------


def build_app(store: SessionStore | None = None, time_limit_s: float | None = None):
    """The Gradio Blocks of the app, and its session store. ``time_limit_s`` bounds each fit
    (FitConfig.time_limit_s; None: no bound)."""
    import gradio as gr

    from handshadow import examples

    store = store or SessionStore()

    def session_of(request: gr.Request) -> Session:
        return store.get(getattr(request, "session_hash", None))

    def show_source(choice):
        return [gr.update(visible=choice == c) for c in ("Example", "Upload", "Draw")]

    def chosen(source, upload, example):
        return upload if source == "Upload" else example if source == "Example" else None

    def show_reading(source, upload, example, invert, size):
        if source == "Draw":
            return None, DRAW
        return read_for_page(chosen(source, upload, example), invert, int(size))

    def on_fit(source, upload, drawing, example, second_source, second_upload, second_example, hands, quality,
               limits, light, lamp_distance, size, invert, view_angle, hand_shape, request: gr.Request,
               progress=gr.Progress()):  # noqa: B008  # fmt: skip
        session = session_of(request)
        options = FitOptions(
            hands=hands,
            quality=quality,
            limits=limits,
            light=light,
            lamp_distance=float(lamp_distance),
            size=int(size),
            invert=bool(invert),
            view_angle=float(view_angle),
            hand_shape=str(hand_shape or ""),
            time_limit_s=time_limit_s,
        )
        try:
            target = target_source(source, upload, drawing, example, session.new_job("input"))
            if second_source != "None":
                second = target_source(second_source, second_upload, None, second_example, session.new_job("second"))
                target = [target, second]
        except ValueError as exc:
            yield None, f"**Nothing to fit:** {exc}", None
            return
        for update in fit_steps(session, target, options):
            if update.fraction is not None:
                progress(update.fraction, desc=update.status.split("  \n")[0])
            yield gr.skip() if update.preview is None else update.preview, update.status, update.finished

    def on_result(finished):
        # A separate, non-streaming step: Gradio's 3D viewer does not mount from a generator.
        return result_files(finished) if finished else [gr.skip()] * 6

    def on_leave(request: gr.Request):
        store.drop(getattr(request, "session_hash", None))

    def on_cancel(request: gr.Request):
        session_of(request).cancel.set()
        return CANCELLING

    def on_morph(source_a, example_a, upload_a, source_b, example_b, upload_b, frames, hands, size, quality,
                 request: gr.Request, progress=gr.Progress()):  # noqa: B008  # fmt: skip
        session = session_of(request)
        try:
            a = target_source(source_a, upload_a, None, example_a, session.new_job("a"))
            b = target_source(source_b, upload_b, None, example_b, session.new_job("b"))
        except ValueError as exc:
            return None, None, None, None, f"**Nothing to morph:** {exc}"
        progress(0.05, desc="fitting both ends and the path")
        return morph_steps(session, a, b, int(frames), hands, int(size), quality, time_limit_s)

    with gr.Blocks(title="handshadow", analytics_enabled=False) as demo:
        shadow, morph = layout(gr, [name for name, _ in examples.list_targets()], time_limit_s)
        picked = [shadow.source, shadow.upload, shadow.example, shadow.invert, shadow.size]
        shadow.source.change(show_source, shadow.source, [shadow.example, shadow.upload, shadow.drawing], queue=False)
        shadow.second_source.change(
            lambda c: [gr.update(visible=c == "Example"), gr.update(visible=c == "Upload")],
            shadow.second_source,
            [shadow.second_example, shadow.second_upload],
            queue=False,
        )
        gr.on(  # one listener for all: its runs follow each other, the last choice is the one shown
            [demo.load, *(component.change for component in picked)],
            show_reading,
            picked,
            [shadow.reading, shadow.status],
            queue=False,
            trigger_mode="always_last",
        )
        shadow.fit.click(lambda: [None] * 6, outputs=shadow.results(), queue=False).then(
            on_fit,
            [shadow.source, shadow.upload, shadow.drawing, shadow.example, *shadow.second(), *shadow.options()],
            [shadow.preview, shadow.status, shadow.finished],
            concurrency_limit=1,  # one fit at a time uses every core; other visitors wait in line
        ).then(on_result, shadow.finished, shadow.results())
        shadow.cancel.click(on_cancel, outputs=[shadow.status], queue=False)
        for source, example, upload in morph.ends:
            source.change(lambda c: [gr.update(visible=c == "Example"), gr.update(visible=c == "Upload")],
                          source, [example, upload], queue=False)  # fmt: skip
        morph.morph.click(
            on_morph,
            [*morph.ends[0], *morph.ends[1], morph.frames, morph.hands, morph.size, morph.quality],
            [morph.video, morph.gif, morph.path_plot, morph.zip_file, morph.status],
            concurrency_limit=1,
        )
        demo.unload(on_leave)
    return demo, store


def launch(host: str = "127.0.0.1", port: int | None = None, block: bool = True, time_limit_s: float | None = None):
    """Start the app; returns (demo, url) when not blocking. ``time_limit_s`` bounds each
    visitor's fit (None: no bound). Without Gradio: a one-line HandshadowError that says how
    to install it."""
    for key, value in OFFLINE_ENV.items():
        os.environ.setdefault(key, value)
    store = SessionStore()
    os.environ["GRADIO_TEMP_DIR"] = str(store.root / "gradio")  # Gradio's own cache, deleted with ours
    try:
        import gradio as gr
    except ModuleNotFoundError as exc:
        if not re.match(r"gradio\b", exc.name or ""):
            raise
        store.close()
        raise HandshadowError(INSTALL_HINT) from None

    demo, _ = build_app(store, time_limit_s)
    demo.queue(default_concurrency_limit=1)
    _, url, _ = demo.launch(
        server_name=host,
        server_port=port,
        prevent_thread_lock=True,
        max_file_size=MAX_UPLOAD,
        share=False,
        ssr_mode=False,
        footer_links=[],
        quiet=True,
        theme=gr.themes.Default(),
        allowed_paths=[str(store.root)],
    )
    if block:
        print(f"handshadow app on {url} (Ctrl-C to stop)", flush=True)
        demo.block_thread()
    return demo, url
