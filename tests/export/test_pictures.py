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


def test_the_guides_inset_never_covers_the_hands():
    # A hand reaching into the view's top right corner: the inset (the shadow over the target)
    # and its label go beside the view instead, which is left whole. Before, the inset sat
    # over the corner and hid part of a forearm.
    from handshadow.guide import guide_image

    view = np.full((300, 300, 3), 255, np.uint8)
    view[20:60, 250:290] = 120  # a fingertip in the corner
    overlay = np.full((64, 64, 3), 200, np.uint8)
    picture = guide_image(view, overlay, ["Left hand: fingers up."])
    assert picture.shape[1] == 300 + 300 // 3 + 12  # a column beside the view
    assert (picture[20:300, :300] == view[20:]).all()  # the view as it was (below its title), fingertip and all
    column = picture[:300, 300:]
    assert (column == 200).all(axis=2).sum() >= 0.9 * (300 // 3) ** 2  # the inset is there
    label = column[300 // 3 + 8 : 300 // 3 + 24]
    assert (label < 150).all(axis=2).any()  # and its label under it

    # With the corner empty the inset sits in it, and the picture keeps the view's width.
    view[20:60, 250:290] = 255
    view[150:290, 100:200] = 120  # the hands lower down
    picture = guide_image(view, overlay, ["Left hand: fingers up."])
    assert picture.shape[1] == 300
    assert (picture[10 : 300 // 3, 300 - 300 // 3 : 294] == 200).all(axis=2).mean() > 0.9
    assert (picture[150:290, 100:200] == 120).all()


def test_the_inset_label_stays_whole_on_a_small_view():
    # A 200-pixel view makes a 66-pixel inset, narrower than its label: the label moves left
    # to stay inside the picture instead of running off its edge.
    from handshadow.guide import guide_image

    view = np.full((200, 200, 3), 255, np.uint8)
    picture = guide_image(view, np.full((64, 64, 3), 200, np.uint8), ["Left hand: fingers up."])
    assert picture.shape[1] == 200
    rows = picture[200 // 3 + 8 : 200 // 3 + 24, :200]
    assert (rows[:, -4:] == 255).all()  # the letters end before the edge
    assert (rows < 100).all(axis=2).any()
