"""The shadow atlas: its descriptor ignores turning, mirroring and scale; an entry's own
shadow finds the entry; starts come from it for one and two hands."""

import numpy as np
import torch

from handshadow.search.atlas import load_atlas, shape_descriptor


def _blob(size=64):
    yy, xx = np.mgrid[:size, :size]
    m = ((yy - 34) ** 2 / 14**2 + (xx - 30) ** 2 / 9**2) <= 1  # an ellipse
    m[10:24, 28:31] = True  # and an ear
    return torch.as_tensor(m, dtype=torch.float32)


def test_the_descriptor_ignores_turns_mirrors_and_size_but_not_shape():
    m = _blob()
    d = shape_descriptor(torch.stack([m, torch.flip(m, [1]), torch.rot90(m, 1, [0, 1])]))
    assert torch.allclose(d[0], d[1], atol=1e-5) and torch.allclose(d[0], d[2], atol=1e-5)
    big = torch.nn.functional.interpolate(m[None, None], scale_factor=2, mode="nearest")[0, 0, 32:96, 32:96]
    assert float((shape_descriptor(big[None])[0] - d[0]).norm()) < 0.1
    no_ear = m.clone()
    no_ear[10:24, 28:31] = 0
    # Losing the ear moves it farther than doubling the size (pixels at 64 px blur both).
    assert float((shape_descriptor(no_ear[None])[0] - d[0]).norm()) > float(
        (shape_descriptor(big[None])[0] - d[0]).norm()
    )


def test_an_entrys_own_shadow_retrieves_it():
    atlas = load_atlas()  # built into the cache on first use
    assert len(atlas.masks) > 1000 and atlas.descriptors.shape[0] == len(atlas.masks)
    rng = np.random.default_rng(3)
    for i in rng.choice(len(atlas.masks), 5, replace=False):
        turned = torch.rot90(torch.as_tensor(atlas.masks[i], dtype=torch.float32), 1, [0, 1])
        nearest = atlas.nearest(shape_descriptor(turned[None])[0].numpy(), 3)
        assert i in nearest


def test_an_atlas_of_hands_without_forearms_builds(monkeypatch):
    """A hand without a forearm has no forearm axis: its entries turn the way the arm would go
    (from the middle finger's base back through the wrist) and are seen from any direction that leads back."""
    from handshadow.hands import load_hand
    from handshadow.hands.limits import JointLimits
    from handshadow.search import atlas as atlas_module

    monkeypatch.setattr(atlas_module, "CONFIGS", 6)
    monkeypatch.setattr(atlas_module, "RINGS", 2)
    model = load_hand("anny", "right", forearm=False)
    atlas = atlas_module.build_atlas(model, JointLimits.preset("anatomical", "right"))
    n = 8 * atlas_module.VIEWS
    assert len(atlas.masks) == n and atlas.poses.batch == n
    assert atlas.masks.reshape(n, -1).any(1).all()  # every entry casts a shadow in the frame
    with torch.no_grad():
        out = model(*atlas.poses.args())
    arm = atlas_module.arm_axis(out)
    toward_lamp = (arm / arm.norm(dim=1, keepdim=True))[:, 2]
    assert float((toward_lamp > 0.98).float().mean()) < 0.25  # not mostly along the beam, as a forearm's are


def test_every_entrys_forearm_leads_back_from_the_wall():
    """No entry points its forearm at the wall (a pose no performer holds, hands.arms): the
    views with the forearm in sight turn it any way that leads back."""
    from handshadow.hands import load_hand
    from handshadow.hands.arms import BACK_SLACK_M

    atlas = load_atlas()
    model = load_hand("anny", "right", forearm=True)
    with torch.no_grad():
        out = model(*atlas.poses.args())
    elbow_minus_wrist = out.forearm_points[:, -1, 2] - atlas.poses.translation[:, 2]  # +z: toward the lamp
    assert float(elbow_minus_wrist.min()) >= -BACK_SLACK_M
