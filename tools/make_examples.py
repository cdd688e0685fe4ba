"""Render the built-in example targets (src/handshadow/data/examples/<name>.png): the shadows of
library poses, black on a white wall, 256 x 256. Being our own renders they carry no licence
question and each has a known answer (the library pose).

Run:  .venv/bin/python tools/make_examples.py
"""

import imageio.v3 as iio
import torch

from handshadow.examples import TARGETS
from handshadow.export.files import shadow_image
from handshadow.hands.posed import cast_shadow
from handshadow.library import library_about, load_library_pose

EXAMPLES = ("rabbit", "dog", "bird", "swan", "deer", "wolf", "duck", "crocodile", "butterfly", "snail")

if __name__ == "__main__":
    TARGETS.mkdir(parents=True, exist_ok=True)
    for name in EXAMPLES:
        pose_set = load_library_pose(name)
        with torch.no_grad():
            mask = cast_shadow(pose_set)[1]
        iio.imwrite(TARGETS / f"{name}.png", shadow_image(mask))
        (TARGETS / f"{name}.txt").write_text(
            library_about(name).split(":")[0] + " (the shadow of the library pose '" + name + "')\n"
        )
        print("wrote", TARGETS / f"{name}.png")
