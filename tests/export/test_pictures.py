import numpy as np
import trimesh

from handshadow.export.pictures import performer_framing, performer_view
from handshadow.scene import Scene


def _box(centre, extents) -> tuple[np.ndarray, np.ndarray]:
    box = trimesh.creation.box(extents=extents)
    return np.asarray(box.vertices) + np.asarray(centre), np.asarray(box.faces)


def test_the_performer_view_shows_all_of_a_forearm_that_reaches_toward_the_lamp():
    # A fist 1 m from the wall and a forearm from it 0.4 m toward the lamp (the wall's normal
    # is +z), tilted down: before the framing projected every vertex, the forearm's near end
    # filled the view and cut the hands off at its edges.
    scene = Scene.default(lamp_to_wall_m=4.0)
    fist = _box((0.0, 1.0, 1.0), (0.09, 0.1, 0.08))
    arm_v, arm_f = _box((0.0, 0.92, 1.22), (0.07, 0.07, 0.4))
    arm_v = arm_v + np.c_[np.zeros((len(arm_v), 1)), -0.4 * (arm_v[:, 2:] - 1.0), np.zeros((len(arm_v), 1))]
    hands = [("left", *fist), ("right", arm_v, arm_f)]
    picture = performer_view(scene, hands, size=(96, 96), supersample=1)
    drawn = np.any(picture < 250, axis=2)
    border = np.concatenate([drawn[0], drawn[-1], drawn[:, 0], drawn[:, -1]])
    assert not border.any()  # nothing cut off at the picture's edges
    assert drawn.mean() > 0.03  # and not a speck: the camera comes no farther than it must
    centre, distance = performer_framing([fist[0], arm_v], scene)
    assert distance > 0.4  # beyond the forearm's near end, 0.42 m from the centre along z
