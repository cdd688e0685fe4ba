"""The whole path in a page: target -> scene -> hands -> render -> loss -> search -> export.

``render_pose_set`` turns a pose file into its shadow and pictures; the fit and the morph build
on the same pieces.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import torch

from handshadow.errors import HandshadowError
from handshadow.export.files import ResultFolder, shadow_image, write_json, write_png
from handshadow.export.meshes import round_vertices, write_glb, write_obj
from handshadow.export.pictures import scene_picture
from handshadow.hands import load_hand
from handshadow.metrics import score
from handshadow.posefile import PoseSet
from handshadow.render import MeshTopology, shadow_mask
from handshadow.scene import Scene


class PlacementError(HandshadowError):
    """Geometry that does not lie between the light and the wall."""


@dataclasses.dataclass(frozen=True)
class PosedMesh:
    """One posed hand, world frame: vertices (V, 3) float64 metres (rounded as in the OBJ),
    faces (F, 3), keypoints (21, 3)."""

    side: str
    vertices: np.ndarray
    faces: np.ndarray
    keypoints: np.ndarray


def pose_hands(pose_set: PoseSet, mano_dir: str | None = None) -> list[PosedMesh]:
    """Build and pose the hands of a pose file (float64)."""
    out = []
    for h in pose_set.hands:
        model = load_hand(h.model, h.side, h.shape, mano_dir, forearm=pose_set.forearm, dtype=torch.float64)
        with torch.no_grad():
            res = model(*h.tensors(dtype=torch.float64))
        out.append(
            PosedMesh(h.side, round_vertices(res.vertices[0].numpy()), res.faces.numpy(), res.keypoints[0].numpy())
        )
    return out


def check_placement(scene: Scene, meshes: list[PosedMesh]) -> None:
    """Raise PlacementError unless every vertex lies strictly between the light and the wall."""
    lo, hi = scene.light_depth_range()
    n = np.asarray(scene.wall.normal)
    for m in meshes:
        h = (m.vertices - np.asarray(scene.wall.point)) @ n
        if h.min() <= lo:
            raise PlacementError(
                f"the {m.side} hand reaches through the wall ({h.min():.3f} m); move it toward the light"
            )
        if h.max() >= hi:
            raise PlacementError(
                f"the {m.side} hand reaches the light's plane ({h.max():.3f} m from the wall); move it toward the wall"
            )


def exact_shadow(scene: Scene, meshes: list[PosedMesh]) -> np.ndarray:
    """(H, W) float mask of the exact shadow of the meshes (float64 projection)."""
    check_placement(scene, meshes)
    verts = torch.as_tensor(np.concatenate([m.vertices for m in meshes]))[None]
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    faces = torch.as_tensor(np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]))
    xy, _ = scene.project(verts)
    return shadow_mask(xy, MeshTopology.from_faces(faces), scene.image.height, scene.image.width)[0].numpy()


def mesh_names(meshes: list[PosedMesh]) -> list[str]:
    return [f"{m.side}.obj" for m in meshes]


def write_scene_files(folder: ResultFolder, scene: Scene, meshes: list[PosedMesh], mask: np.ndarray) -> None:
    """shadow.png, scene.json, <side>.obj, hands.glb and scene.png into the folder."""
    shadow = shadow_image(mask)
    write_png(folder / "shadow.png", shadow)
    write_json(folder / "scene.json", scene.to_json(meshes=mesh_names(meshes)))
    for m in meshes:
        write_obj(folder / f"{m.side}.obj", m.vertices, m.faces, f"{m.side}_hand")
    hands = [(m.side, m.vertices, m.faces) for m in meshes]
    write_glb(folder / "hands.glb", scene, hands, shadow)
    tips = np.concatenate([m.keypoints[[4, 12]] for m in meshes])  # thumb and middle tips
    write_png(folder / "scene.png", scene_picture(scene, hands, mask, rays_through=tips))


def resolve_target(source: str, width: int, height: int, invert: bool | None = None) -> np.ndarray:
    """A target frame from an image file or the name of a built-in example."""
    from handshadow import examples
    from handshadow.target import load_target

    return load_target(examples.target_path(source), width, height, invert)


class FrameRecorder:
    """Keeps snapshots of the searches (step, IoU, shadow, poses) for progress.gif: about
    ``limit`` over ``total_steps``, counted over all of a fit's searches (``--hands auto`` runs
    one per hand count, each counting its steps from 0). ``done`` is that overall count and
    ``finished`` says whether the last search has taken its last step."""

    def __init__(self, total_steps: int, searches: int = 1, limit: int = 36):
        self.every = max(1, total_steps // limit)
        self.searches = searches
        self.frames: list = []
        self.done = 0
        self.finished = False
        self._next = 0
        self._offset = 0
        self._last = 0
        self._search = 0

    def __call__(self, p) -> None:
        if p.done < self._last:  # the next search began
            self._offset += self._last
            self._search += 1
        self._last = p.done
        self.done = self._offset + p.done
        self.finished = p.done >= p.total and self._search + 1 >= self.searches
        if self.done >= self._next or p.done == p.total:
            self.frames.append(p)
            self._next = self.done + self.every


def progress_frames(
    frames: list, target: np.ndarray, scene: Scene, sides: list[str], pose_set: PoseSet, size: int = 220
) -> list[np.ndarray]:
    """One picture per snapshot: the hands in 3D (from the performer's side) beside their
    shadow over the target."""
    from skimage.transform import resize

    from handshadow.export.images import overlay_image
    from handshadow.export.pictures import performer_framing, performer_view

    frames = [f for f in frames if len(f.poses) == len(pose_set.hands)]  # not the search with the other hand count
    models = [load_hand(h.model, h.side, h.shape, None, forearm=pose_set.forearm) for h in pose_set.hands]
    with torch.no_grad():
        vertices = [
            [m(*p.to("cpu").args()).vertices[0].cpu().double().numpy() for m, p in zip(models, f.poses)] for f in frames
        ]  # the snapshots' poses live on the fit's device, these models on the CPU
    framing = performer_framing([v for vs in vertices for v in vs], scene) if frames else None  # one camera throughout
    out = []
    faces = [m.faces.cpu().numpy() for m in models]
    for f, vs in zip(frames, vertices):
        meshes = [(s, v, fs) for s, fs, v in zip(sides, faces, vs)]
        view = performer_view(scene, meshes, size=(size, size), supersample=1, framing=framing)
        small_target = resize(target.astype(float), f.shadow.shape, order=0) > 0.5
        ov = overlay_image(small_target, f.shadow > 0.5)
        ov = (resize(ov.astype(float) / 255, (size, size * ov.shape[1] // ov.shape[0]), order=0) * 255).astype(np.uint8)
        frame = np.concatenate([view, ov], 1)
        frame[-14:, :] = 255
        bar = int(frame.shape[1] * f.done / max(f.total, 1))
        frame[-10:-4, :bar] = (70, 130, 200)
        out.append(frame)
    return out


def fit_to_folder(
    target_source: str,
    out: str | Path,
    config,
    force: bool = False,
    invert: bool | None = None,
    show_progress: bool = True,
    progress_hook=None,
    stop=None,
):
    """Fit hands to a target and write the result folder: target.png, shadow.png, overlay.png,
    scene.json, pose.json, <side>.obj, hands.glb, scene.png, progress.gif, guide.png.

    ``progress_hook`` is called with each search.Progress. Ctrl-C, or ``stop`` (a callable
    checked at every step) returning True, ends the fit early and writes the best result so
    far, completely.
    Returns (folder, FitResult, instruction lines)."""
    import sys

    from handshadow.export.files import write_gif
    from handshadow.export.images import mask_image, overlay_image
    from handshadow.export.pictures import performer_view
    from handshadow.fit import fit_frame, schedule
    from handshadow.guide import describe, guide_image
    from handshadow.posefile import parse_pose

    ResultFolder(out, force)  # refuse an unusable output folder before the work
    frame = resolve_target(target_source, config.size, config.size, invert)
    _, _, stages = schedule(config.quality, config.iters, config.size)
    searches = 2 if config.hands == "auto" else 1  # fit_frame runs one search per hand count
    total = sum(s.steps for s in stages) * searches
    recorder = FrameRecorder(total, searches)
    bar = None
    if show_progress and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=total, desc="fitting", unit="step", leave=False)

    def on_progress(p):
        recorder(p)
        if progress_hook is not None:
            progress_hook(p)
        if bar is not None:
            bar.n = min(total, recorder.done)
            bar.set_postfix(iou=f"{p.iou:.3f}")
            # After the last search's last step come the separation, the polish and the export.
            bar.set_description("finishing" if recorder.finished else "fitting")

    result = fit_frame(frame, config, progress=on_progress, stop=stop)
    if bar is not None:
        bar.close()
    from handshadow.search import Progress

    done = recorder.frames[-1].done if recorder.frames else 0
    recorder.frames.append(
        Progress(-1, 0, done, max(done, 1), result.shadow.astype(np.float32), result.score.iou, result.poses)
    )
    pose_set = parse_pose(result.pose_set.to_json())  # exactly what pose.json will hold
    meshes = pose_hands(pose_set, config.mano_dir)
    mask = exact_shadow(pose_set.scene, meshes)
    # Report the measures of the shadow that is written (float64, from pose.json's values).
    result.score = score(mask > 0.5, frame)
    pose_set = dataclasses.replace(
        pose_set,
        fit={
            **pose_set.fit,
            **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in result.score.as_dict().items()},
        },
    )
    scene = pose_set.scene
    sides = [h.side for h in pose_set.hands]
    frames = progress_frames(recorder.frames, frame, scene, sides, pose_set)
    lines = describe(list(pose_set.hands), scene)
    hands = [(m.side, m.vertices, m.faces) for m in meshes]
    guide = guide_image(performer_view(scene, hands, size=(560, 560)), overlay_image(frame, mask > 0.5), lines)
    with ResultFolder(out, force) as folder:
        write_png(folder / "target.png", mask_image(frame))
        write_png(folder / "overlay.png", overlay_image(frame, mask > 0.5))
        write_scene_files(folder, scene, meshes, mask)
        write_json(folder / "pose.json", pose_set.to_json())
        write_gif(folder / "progress.gif", frames)
        write_png(folder / "guide.png", guide)
        path = folder.commit()
    return path, result, lines


def render_pose_set(pose_set: PoseSet, out: str | Path, force: bool = False, mano_dir: str | None = None) -> Path:
    """Render a pose file into ``out``: shadow.png, scene.json, <side>.obj, hands.glb, scene.png."""
    meshes = pose_hands(pose_set, mano_dir)
    mask = exact_shadow(pose_set.scene, meshes)
    with ResultFolder(out, force) as folder:
        write_scene_files(folder, pose_set.scene, meshes, mask)
        write_json(folder / "pose.json", pose_set.to_json())
        return folder.commit()


def interpolate_to_folder(
    source_a: str,
    source_b: str,
    out: str | Path,
    config,
    frames: int = 30,
    force: bool = False,
    show_progress: bool = True,
    path_steps: int = 200,
):
    """Morph target A into target B: fit both ends (B close to A), blend and refine the path,
    and write frames/, animation.gif, animation.mp4, poses.json, path.png, target_a.png,
    target_b.png. Returns (folder, PathReport).

    Ctrl-C while fitting an end stops the whole morph (KeyboardInterrupt, nothing written);
    Ctrl-C while refining the path writes the path as refined so far (report.interrupted)."""
    import sys

    from handshadow.export.files import require_mp4, write_gif, write_mp4
    from handshadow.export.images import mask_image
    from handshadow.export.pictures import performer_framing, performer_view
    from handshadow.export.plots import path_plot
    from handshadow.fit import fit_frame
    from handshadow.interpolate import morph_targets, refine_path, report, straight_path
    from handshadow.search import Interrupted

    ResultFolder(out, force)
    require_mp4()
    if frames < 2 or frames > 600:
        raise HandshadowError(f"--frames must be between 2 and 600, got {frames}")
    target_a = resolve_target(source_a, config.size, config.size)
    target_b = resolve_target(source_b, config.size, config.size)
    say = (lambda msg: print(msg, file=sys.stderr, flush=True)) if show_progress else (lambda msg: None)
    say("fitting A ...")
    fit_a = fit_frame(target_a, config)
    if fit_a.interrupted:  # Ctrl-C in a fit: a morph needs both ends, so nothing is written
        raise KeyboardInterrupt
    say(f"fitting A: {_judged(fit_a.score)}; fitting B close to A ...")
    fit_b = fit_frame(target_b, config, extra_starts=fit_a.poses, anchor=fit_a.poses)
    if fit_b.interrupted:
        raise KeyboardInterrupt
    say(f"fitting B: {_judged(fit_b.score)}; refining the path (Ctrl-C keeps the path so far) ...")
    searcher = fit_a.searcher
    path = straight_path(fit_a.poses, fit_b.poses, frames)
    interrupted = False
    try:
        path = refine_path(searcher, path, morph_targets(target_a, target_b, frames), steps=path_steps)
    except Interrupted as halt:
        path, interrupted = halt.poses, True
    rep, shadows = report(searcher, path, target_a, target_b, interrupted)
    scene = fit_a.pose_set.scene
    sides = [h.side for h in fit_a.pose_set.hands]
    poses_json = path_pose_file(path, sides, fit_a.pose_set, rep)
    with torch.no_grad():
        vertices = [hand(*p.args()).vertices.cpu().double().numpy() for hand, p in zip(searcher.hands, path)]
    faces = [hand.faces.cpu().numpy() for hand in searcher.hands]
    framing = performer_framing(vertices, scene)  # one camera for the whole performance
    views, pictures = [], []
    for k in range(frames):
        meshes = [(side, v[k], f) for side, f, v in zip(sides, faces, vertices)]
        view = performer_view(scene, meshes, size=(config.size, config.size), supersample=1, framing=framing)
        shadow_rgb = np.repeat(mask_image(shadows[k])[..., None], 3, axis=2)
        views.append(view)
        pictures.append(np.concatenate([shadow_rgb, view], 1))
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


def _judged(s) -> str:
    """A fit's measures in words, and whether it passes the success test."""
    verdict = "a success" if s.success else "short of the success test"
    return f"{s} ({verdict})"


def path_pose_file(path, sides, template: PoseSet, rep) -> dict:
    """poses.json: the scene once and every frame's hands, readable by ``render --frame K``."""
    from handshadow.posefile import HandPose

    frames = []
    for k in range(path[0].pose_rad.shape[0]):
        hands = []
        for side, p, h0 in zip(sides, path, template.hands):
            q = p.select(slice(k, k + 1))
            hands.append(
                HandPose(
                    side,
                    h0.model,
                    h0.shape,
                    np.degrees(q.pose_rad[0].cpu().double().numpy()),
                    q.rotation[0].cpu().double().numpy(),
                    q.translation[0].cpu().double().numpy(),
                    np.degrees(q.wrist_rad[0].cpu().double().numpy()),
                ).to_json()
            )
        frames.append({"hands": hands, "iou_a": round(rep.iou_a[k], 4), "iou_b": round(rep.iou_b[k], 4)})
    return {
        "format": "handshadow.poses/1",
        "scene": template.scene.to_json(),
        "forearm": template.forearm,
        "frames": frames,
        "summary": rep.summary(),
        "interrupted": rep.interrupted,
    }
