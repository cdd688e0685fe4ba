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


def test_the_guide_writes_the_inset_label_on_white_over_a_hand_under_it():
    # A performer's view dark all over (a hand reaching under the inset): the label under the
    # inset is still drawn on white, so it reads. Before, its letters ran through the hand.
    from handshadow.guide import guide_image

    view = np.full((300, 300, 3), 120, np.uint8)
    overlay = np.full((64, 64, 3), 200, np.uint8)
    picture = guide_image(view, overlay, ["Left hand: fingers up."])
    inset_w = 300 // 3
    band = picture[inset_w + 10 : inset_w + 20, 300 - inset_w - 6 : 300 - 6]
    assert (band == 255).all(axis=2).mean() > 0.25  # white around the letters (before: none)
    assert (band < 150).all(axis=2).any()  # and the letters are there
    below = picture[inset_w + 40 : inset_w + 60, 300 - inset_w - 6 : 300 - 6]
    assert (below == 120).all()  # the view itself is left as it is below the label


def test_the_inset_label_stays_whole_on_a_small_view():
    # A 200-pixel view makes a 66-pixel inset, narrower than its label: the label moves left
    # to stay inside the picture instead of running off its edge.
    from handshadow.guide import guide_image

    view = np.full((200, 200, 3), 120, np.uint8)
    picture = guide_image(view, np.full((64, 64, 3), 200, np.uint8), ["Left hand: fingers up."])
    rows = picture[200 // 3 + 8 : 200 // 3 + 24, :200]
    assert (rows[:, -4:] == 120).all()  # the band and its letters end before the edge
    assert (rows == 255).all(axis=2).mean(axis=0).max() > 0.5 and (rows < 100).all(axis=2).any()
