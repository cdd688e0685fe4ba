"""ResultFolder: a result folder holds a whole result or none, even if the writer dies while
putting it in place."""

import os

import pytest

from handshadow.export.files import OutputError, ResultFolder


def _write(path, files):
    with ResultFolder(path, force=True) as folder:
        for name, text in files.items():
            (folder / name).write_text(text)
        return folder.commit()


def test_a_new_folder_appears_whole_by_one_rename(tmp_path, monkeypatch):
    renames = []
    real = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: (renames.append((a, b)), real(a, b))[1])
    out = _write(tmp_path / "res", {"pose.json": "{}", "shadow.png": "x"})
    assert renames == [(tmp_path / f".res.partial-{os.getpid()}", tmp_path / "res")]
    assert sorted(p.name for p in out.iterdir()) == ["pose.json", "shadow.png"]
    assert [p.name for p in tmp_path.iterdir()] == ["res"]


def test_dying_during_commit_leaves_the_old_result_or_none(tmp_path, monkeypatch):
    def die(a, b):
        raise KeyboardInterrupt  # the process is stopped at the rename

    monkeypatch.setattr(os, "replace", die)
    with pytest.raises(KeyboardInterrupt):
        _write(tmp_path / "res", {"pose.json": "{}", "shadow.png": "x"})
    assert not (tmp_path / "res").exists()
    monkeypatch.undo()
    _write(tmp_path / "res", {"pose.json": "old", "shadow.png": "old"})
    monkeypatch.setattr(os, "replace", die)
    with pytest.raises(KeyboardInterrupt):
        _write(tmp_path / "res", {"pose.json": "new"})
    assert {p.name: p.read_text() for p in (tmp_path / "res").iterdir()} == {"pose.json": "old", "shadow.png": "old"}


def test_force_replaces_same_named_files_and_keeps_the_others(tmp_path):
    res = tmp_path / "res"
    (res / "notes").mkdir(parents=True)
    (res / "notes" / "mine.txt").write_text("precious")
    (res / "shadow.png").write_text("old")
    (res / "link").symlink_to("shadow.png")
    with pytest.raises(OutputError, match="--force"):
        ResultFolder(res)
    _write(res, {"shadow.png": "new", "pose.json": "{}"})
    assert (res / "shadow.png").read_text() == "new"
    assert (res / "notes" / "mine.txt").read_text() == "precious"
    assert os.readlink(res / "link") == "shadow.png"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]  # no staging or old folder left


def test_an_empty_folder_is_replaced(tmp_path):
    (tmp_path / "res").mkdir()
    _write(tmp_path / "res", {"pose.json": "{}"})
    assert [p.name for p in (tmp_path / "res").iterdir()] == ["pose.json"]
