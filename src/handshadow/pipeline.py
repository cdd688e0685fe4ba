"""The whole path in a page: target -> scene -> hands -> render -> loss -> search -> export.

    fit_to_folder          an image (or example name) -> a fitted result folder
    render_to_folder       a pose file -> its shadow, meshes and pictures
    interpolate_to_folder  two images -> a morph: frames, animation, poses.json

The CLI and the app call these; each writes its folder completely or not at all.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from handshadow import examples
from handshadow.errors import HandshadowError
from handshadow.export.files import ResultFolder, require_mp4, shadow_image, write_gif, write_json, write_mp4, write_png
from handshadow.export.images import mask_image, overlay_image, overlay_preview
from handshadow.export.meshes import write_glb, write_obj
from handshadow.export.pictures import performer_framing, performer_view, plan_picture, scene_picture
from handshadow.export.plots import path_plot
from handshadow.fit import FitConfig, FitResult, fit_frame, search_budget
from handshadow.guide import (
    describe,
    guide_image,
    guide_views_image,
    holding_line,
    lamp_lines,
    shortfall_line,
    view_lines,
)
from handshadow.hands import load_hand
from handshadow.hands.limits import beyond_limits
from handshadow.hands.posed import PosedMesh, arm_check, cast_shadows, hand_models, pose_penetration
from handshadow.hands.rig import hand_length_m
from handshadow.interpolate import PathReport, morph_targets, refine_path, report, straight_path
from handshadow.poses import PoseBatch, PosedScene
from handshadow.scene import FRAME_HEIGHT_M, Scene, frame_height_for, views_to_json
from handshadow.search import Interrupted, Progress
from handshadow.target import load_target


def mesh_names(meshes: list[PosedMesh]) -> list[str]:
    return [f"{m.side}.obj" for m in meshes]


def view_name(stem: str, view: int, n_views: int) -> str:
    """A per-view file's name: 'shadow.png' with one view, 'shadow_K.png' with several."""
    return f"{stem}.png" if n_views == 1 else f"{stem}_{view}.png"


def write_scene_files(
    folder: ResultFolder, scenes: list[Scene], meshes: list[PosedMesh], masks: list[np.ndarray]
) -> None:
    """shadow.png (shadow_K.png per view with several), scene.json (a list of views with
    several), <side>.obj, hands.glb and scene.png into the folder; masks (H, W) in [0, 1]
    per view."""
    shadows = [shadow_image(m) for m in masks]
    for k, shadow in enumerate(shadows):
        write_png(folder / view_name("shadow", k, len(scenes)), shadow)
    write_json(folder / "scene.json", views_to_json(scenes, meshes=mesh_names(meshes)))
    for m in meshes:
        write_obj(folder / f"{m.side}.obj", m.vertices, m.faces, f"{m.side}_hand")
    hands = [(m.side, m.vertices, m.faces) for m in meshes]
    write_glb(folder / "hands.glb", scenes[0], hands, shadows[0], list(zip(scenes[1:], shadows[1:])))
    tips = np.concatenate([m.keypoints[[4, 12]] for m in meshes])  # thumb and middle tips
    picture = scene_picture(scenes[0], hands, masks[0], rays_through=tips, more_views=list(zip(scenes[1:], masks[1:])))
    write_png(folder / "scene.png", picture)


def resolve_target(source: str, width: int, height: int, invert: bool | None = None) -> np.ndarray:
    """A target frame from an image file or the name of a built-in example."""
    return load_target(examples.target_path(source), width, height, invert)


class FrameRecorder:
    """Keeps snapshots of the searches (search.Progress) for progress.gif: about ``limit``
    over ``total_steps``, counted over all of an attempt's searches (``--hands auto`` runs
    one per hand count, each counting its steps from 0). ``done`` is that count over every
    attempt so far, ``attempt`` the current attempt (fit.fit_frame starts afresh while a
    result fails the success test), ``in_attempt`` the count within it (an attempt that gives
    up early, fit.GIVE_UP, ends short of its total) and ``finished`` says whether its last
    search has taken its last step. The hops' stages (Progress.hop) are not counted or kept: they come after
    the searches, and their result is the GIF's last frame."""

    def __init__(self, total_steps: int, searches: int = 1, limit: int = 36):
        self.every = max(1, total_steps // limit)
        self.searches = searches
        self.frames: list[Progress] = []
        self.done = 0
        self.in_attempt = 0
        self.attempt = 0
        self.finished = False
        self._next = 0
        self._offset = 0
        self._last = 0
        self._search = 0
        self._attempt_start = 0

    def __call__(self, p: Progress) -> None:
        if p.hop:
            return
        fresh = p.attempt != self.attempt
        if fresh:  # a fresh attempt: its searches count from the first
            self.attempt, self._search = p.attempt, -1
        if p.done < self._last or self._search < 0:  # the next search began
            self._offset += self._last
            self._search += 1
        if fresh:
            self._attempt_start = self._offset
        self._last = p.done
        self.done = self._offset + p.done
        self.in_attempt = self.done - self._attempt_start
        self.finished = p.done >= p.total and self._search + 1 >= self.searches
        if self.done >= self._next or p.done == p.total:
            self.frames.append(p)
            self._next = self.done + self.every


def progress_frames(
    frames: list[Progress],
    targets: np.ndarray | list[np.ndarray],
    posed: PosedScene,
    size: int = 220,
    mano_dir: str | None = None,
) -> list[np.ndarray]:
    """One picture per snapshot: the hands in 3D (from the performer's side) beside their
    shadow over the target, one per view (targets: (H, W) bool, or one per view); mano_dir:
    where the MANO files are, for a MANO result."""
    targets = [targets] if isinstance(targets, np.ndarray) else list(targets)
    attempt = posed.fit.get("attempt", 1) - 1  # the attempt that gave the result, not the others
    frames = [f for f in frames if f.poses.n_hands == len(posed.hands) and f.attempt == attempt]
    models = [load_hand(h.model, h.side, h.shape, mano_dir, forearm=posed.forearm) for h in posed.hands]
    with torch.no_grad():  # the snapshots' poses live on the fit's device, these models on the CPU
        vertices = [
            [m(*h.to("cpu").args()).vertices[0].double().numpy() for m, h in zip(models, f.poses.hands)] for f in frames
        ]
    framing = performer_framing([v for vs in vertices for v in vs], posed.scene) if frames else None
    faces = [m.faces.cpu().numpy() for m in models]
    out = []
    for f, vs in zip(frames, vertices):
        meshes = [(h.side, v, fs) for h, fs, v in zip(posed.hands, faces, vs)]
        view = performer_view(posed.scene, meshes, size=(size, size), supersample=1, framing=framing)
        overlays = [overlay_preview(t, m, size) for t, m in zip(targets, (f.shadow, *f.more_shadows))]
        frame = np.concatenate([view, *overlays], 1)
        frame[-14:, :] = 255
        bar = int(frame.shape[1] * f.done / max(f.total, 1))
        frame[-10:-4, :bar] = (70, 130, 200)
        out.append(frame)
    return out


def fit_to_folder(
    target_source: str | Sequence[str],
    out: str | Path,
    config: FitConfig,
    force: bool = False,
    invert: bool | None = None,
    show_progress: bool = True,
    progress_hook=None,
    stop=None,
) -> tuple[Path, FitResult, list[str]]:
    """Fit hands to a target and write the result folder: target.png, shadow.png, overlay.png,
    scene.json, pose.json, <side>.obj, hands.glb, scene.png, progress.gif, guide.png.

    Several targets (a sequence of sources, one per view, FitConfig.view_angle_deg between
    them) fit one pose to all: target_K.png, shadow_K.png and overlay_K.png per view K, and
    scene.json a list of views; hands.glb and scene.png show every lamp and wall with its
    shadow, guide.png where to put each lamp and which target parts each shadow misses.

    ``progress_hook`` is called with each search.Progress. Ctrl-C, or ``stop`` (a callable
    checked at every step) returning True, ends the fit early and writes the best result so
    far, completely.
    Returns (folder, FitResult, instruction lines)."""
    ResultFolder(out, force)  # refuse an unusable output folder before the work
    sources = [target_source] if isinstance(target_source, str) else list(target_source)
    frames = [resolve_target(source, config.size, config.size, invert) for source in sources]
    # The budget sizes the views (fit.view_scenes): bad view options fail here, before the work.
    total, searches = search_budget(frames[0] if len(frames) == 1 else frames, config)
    recorder = FrameRecorder(total, searches)
    bar = tqdm(total=total, desc="fitting", unit="step", leave=False) if show_progress and sys.stderr.isatty() else None

    def on_progress(p: Progress) -> None:
        recorder(p)
        if progress_hook is not None:
            progress_hook(p)
        if bar is not None:
            bar.total = total * (p.attempt + 1)  # a fresh attempt runs the searches again
            bar.n = min(bar.total, total * p.attempt + recorder.in_attempt)
            bar.set_postfix(iou=f"{p.iou:.3f}")
            # After the last search's last step come the separation, the polish and the export.
            again = f" (attempt {p.attempt + 1})" if p.attempt else ""
            doing = "finishing" if recorder.finished else "fitting"
            bar.set_description((f"hop {p.hop} of {p.hops}" if p.hop else doing) + again)

    result = fit_frame(frames[0] if len(frames) == 1 else frames, config, progress=on_progress, stop=stop)
    if bar is not None:
        bar.close()
    done = recorder.frames[-1].done if recorder.frames else 0
    last = Progress(
        stage=-1,
        step=0,
        done=done,
        total=max(done, 1),
        shadow=result.shadow.astype(np.float32),
        iou=result.score.iou,
        poses=result.poses,
        more_shadows=tuple(v.shadow.astype(np.float32) for v in result.views[1:]),
        attempt=result.posed.fit.get("attempt", 1) - 1,
    )
    recorder.frames.append(last)
    pictures = progress_frames(recorder.frames, frames, result.posed, mano_dir=config.mano_dir)
    lines, guide = _guide(result)
    with ResultFolder(out, force) as folder:
        for k, view in enumerate(result.views):
            write_png(folder / view_name("target", k, len(frames)), mask_image(view.target))
            write_png(folder / view_name("overlay", k, len(frames)), overlay_image(view.target, view.shadow))
        masks = [v.shadow.astype(float) for v in result.views]
        write_scene_files(folder, result.posed.views, result.meshes, masks)
        write_json(folder / "pose.json", result.posed.to_json())
        write_gif(folder / "progress.gif", pictures)
        write_png(folder / "guide.png", guide)
        path = folder.commit()
    return path, result, lines


def _guide(result: FitResult) -> tuple[list[str], np.ndarray]:
    """The instruction lines and guide.png of a fit: how to hold the hands, after a word on
    what the shadow misses when it falls short of the success test (guide.shortfall_line);
    with several views also where each lamp goes and how each shadow came out, and a plan of
    the room."""
    posed = result.posed
    length = hand_length_m(result.problem.models[0].rig)
    lines = describe(list(posed.hands), posed.scene, length, len(result.views))
    hands = [(m.side, m.vertices, m.faces) for m in result.meshes]
    view = performer_view(posed.scene, hands, size=(560, 560))
    overlays = [overlay_image(v.target, v.shadow) for v in result.views]
    if len(result.views) == 1:
        v = result.views[0]
        short = shortfall_line(v.score, v.missing, v.extra)
        lines = lines if short is None else [short, *lines]
        return lines, guide_image(view, overlays[0], lines)
    vertices = np.concatenate([m.vertices for m in result.meshes])
    lines = lines + lamp_lines(posed.views, vertices.mean(0)) + result_lines(result)
    return lines, guide_views_image(view, plan_picture(posed.views, vertices), overlays, lines)


def result_lines(result: FitResult) -> list[str]:
    """Per view how its shadow came out, which target parts it misses, and the trade-off."""
    views = result.views
    return view_lines([v.score for v in views], [(v.missing, v.extra) for v in views], [v.weight for v in views])


def render_to_folder(
    posed: PosedScene, out: str | Path, force: bool = False, mano_dir: str | None = None
) -> tuple[Path, str, list[str]]:
    """Render a pose file into ``out``: shadow.png (shadow_K.png per view when the file has
    several), scene.json, pose.json, <side>.obj, hands.glb, scene.png, and with one view guide.png (the
    hands as the performer sees them, the shadow, how to hold the hands). Returns the folder,
    whether a person can hold the pose in a line (guide.holding_line) and how to hold the
    hands (guide.describe)."""
    meshes, masks = cast_shadows(posed, mano_dir)
    models = hand_models(posed, mano_dir)
    pen = pose_penetration(posed, meshes, models=models)
    beyond = [beyond_limits(h.pose_deg, h.wrist_deg if posed.forearm else None, h.side) for h in posed.hands]
    sides = [h.side for h in posed.hands]
    holding = holding_line(sides, pen.between_mm, arm_check(posed, models=models), pen.within_mm, beyond)
    lines = describe(list(posed.hands), posed.scene, hand_length_m(models[0].rig), len(posed.views))
    with ResultFolder(out, force) as folder:
        write_scene_files(folder, posed.views, meshes, masks)
        write_json(folder / "pose.json", posed.to_json())
        if len(posed.views) == 1:
            view = performer_view(posed.scene, [(m.side, m.vertices, m.faces) for m in meshes], size=(560, 560))
            shadow = np.repeat(shadow_image(masks[0])[..., None], 3, axis=2)
            write_png(folder / "guide.png", guide_image(view, shadow, [holding, *lines], label="shadow"))
        return folder.commit(), holding, lines


def interpolate_to_folder(
    source_a: str,
    source_b: str,
    out: str | Path,
    config: FitConfig,
    frames: int = 30,
    force: bool = False,
    show_progress: bool = True,
    path_steps: int = 200,
) -> tuple[Path, PathReport]:
    """Morph target A into target B: fit both ends (B close to A), blend and refine the path,
    and write frames/, animation.gif, animation.mp4, poses.json, path.png, target_a.png,
    target_b.png. Returns (folder, PathReport).

    config.time_limit_s bounds each end's fit and the path's refinement, each on its own
    (report.time_limited says which it ended). Ctrl-C while fitting an end stops the whole
    morph (KeyboardInterrupt, nothing written); Ctrl-C while refining the path writes the path
    as refined so far (report.interrupted)."""
    ResultFolder(out, force)
    require_mp4()
    if frames < 2 or frames > 600:
        raise HandshadowError(f"--frames must be between 2 and 600, got {frames}")
    target_a = resolve_target(source_a, config.size, config.size)
    target_b = resolve_target(source_b, config.size, config.size)
    if config.frame_height_m is None:  # one frame on the wall for both ends, sized to the larger shape
        shared = frame_height_for([target_a, target_b], config.light) or FRAME_HEIGHT_M[config.light]
        config = dataclasses.replace(config, frame_height_m=shared)
    say = (lambda msg: print(msg, file=sys.stderr, flush=True)) if show_progress else (lambda msg: None)
    say("fitting A ...")
    fit_a = fit_frame(target_a, config)
    if fit_a.interrupted:  # Ctrl-C in a fit: a morph needs both ends, so nothing is written
        raise KeyboardInterrupt
    say(f"fitting A: {_judged(fit_a)}; fitting B close to A ...")
    fit_b = fit_frame(target_b, config, extra_starts=fit_a.poses, anchor=fit_a.poses)
    if fit_b.interrupted:
        raise KeyboardInterrupt
    say(f"fitting B: {_judged(fit_b)}; refining the path (Ctrl-C keeps the path so far) ...")
    problem = fit_a.problem
    path = straight_path(fit_a.poses, fit_b.poses, frames)
    interrupted = path_limited = False
    try:
        path, path_limited = refine_path(
            problem, path, morph_targets(target_a, target_b, frames), steps=path_steps, time_limit_s=config.time_limit_s
        )
    except Interrupted as halt:
        path, interrupted = halt.poses, True
    rep, shadows = report(problem, path, target_a, target_b, interrupted)
    ends_limited = (fit_a.posed.fit["time_limited"], fit_b.posed.fit["time_limited"])
    rep = dataclasses.replace(rep, time_limited=(*ends_limited, path_limited))
    poses_json = path_pose_file(path, fit_a.posed, rep)
    views = performance_views(problem, path, fit_a.posed, config.size)
    pictures = [np.concatenate([np.repeat(mask_image(m)[..., None], 3, axis=2), v], 1) for m, v in zip(shadows, views)]
    with ResultFolder(out, force) as folder:
        (folder / "frames").mkdir()
        for k in range(frames):
            write_png(folder / "frames" / f"frame_{k:03d}_shadow.png", mask_image(shadows[k]))
            write_png(folder / "frames" / f"frame_{k:03d}_hands.png", views[k])
        write_png(folder / "target_a.png", mask_image(target_a))
        write_png(folder / "target_b.png", mask_image(target_b))
        write_gif(folder / "animation.gif", pictures, seconds_per_frame=1 / 12, hold_last_s=0.8)
        write_mp4(folder / "animation.mp4", pictures, fps=12)
        write_json(folder / "poses.json", poses_json)
        write_png(folder / "path.png", path_plot(rep))
        result = folder.commit()
    return result, rep


def performance_views(problem, path: PoseBatch, template: PosedScene, size: int) -> list[np.ndarray]:
    """The hands of every frame of a path as the performer sees them, (size, size, 3) uint8
    each, with one camera for the whole performance."""
    with torch.no_grad():
        vertices = [o.vertices.cpu().double().numpy() for o in problem.pose(path.hands)]
    faces = [m.faces.cpu().numpy() for m in problem.models]
    framing = performer_framing(vertices, template.scene)
    return [
        performer_view(
            template.scene,
            [(h.side, v[k], f) for h, f, v in zip(template.hands, faces, vertices)],
            size=(size, size),
            supersample=1,
            framing=framing,
        )
        for k in range(path.batch)
    ]


def _judged(fit: FitResult) -> str:
    """A fit's measures in words, whether it passes the success test, and whether the time
    limit ended it."""
    s = fit.score
    verdict = "a success" if s.success else "short of the success test"
    return f"{s} ({verdict}{'; the time limit ended it' if fit.posed.fit['time_limited'] else ''})"


def path_pose_file(path: PoseBatch, template: PosedScene, rep: PathReport) -> dict:
    """poses.json: the scene once and every frame's hands, readable by ``render --frame K``."""
    per_hand = [
        batch.to_hand_poses(h.side, h.model, h.shape) for batch, h in zip(path.hands, template.hands)
    ]  # [hand][frame]
    frames = [
        {
            "hands": [hands[k].to_json() for hands in per_hand],
            "iou_a": round(rep.iou_a[k], 4),
            "iou_b": round(rep.iou_b[k], 4),
        }
        for k in range(path.batch)
    ]
    return {
        "format": "handshadow.poses/1",
        "scene": template.scene.to_json(),
        "forearm": template.forearm,
        "frames": frames,
        "summary": rep.summary(),
        "interrupted": rep.interrupted,
    }
