"""`handshadow app`: a local web page to make a hand shadow from an upload, a drawing or an
example, watch the fit, turn the 3D hands around, and download everything.

Offline and private: it binds to 127.0.0.1 unless told otherwise, Gradio's analytics and
Hugging Face telemetry are switched off, fonts are Gradio's bundled ones, and every browser
session works in its own temporary folder, deleted when the session ends and when the app
stops. Gradio is imported only here.
"""

import atexit
import os
import queue
import shutil
import tempfile
import threading
import time
import uuid
from pathlib import Path

os.environ.setdefault("GRADIO_ANALYTICS_ENABLED", "False")
os.environ.setdefault("HF_HUB_DISABLE_TELEMETRY", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("GRADIO_DO_NOT_TRACK", "1")

import numpy as np  # noqa: E402

MAX_UPLOAD = "8mb"
MAX_PIXELS = 16_000_000
QUALITY_HELP = "fast: about 20 s; default: about a minute; best: a few minutes (on a laptop CPU)"


class Session:
    """One browser session's folder and its running job."""

    def __init__(self, root: Path):
        self.dir = Path(tempfile.mkdtemp(prefix="session-", dir=root))
        self.cancel = threading.Event()

    def new_job(self, kind: str) -> Path:
        path = self.dir / f"{kind}-{uuid.uuid4().hex[:8]}"
        return path


class SessionStore:
    """Sessions by Gradio session hash; each has its own folder under one root temp dir."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="handshadow-app-"))
        self._sessions: dict[str, Session] = {}
        self._lock = threading.Lock()
        atexit.register(self.close)

    def get(self, key: str) -> "Session":
        with self._lock:
            if key not in self._sessions:
                self._sessions[key] = Session(self.root)
            return self._sessions[key]

    def drop(self, key: str) -> None:
        with self._lock:
            session = self._sessions.pop(key, None)
        if session is not None:
            session.cancel.set()
            shutil.rmtree(session.dir, ignore_errors=True)

    def close(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)


def _save_target(image, folder: Path) -> Path:
    """Write an uploaded or drawn image (numpy RGB/RGBA) as the job's target.png source."""
    import imageio.v3 as iio

    if image is None:
        raise ValueError("no target: upload an image, draw a shape or pick an example")
    arr = np.asarray(image)
    if arr.ndim < 2 or arr.size == 0:
        raise ValueError("the target image is empty")
    if arr.shape[0] * arr.shape[1] > MAX_PIXELS:
        raise ValueError(
            f"the image is too large ({arr.shape[1]} x {arr.shape[0]} pixels; at most {MAX_PIXELS // 1_000_000} megapixels)"
        )
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "input.png"
    iio.imwrite(path, arr.astype(np.uint8) if arr.dtype != np.uint8 else arr)
    return path


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


def build_app(store: SessionStore | None = None):
    """The Gradio Blocks of the app."""
    import gradio as gr

    from handshadow import examples
    from handshadow.errors import HandshadowError
    from handshadow.fit import FitConfig
    from handshadow.pipeline import fit_to_folder, interpolate_to_folder, resolve_target

    store = store or SessionStore()
    example_names = [name for name, _ in examples.list_targets()]

    def session_of(request: gr.Request) -> Session:
        return store.get(getattr(request, "session_hash", None) or "local")

    def target_source(source, upload, drawing, example, folder: Path) -> str:
        if source == "Draw":
            image = _drawing(drawing)
            if image is None:
                raise ValueError("the sketchpad is empty: draw a shape first")
            return str(_save_target(image, folder))
        if source == "Upload":
            return str(_save_target(upload, folder))
        if not example:
            raise ValueError("pick an example")
        return example

    def run_fit(
        source,
        upload,
        drawing,
        example,
        hands,
        limits,
        quality,
        light,
        request: gr.Request,
        progress=gr.Progress(),  # noqa: B008
    ):
        session = session_of(request)
        session.cancel.clear()
        job = session.new_job("fit")
        try:
            target = target_source(source, upload, drawing, example, job / "input")
            frame = resolve_target(target, 256, 256)
        except (ValueError, HandshadowError) as exc:
            raise gr.Error(str(exc)) from None
        updates: queue.Queue = queue.Queue()
        outcome: dict = {}

        def on_progress(p):
            updates.put(p)

        def work():
            try:
                config = FitConfig(hands=hands, quality=quality, limits=limits, light=light, device=_device())
                outcome["result"] = fit_to_folder(
                    target,
                    job / "result",
                    config,
                    show_progress=False,
                    progress_hook=on_progress,
                    stop=session.cancel.is_set,  # Cancel: the best result so far, as Ctrl-C
                )
            except Exception as exc:  # shown in the page
                outcome["error"] = exc

        thread = threading.Thread(target=work, daemon=True)
        thread.start()
        progress(0, desc="starting")
        last_preview = None
        while thread.is_alive() or not updates.empty():
            try:
                p = updates.get(timeout=0.25)
            except queue.Empty:
                continue
            progress(min(1.0, p.done / max(p.total, 1)), desc=f"IoU {p.iou:.3f}")
            if last_preview is None or time.perf_counter() - last_preview > 0.7:
                last_preview = time.perf_counter()
                yield _preview(frame, p.shadow), f"Fitting... IoU {p.iou:.3f}", None
        thread.join()
        if "error" in outcome:
            raise gr.Error(str(outcome["error"]).splitlines()[0])
        folder, result, lines = outcome["result"]
        zip_path = shutil.make_archive(str(job / "handshadow-result"), "zip", folder)
        s = result.score
        status = (
            ("Cancelled: best result so far. " if result.interrupted else "")
            + str(s)
            + (" (a success)" if s.success else "")
            + "\n\n"
            + "\n".join(line.strip() for line in lines)
        )
        yield str(folder / "overlay.png"), status, {"folder": str(folder), "zip": zip_path}

    def show_result(done):
        # A separate, non-streaming step: Gradio's 3D viewer does not mount from a generator.
        if not done:
            return [gr.skip()] * 6
        folder = Path(done["folder"])
        return (
            str(folder / "shadow.png"),
            str(folder / "hands.glb"),
            str(folder / "guide.png"),
            str(folder / "pose.json"),
            done["zip"],
            str(folder / "progress.gif"),
        )

    def cancel(request: gr.Request):
        session_of(request).cancel.set()
        return "Cancelling: keeping the best result so far..."

    def run_morph(
        source_a,
        upload_a,
        example_a,
        source_b,
        upload_b,
        example_b,
        frames,
        hands,
        request: gr.Request,
        progress=gr.Progress(),  # noqa: B008
    ):
        session = session_of(request)
        job = session.new_job("morph")
        try:
            a = target_source(source_a, upload_a, None, example_a, job / "a")
            b = target_source(source_b, upload_b, None, example_b, job / "b")
            for t in (a, b):
                resolve_target(t, 64, 64)
        except (ValueError, HandshadowError) as exc:
            raise gr.Error(str(exc)) from None
        progress(0.05, desc="fitting both ends and the path (a few minutes)")
        config = FitConfig(hands=hands, quality="fast", device=_device())
        try:
            folder, report = interpolate_to_folder(
                a, b, job / "result", config, frames=int(frames), show_progress=False
            )
        except HandshadowError as exc:
            raise gr.Error(str(exc)) from None
        zip_path = shutil.make_archive(str(job / "handshadow-morph"), "zip", folder)
        return (
            str(folder / "animation.mp4"),
            str(folder / "animation.gif"),
            str(folder / "path.png"),
            report.summary(),
            zip_path,
        )

    with gr.Blocks(title="handshadow", analytics_enabled=False) as demo:
        gr.Markdown(
            "# handshadow\n"
            "Make a shadow with your hands. **1.** Choose a shape: an example, your own picture, or a drawing. "
            "**2.** Press **Fit** and watch the hands find it. **3.** Turn the 3D hands around, read how to hold "
            "them, and try it with a lamp and a wall."
        )
        with gr.Tab("Shadow"):
            with gr.Row():
                with gr.Column(scale=2, min_width=320):
                    source = gr.Radio(["Example", "Upload", "Draw"], value="Example", label="Shape", elem_id="source")
                    example = gr.Dropdown(
                        example_names,
                        value=example_names[0] if example_names else None,
                        label="Example",
                        elem_id="example",
                    )
                    upload = gr.Image(
                        label="Your picture: a dark shape on a light ground, or light on dark",
                        type="numpy",
                        image_mode="RGBA",
                        sources=["upload", "clipboard"],
                        visible=False,
                        elem_id="upload",
                    )
                    drawing = gr.Sketchpad(
                        label="Draw a filled shape (pick the brush first)",
                        type="numpy",
                        image_mode="RGBA",
                        brush=gr.Brush(default_size=28, colors=["#000000"], color_mode="fixed"),
                        canvas_size=(512, 512),
                        visible=False,
                        elem_id="sketchpad",
                    )
                    with gr.Accordion("Options", open=False):
                        hands = gr.Radio(["1", "2", "auto"], value="auto", label="Hands")
                        quality = gr.Radio(
                            ["fast", "default", "best"], value="fast", label="Quality", info=QUALITY_HELP
                        )
                        limits = gr.Radio(
                            ["anatomical", "paper"],
                            value="anatomical",
                            label="Joint limits",
                            info="anatomical: real ranges of motion; paper: Table 1 of the 2023 paper",
                        )
                        light = gr.Radio(
                            ["point", "directional"],
                            value="point",
                            label="Light",
                            info="point: a lamp 2 m from the wall; directional: sunlight",
                        )
                    with gr.Row():
                        fit_button = gr.Button("Fit", variant="primary", elem_id="fit")
                        cancel_button = gr.Button("Cancel", elem_id="cancel")
                    status = gr.Markdown("Pick a shape and press **Fit**.", elem_id="status")
                    guide = gr.Image(label="How to hold your hands", type="filepath", elem_id="guide")
                with gr.Column(scale=3, min_width=420):
                    with gr.Row():
                        preview = gr.Image(
                            label="Shadow over target: grey both, red extra, blue missing",
                            type="filepath",
                            elem_id="preview",
                            height=300,
                        )
                        shadow = gr.Image(label="The shadow", type="filepath", elem_id="shadow", height=300)
                    model = gr.Model3D(
                        label="3D: drag to turn. Hands, lamp (yellow) and wall",
                        clear_color=(0.93, 0.94, 0.96, 1.0),
                        elem_id="model3d",
                        height=440,
                    )
                    with gr.Row():
                        pose_file = gr.File(label="pose.json", elem_id="pose")
                        zip_file = gr.File(label="Everything (zip)", elem_id="zip")
                    with gr.Accordion("The search, step by step", open=False):
                        progress_gif = gr.Image(label="progress.gif", type="filepath", elem_id="progress")

            def show_source(choice):
                return (
                    gr.update(visible=choice == "Example"),
                    gr.update(visible=choice == "Upload"),
                    gr.update(visible=choice == "Draw"),
                )

            source.change(show_source, inputs=source, outputs=[example, upload, drawing], queue=False)
            finished = gr.State(None)
            fit_button.click(
                run_fit,
                inputs=[source, upload, drawing, example, hands, limits, quality, light],
                outputs=[preview, status, finished],
                concurrency_limit=1,
            ).then(show_result, inputs=finished, outputs=[shadow, model, guide, pose_file, zip_file, progress_gif])
            cancel_button.click(cancel, outputs=[status], queue=False)
        with gr.Tab("Morph"):
            gr.Markdown("Two shadows in, a performance out: the poses that turn the first shadow into the second.")
            with gr.Row():
                with gr.Column():
                    source_a = gr.Radio(["Example", "Upload"], value="Example", label="First shadow")
                    example_a = gr.Dropdown(
                        example_names, value=example_names[0] if example_names else None, label="Example"
                    )
                    upload_a = gr.Image(label="Upload", type="numpy", image_mode="RGBA", sources=["upload"])
                with gr.Column():
                    source_b = gr.Radio(["Example", "Upload"], value="Example", label="Last shadow")
                    example_b = gr.Dropdown(
                        example_names, value=example_names[1] if len(example_names) > 1 else None, label="Example"
                    )
                    upload_b = gr.Image(label="Upload", type="numpy", image_mode="RGBA", sources=["upload"])
            with gr.Row():
                frames = gr.Slider(8, 60, value=30, step=1, label="Frames")
                morph_hands = gr.Radio(["1", "2"], value="2", label="Hands")
                morph_button = gr.Button("Morph", variant="primary", elem_id="morph")
            with gr.Row():
                video = gr.Video(label="Animation", elem_id="video")
                gif = gr.Image(label="Animation (GIF)", type="filepath")
            path_plot = gr.Image(label="Path", type="filepath")
            summary = gr.Textbox(label="Summary")
            morph_zip = gr.File(label="Everything (zip)")
            morph_button.click(
                run_morph,
                inputs=[source_a, upload_a, example_a, source_b, upload_b, example_b, frames, morph_hands],
                outputs=[video, gif, path_plot, summary, morph_zip],
                concurrency_limit=1,
            )

        def _goodbye(request: gr.Request):
            store.drop(getattr(request, "session_hash", None) or "local")

        demo.unload(_goodbye)
    return demo, store


def _device() -> str:
    import torch

    return "cuda" if torch.cuda.is_available() else "cpu"


def _preview(target: np.ndarray, shadow: np.ndarray) -> np.ndarray:
    from skimage.transform import resize

    from handshadow.export.images import overlay_image

    small_target = resize(target.astype(float), shadow.shape, order=0) > 0.5
    ov = overlay_image(small_target, shadow > 0.5)
    return (resize(ov.astype(float) / 255, (256, 256 * ov.shape[1] // ov.shape[0]), order=0) * 255).astype(np.uint8)


def launch(host: str = "127.0.0.1", port: int | None = None, block: bool = True):
    """Start the app; returns (demo, url) when not blocking."""
    store = SessionStore()
    os.environ["GRADIO_TEMP_DIR"] = str(store.root / "gradio")  # Gradio's own cache, deleted with ours
    import gradio as gr

    demo, _ = build_app(store)
    demo.queue(default_concurrency_limit=1)
    _, url, _ = demo.launch(
        server_name=host,
        server_port=port,
        prevent_thread_lock=not block,
        max_file_size=MAX_UPLOAD,
        share=False,
        ssr_mode=False,
        footer_links=[],
        quiet=not block,
        theme=gr.themes.Default(),
        allowed_paths=[str(store.root)],
    )
    return demo, url
