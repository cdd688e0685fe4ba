"""Our shadow against an independent ray tracer: Mitsuba 3 (scalar_rgb) tracing shadow rays
from the wall toward the light through the exported OBJ meshes."""

import numpy as np
import pytest
import torch

from handshadow.export.meshes import round_vertices, write_obj
from handshadow.hands.posed import PosedMesh, mesh_shadow
from handshadow.metrics import iou
from handshadow.scene import Scene
from tests.conftest import random_pose, random_rotation

mi = pytest.importorskip("mitsuba")
SUBSAMPLES = [(0.5, 0.5), (0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)]  # centre first


def raytraced_shadow(scene: Scene, obj_paths) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel: (centre sample in shadow, share of 5 samples in shadow)."""
    mi.set_variant("scalar_rgb")
    shapes = {"type": "scene"}
    for i, path in enumerate(obj_paths):
        shapes[f"m{i}"] = {"type": "obj", "filename": str(path)}
    rt = mi.load_dict(shapes)
    im = scene.image
    o, u, v = (np.asarray(a, float) for a in (im.origin, im.u, im.v))
    hits = np.zeros((len(SUBSAMPLES), im.height, im.width), bool)
    for s, (dx, dy) in enumerate(SUBSAMPLES):
        for i in range(im.height):
            for j in range(im.width):
                p = o + (j + dx) / im.width * u + (i + dy) / im.height * v
                if scene.light.type == "point":
                    d = np.asarray(scene.light.position) - p
                    dist = float(np.linalg.norm(d))
                    d = d / dist
                else:
                    d = -np.asarray(scene.light.direction)
                    dist = 100.0
                ray = mi.Ray3f(mi.Point3f(*p), mi.Vector3f(*d))
                ray.maxt = dist * (1 - 1e-6)
                hits[s, i, j] = bool(rt.ray_test(ray))
    return hits[0], hits.mean(0)


@pytest.mark.parametrize("case", range(4))
def test_shadow_equals_ray_traced_shadow(tmp_path, hands64, case):
    rng = np.random.default_rng(100 + case)
    light = "directional" if case == 3 else "point"
    scene = Scene.default(96, 80, light=light)
    meshes = []
    for side, x in (("right", 0.07), ("left", -0.07)):
        depth = rng.uniform(0.7, 1.3) if light == "point" else rng.uniform(0.3, 0.8)
        out = hands64[side](
            random_pose(rng), random_rotation(rng, 50), torch.tensor([[x, -0.1, depth]], dtype=torch.float64)
        )
        meshes.append(
            PosedMesh(side, round_vertices(out.vertices[0].numpy()), out.faces.numpy(), out.keypoints[0].numpy())
        )
    paths = []
    for m in meshes:
        paths.append(tmp_path / f"{m.side}.obj")
        write_obj(paths[-1], m.vertices, m.faces, m.side)
    ours = mesh_shadow(scene, meshes) > 0.5
    centre, share = raytraced_shadow(scene, paths)
    print(
        f"case {case}: IoU centre {iou(ours, centre):.4f}, 5-sample {iou(ours, share >= 0.5):.4f}, shadow px {ours.sum()}"
    )
    assert ours.sum() > 200  # the hands do cast a shadow into the frame
    assert iou(ours, centre) >= 0.99
    assert iou(ours, share >= 0.5) >= 0.97  # a few samples per pixel: only edge pixels differ
