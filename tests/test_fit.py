"""`handshadow fit`: a known answer comes back; the result folder is complete; bad input and
Ctrl-C behave."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from handshadow.cli import main
from handshadow.fit import FitConfig, fit_frame
from handshadow.hands.posed import cast_shadow
from handshadow.library import load_library_pose
from handshadow.posefile import load_pose_file
from handshadow.scene import LAMP_TO_WALL_M, Scene, frame_height_for
from handshadow.search.pieces import two_pieces
from tests.conftest import run_cli

PY = [sys.executable, "-m", "handshadow.cli"]
OUTPUTS = {
    "target.png",
    "shadow.png",
    "overlay.png",
    "scene.json",
    "pose.json",
    "right.obj",
    "hands.glb",
    "progress.gif",
    "guide.png",
}


# Poses whose hands pass into flesh, for the tests of the separation: the library's bird and
# rabbit as they were before tools/make_library.py --fix-depth (2026-12-07), the bird's palms
# 18 mm into each other, the rabbit's ring and little fingers 12 mm into its palm.
INSIDE_POSES = os.path.join(os.path.dirname(__file__), "data", "poses")


def known_target(name: str, size: int, lamp_to_wall_m: float = LAMP_TO_WALL_M):
    """The exact shadow of a library pose at a size, and that pose (a PosedScene); a name
    ending in '-inside' is one of INSIDE_POSES. Under a farther lamp the hands move away from
    the wall by as much, so the shadow keeps its size."""
    if name.endswith("-inside"):
        posed = load_pose_file(os.path.join(INSIDE_POSES, f"{name}.json"))
    else:
        posed = load_library_pose(name)
    shift = np.array([0.0, 0.0, lamp_to_wall_m - LAMP_TO_WALL_M])
    hands = tuple(dataclasses.replace(h, translation=h.translation + shift) for h in posed.hands)
    posed = dataclasses.replace(posed, hands=hands, scene=Scene.default(size, size, lamp_to_wall_m=lamp_to_wall_m))
    return cast_shadow(posed)[1] > 0.5, posed


@pytest.mark.parametrize("lamp_to_wall_m", [LAMP_TO_WALL_M, 4.0])
def test_fit_recovers_a_shadow_rendered_from_a_known_pose(lamp_to_wall_m):
    target, truth = known_target("dog", 128, lamp_to_wall_m)
    # The dog's own pose is left out of the starts: the search has to find it.
    config = FitConfig(
        hands="1", size=128, quality="fast", seed=1, exclude_library=("dog",), lamp_to_wall_m=lamp_to_wall_m
    )
    result = fit_frame(target, config)
    assert result.score.success, result.score
    # The lamp where it was asked for, and the default frame: the dog's forearm runs off it.
    assert result.posed.scene == truth.scene
    _assert_wrists_cast_alike(result, truth, 128)


def _assert_wrists_cast_alike(result, truth, frame_px: int) -> None:
    """The answer comes back: the hand casts its shadow where the true hand casts it."""
    true_wrist = truth.scene.project(torch.as_tensor(truth.hands[0].translation)[None])[0][0]
    got_wrist = result.posed.scene.project(torch.as_tensor(result.posed.hands[0].translation)[None])[0][0]
    assert float((true_wrist - got_wrist).norm()) < 0.12 * frame_px


def test_a_shape_drawn_large_in_its_frame_is_fitted_in_a_smaller_frame_and_comes_back():
    # The rabbit's hand without its forearm: a whole shape whose longer side is 0.87 of the
    # frame, larger than the search's working size (0.715), so the fit's frame on the wall is
    # smaller than the truth's; its pixels, and the shadow in them, are the same.
    _, truth = known_target("rabbit", 128, 4.0)
    truth = dataclasses.replace(truth, forearm=False)
    target = cast_shadow(truth)[1] > 0.5
    config = FitConfig(hands="1", size=128, quality="fast", seed=1, exclude_library=("rabbit",), forearm=False)
    result = fit_frame(target, config)
    assert result.score.success, result.score
    scene = result.posed.scene
    assert scene.light == truth.scene.light and scene.image.width == 128
    assert scene.frame_height_m == pytest.approx(frame_height_for([target]))
    assert scene.frame_height_m < 0.9 * truth.scene.frame_height_m
    _assert_wrists_cast_alike(result, truth, 128)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    out = tmp_path_factory.mktemp("fit") / "dog"
    assert main("fit dog --hands 1 --size 96 --quality fast --quiet --device cpu --out".split() + [str(out)]) == 0
    return out


def test_result_folder_is_complete_and_renders_back(fitted, tmp_path):
    assert OUTPUTS <= {p.name for p in fitted.iterdir()}
    pose = json.loads((fitted / "pose.json").read_text())
    assert {"iou", "iterations", "seconds", "seed", "success"} <= set(pose["fit"])
    shadow = iio.imread(fitted / "shadow.png")
    overlay = iio.imread(fitted / "overlay.png")
    assert shadow.shape == (96, 96) and overlay.shape == (96, 96, 3)
    gif = iio.imread(fitted / "progress.gif", index=None)
    assert gif.ndim == 4 and gif.shape[0] >= 5  # frames of the optimisation
    assert main(["render", str(fitted / "pose.json"), "--out", str(tmp_path / "again")]) == 0
    assert np.array_equal(iio.imread(tmp_path / "again" / "shadow.png"), shadow)


def _run(args, **kw):
    return subprocess.run(PY + args, capture_output=True, text=True, **kw)


def _bad_images(tmp_path):
    cases = {}
    (tmp_path / "notes.png").write_text("not an image")
    cases["non-image"] = tmp_path / "notes.png"
    iio.imwrite(tmp_path / "empty.png", np.full((40, 40), 255, np.uint8))
    cases["empty"] = tmp_path / "empty.png"
    full = np.zeros((40, 40), np.uint8)
    full[0, :] = full[-1, :] = full[:, 0] = full[:, -1] = 255
    iio.imwrite(tmp_path / "full.png", full)
    cases["fills the frame"] = tmp_path / "full.png"
    iio.imwrite(tmp_path / "dot.png", np.zeros((1, 1), np.uint8))
    cases["1 pixel"] = tmp_path / "dot.png"
    cases["missing"] = tmp_path / "nope.png"
    return cases


def test_bad_targets_fail_cleanly(tmp_path):
    for name, path in _bad_images(tmp_path).items():
        out = tmp_path / f"out-{name.replace(' ', '_')}"
        res = _run(["fit", str(path), "--out", str(out)])
        assert res.returncode == 2, (name, res.stderr)
        assert res.stderr.startswith("handshadow: error: ") and res.stderr.count("\n") == 1, (name, res.stderr)
        assert not out.exists(), name


@pytest.mark.parametrize(
    "args, message",
    [
        (["--device", "tpu"], "unknown device"),
        (["--hand-model", "mano"], "--mano-dir"),
        (["--size", "4"], "--size"),
        (["--lamp-distance", "9"], "lamp's distance from the wall must be 2 to 5 m"),
        (["--lamp-distance", "nan"], "lamp's distance"),
        (["--lamp-distance", "3", "--light", "directional"], "--lamp-distance needs a point light"),
        (["bird", "--lamp-distance", "3"], "--lamp-distance works with one target"),
        (["--seed", "-1"], "--seed must be a whole number from 0 to 4294967295, got -1"),
        (["--seed", str(2**40)], "--seed must be a whole number"),
        (["--hand-shape", "weight=2"], "--hand-shape: Anny shape parameter weight must lie in [0, 1]"),
        (["--hand-shape", "wrist=0.3"], "--hand-shape: unknown Anny shape parameter 'wrist'"),
        (["--hand-shape", "0.5,1"], "--hand-shape: give Anny phenotype values as name=value"),
        (["--hand-shape", "weight=heavy"], "--hand-shape: 'weight=heavy' does not give a number"),
        (["--time-limit", "0"], "--time-limit must be a positive number of seconds, got 0"),
        (["--time-limit", "nan"], "--time-limit must be a positive number of seconds"),
    ],
)
def test_bad_options_fail_cleanly(tmp_path, args, message):
    res = run_cli(["fit", "dog"] + args + ["--out", str(tmp_path / "o")])
    assert res.returncode == 2 and message in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert not (tmp_path / "o").exists()


def test_a_mano_fit_with_the_users_hand_shape_writes_that_hand_and_renders_back(tmp_path):
    from handshadow.hands import load_rig
    from handshadow.hands.rig import hand_length_m
    from tests.hands.fake_mano import write_synthetic_mano

    mano = tmp_path / "mano"
    mano.mkdir()
    for side in ("right", "left"):
        write_synthetic_mano(mano / f"MANO_{side.upper()}.pkl", side)
    out = tmp_path / "o"
    fast = ["--quality", "fast", "--iters", "40", "--attempts", "1", "--hops", "0", "--size", "64", "--hands", "1"]
    args = ["fit", "dog", "--hand-model", "mano", "--mano-dir", str(mano), "--hand-shape", "1.5,-0.5"]
    res = _run([*args, *fast, "--out", str(out)])
    assert res.returncode == 0, res.stderr
    pose = json.loads((out / "pose.json").read_text())
    assert [(h["model"], h["shape"]) for h in pose["hands"]] == [("mano", {"betas": [1.5, -0.5]})]
    length = hand_length_m(load_rig("mano", pose["hands"][0]["side"], {"betas": [1.5, -0.5]}, str(mano)))
    mean = hand_length_m(load_rig("mano", pose["hands"][0]["side"], None, str(mano)))
    assert abs(length - mean) > 0.002  # the shape is a hand of another length, and the guide says which
    assert f"Sized for hands {length * 100:.1f} cm long" in res.stdout
    again = tmp_path / "again"
    assert main(["render", str(out / "pose.json"), "--mano-dir", str(mano), "--out", str(again)]) == 0
    assert np.array_equal(iio.imread(again / "shadow.png"), iio.imread(out / "shadow.png"))


def test_the_time_limit_ends_the_search_and_the_result_is_written(tmp_path):
    out = tmp_path / "o"
    res = _run(
        ["fit", "dog", "--hands", "1", "--size", "64", "--quality", "fast", "--time-limit", "1e-6", "--out", str(out)]
    )
    assert res.returncode == 0, res.stderr
    fit = json.loads((out / "pose.json").read_text())["fit"]
    assert fit["iterations"] == 1 and not fit["interrupted"]  # the deadline is checked after each step
    assert fit["time_limited"] and res.stdout.startswith("time limit reached; best so far: IoU")
    assert (out / "shadow.png").exists() and (out / "guide.png").exists()


def test_missing_mano_files_and_unavailable_cuda(tmp_path):
    res = _run(["fit", "dog", "--out", str(tmp_path / "o"), "--hand-model", "mano", "--mano-dir", str(tmp_path)])
    assert res.returncode == 2 and "MANO_RIGHT.pkl" in res.stderr and res.stderr.count("\n") == 1
    if not torch.cuda.is_available():
        res = _run(["fit", "dog", "--out", str(tmp_path / "o"), "--device", "cuda"])
        assert res.returncode == 2 and "CUDA" in res.stderr and res.stderr.count("\n") == 1


def test_non_empty_output_folder_is_kept(tmp_path):
    (tmp_path / "keep").mkdir()
    (tmp_path / "keep" / "mine.txt").write_text("precious")
    res = _run(["fit", "dog", "--out", str(tmp_path / "keep")])
    assert res.returncode == 2 and "--force" in res.stderr
    assert (tmp_path / "keep" / "mine.txt").read_text() == "precious"


@pytest.mark.parametrize("sent", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_ctrl_c_or_a_sigterm_writes_the_best_result_so_far(tmp_path, sent):
    # A SIGTERM is a job runner's or `timeout`'s way to stop a fit: it keeps the best, as Ctrl-C does.
    out = tmp_path / "interrupted"
    proc = subprocess.Popen(
        PY
        + [
            "fit",
            "bird",
            "--hands",
            "2",
            "--size",
            "96",
            "--out",
            str(out),
            "--quiet",
            "--verbose",
            "--device",
            "cpu",
            "--iters",
            "100000",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        # A shell that starts jobs in the background ignores SIGINT, and children inherit that.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    lines = []
    for line in proc.stderr:  # -v logs each stage as it begins: wait for the search's first
        lines.append(line)
        if line.startswith("stage 1 of"):
            break
    assert lines and lines[-1].startswith("stage 1 of"), "".join(lines)
    time.sleep(1)  # a few steps into it
    proc.send_signal(sent)
    _, rest = proc.communicate(timeout=240)
    err = "".join(lines) + rest
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert OUTPUTS | {"left.obj"} <= {p.name for p in out.iterdir()}
    pose = json.loads((out / "pose.json").read_text())
    assert pose["fit"]["interrupted"] is True and len(pose["hands"]) == 2


def test_frame_recorder_counts_over_both_searches_of_hands_auto_and_every_attempt():
    from types import SimpleNamespace

    from handshadow.pipeline import FrameRecorder

    recorder = FrameRecorder(total_steps=200, searches=2, limit=10)
    seen = []
    for attempt in (0, 1):  # a failed fit's second attempt runs both searches again
        for n_hands in (1, 2):  # each search counts its own steps from 0
            for done in range(1, 101):
                hands = SimpleNamespace(n_hands=n_hands)
                recorder(SimpleNamespace(done=done, total=100, poses=hands, attempt=attempt, hop=0))
                seen.append((recorder.done, recorder.finished, recorder.attempt))
        kept = len(recorder.frames)
        for done in range(1, 51):  # a hop's stages after the searches: neither counted nor kept
            recorder(SimpleNamespace(done=done, total=50, poses=hands, attempt=attempt, hop=1))
        assert (len(recorder.frames), recorder.done, recorder.finished) == (kept, seen[-1][0], True)
    assert [d for d, _, _ in seen] == list(range(1, 401))
    # finished only after each attempt's last search
    assert [f for _, f, _ in seen] == ([False] * 199 + [True]) * 2
    assert [a for _, _, a in seen] == [0] * 200 + [1] * 200
    per_search = [sum(f.poses.n_hands == n and f.attempt == 1 for f in recorder.frames) for n in (1, 2)]
    assert min(per_search) >= 5  # both searches of an attempt are in the GIF's snapshots


def test_frame_recorder_counts_each_attempt_from_zero_after_one_that_gave_up_early():
    from types import SimpleNamespace

    from handshadow.pipeline import FrameRecorder

    recorder = FrameRecorder(total_steps=200, searches=2, limit=10)
    within = []
    for attempt, last in ((0, 40), (1, 100)):  # the first attempt's searches both gave up after 40 of 100 steps
        for n_hands in (1, 2):
            for done in range(1, last + 1):
                recorder(
                    SimpleNamespace(
                        done=done, total=100, poses=SimpleNamespace(n_hands=n_hands), attempt=attempt, hop=0
                    )
                )
                within.append(recorder.in_attempt)
    assert within == list(range(1, 81)) + list(range(1, 201))
    assert recorder.done == 280 and recorder.finished


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [("attempts", 0, "attempt"), ("hops", -1, "hops"), ("skip_attempts", None, "skip_attempts")],
)
def test_a_bad_count_from_python_fails_before_the_search(field, value, words, monkeypatch):
    import handshadow.fit as fit_module
    from handshadow.errors import HandshadowError

    if field == "skip_attempts":  # skipping every attempt fast may make leaves none to run
        value = fit_module.ATTEMPTS["fast"]

    def no_search(*args, **kwargs):
        raise AssertionError("the search started")

    monkeypatch.setattr(fit_module, "choose_starts", no_search)
    target = np.zeros((32, 32), bool)
    target[8:24, 10:22] = True
    with pytest.raises(HandshadowError, match=words):
        fit_frame(target, dataclasses.replace(FitConfig(size=32, quality="fast"), **{field: value}))


def test_hands_auto_takes_one_hand_when_its_search_passes():
    from types import SimpleNamespace

    from handshadow.fit import ONE_HAND_PREFERENCE, HandCountFit

    def search(n_hands, failed, blend, unholdable=False):
        return HandCountFit(n_hands, [], None, SimpleNamespace(key=(unholdable, failed, -blend)))

    def chosen(*searches):
        return min(searches, key=HandCountFit.preference_key).n_hands

    # both pass: one hand, however much better two hands fit
    assert chosen(search(1, 0.0, 1.0), search(2, 0.0, 1.3)) == 1
    # only two hands pass, or only they can be held: two hands
    assert chosen(search(1, 1.0, 1.3), search(2, 0.0, 1.0)) == 2
    assert chosen(search(1, 0.0, 1.3, unholdable=True), search(2, 0.0, 1.0)) == 2
    # neither passes: one hand unless two blend better by more than the preference
    margin = ONE_HAND_PREFERENCE
    assert chosen(search(1, 1.0, 1.0), search(2, 1.0, 1.0 + margin / 2)) == 1
    assert chosen(search(1, 1.0, 1.0), search(2, 1.0, 1.0 + 2 * margin)) == 2


def test_a_target_in_two_pieces_comes_back_with_a_hand_for_each_piece():
    # The library's heart with its hands drawn 8 cm apart: two pieces, each one hand's shadow.
    _, heart = known_target("heart", 128)
    apart = {"right": np.array([0.08, 0.0, 0.0]), "left": np.array([-0.08, 0.0, 0.0])}
    hands = tuple(dataclasses.replace(h, translation=h.translation + apart[h.side]) for h in heart.hands)
    truth = dataclasses.replace(heart, hands=hands)
    target = cast_shadow(truth)[1] > 0.5
    pieces = two_pieces(target, truth.scene)
    assert pieces is not None
    reports = []
    config = FitConfig(size=128, quality="fast", seed=1, exclude_library=("heart",), attempts=1)
    result = fit_frame(target, config, progress=reports.append)  # hands auto: two pieces take two
    assert result.score.success, result.score
    assert [h.side for h in result.posed.hands] == ["right", "left"]
    for hand, piece in zip(result.posed.hands, pieces):  # the right hand casts the right piece
        alone = cast_shadow(dataclasses.replace(result.posed, hands=(hand,)))[1] > 0.5
        assert (alone & piece).sum() > 0.9 * alone.sum() and (alone & piece).sum() > 0.8 * piece.sum()
    # Progress counts the pieces' searches and the last stage as one search, with both hands.
    total = reports[0].total
    assert all(r.total == total and r.poses.n_hands == 2 for r in reports)
    done = [r.done for r in reports if not r.hop]
    assert done == sorted(done) and done[-1] == total
