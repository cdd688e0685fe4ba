"""The command line's own manners: one-line usage errors, help for a bare command, the
version, and a reader that goes away."""

import subprocess
import sys

import pytest

from handshadow.cli import main

PY = [sys.executable, "-m", "handshadow.cli"]


@pytest.mark.parametrize(
    "argv, reason",
    [
        (["fit", "x.png", "--hands", "3"], "handshadow fit: error: argument --hands: invalid choice: '3'"),
        (["fit", "x.png", "--time-limit", "abc"], "handshadow fit: error: argument --time-limit: invalid float"),
        (["interpolate", "a.png"], "handshadow interpolate: error: the following arguments are required: b"),
        (["fit", "x.png", "--no-such-option"], "handshadow: error: unrecognized arguments: --no-such-option"),
        (["sculpt"], "handshadow: error: argument COMMAND: invalid choice: 'sculpt'"),
    ],
)
def test_a_usage_error_is_one_line_with_where_the_help_is(argv, reason, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert err.count("\n") == 1 and err.startswith(reason) and err.rstrip().endswith("--help)"), err


@pytest.mark.parametrize(
    "command", [["fit", "dog"], ["render", "rabbit"], ["interpolate", "dog", "bird"], ["batch", "dog"]]
)
def test_an_empty_out_is_refused_before_any_work(command, capsys, tmp_path, monkeypatch):
    # `--out "$DIR"` with DIR unset: not the default folder, not the current one.
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main([*command, "--out", ""])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.count("\n") == 1 and "argument --out: an empty name" in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_bare_command_shows_what_it_can_do(capsys):
    assert main([]) == 2
    out = capsys.readouterr().out
    assert out.startswith("usage: handshadow") and all(c in out for c in ("fit", "interpolate", "render", "batch"))


def test_the_version_is_the_installed_one(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out == f"handshadow {version('handshadow')}\n"


def test_a_reader_that_goes_away_ends_the_listing_quietly():
    """`handshadow examples | head -1`: the pipe's reader has gone before the listing is written."""
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)  # every write now meets a closed pipe
    try:
        proc = subprocess.run(PY + ["examples"], stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=60)
    finally:
        os.close(write_end)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_a_folder_named_like_a_built_in_does_not_hide_it(tmp_path, monkeypatch):
    # `handshadow render rabbit --out rabbit`, then again with --force: the folder the first
    # run made must not stand for the pose (before: "pose file not found: rabbit"), nor for
    # the built-in target of that name.
    from handshadow import examples

    monkeypatch.chdir(tmp_path)
    assert main(["render", "rabbit", "--out", "rabbit"]) == 0
    assert main(["render", "rabbit", "--out", "rabbit", "--force"]) == 0
    assert examples.pose_path("rabbit") == examples.LIBRARY / "rabbit.json"
    assert examples.target_path("rabbit") == examples.TARGETS / "rabbit.png"
    assert (tmp_path / "rabbit" / "shadow.png").is_file()
