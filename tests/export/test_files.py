"""ResultFolder: a result folder holds a whole result or none, even if the writer dies while
putting it in place."""

import os

import pytest

from handshadow.export.files import MANIFEST, OutputError, ResultFolder, StagedFiles


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
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "pose.json", "shadow.png"]
    assert (out / MANIFEST).read_text() == "pose.json\nshadow.png\n"
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
    kept = {p.name: p.read_text() for p in (tmp_path / "res").iterdir() if p.name != MANIFEST}
    assert kept == {"pose.json": "old", "shadow.png": "old"}


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
    assert sorted(p.name for p in (tmp_path / "res").iterdir()) == [MANIFEST, "pose.json"]


def test_force_drops_the_files_of_the_result_it_replaces(tmp_path):
    """A one-hand result written over a two-hand one leaves no left.obj that looks current,
    nor the print that joined the old result; the person's own files stay."""
    res = tmp_path / "res"
    _write(res, {"pose.json": "two", "left.obj": "old", "right.obj": "old"})
    with StagedFiles([res / "print.stl"]) as files:
        files["print.stl"].write_text("old print")
        files.commit()
    (res / "mine.txt").write_text("precious")
    _write(res, {"pose.json": "one", "right.obj": "new"})
    assert {p.name: p.read_text() for p in res.iterdir() if p.name != MANIFEST} == {
        "pose.json": "one",
        "right.obj": "new",
        "mine.txt": "precious",
    }
    assert (res / MANIFEST).read_text() == "pose.json\nright.obj\n"


@pytest.mark.parametrize("where", ["under-a-file", "a-file"])
def test_a_place_where_no_folder_can_be_made_is_refused_before_the_work(tmp_path, where):
    (tmp_path / "file.txt").write_text("x")
    out = tmp_path / "file.txt" / "res" if where == "under-a-file" else tmp_path / "file.txt"
    with pytest.raises(OutputError, match="cannot write to|not a folder"):
        ResultFolder(out, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]  # nothing made, nothing left


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_a_folder_without_room_for_entries_is_refused_before_the_work():
    with pytest.raises(OutputError, match=r"cannot write to /proc/handshadow/res: no folder can be made in /proc \("):
        ResultFolder("/proc/handshadow/res")  # /proc takes no new entries, even from root


@pytest.mark.parametrize("out", [".", "", "..", "/"])
def test_the_current_folder_or_one_above_it_is_refused_as_an_output(tmp_path, monkeypatch, out):
    # A result folder is swapped in by rename, which the current folder (or a folder holding
    # it) cannot be: '--out .' used to fail with a traceback after the whole fit.
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "notes.txt").write_text("mine")
    monkeypatch.chdir(tmp_path / "work")
    with pytest.raises(OutputError, match="holds the current folder"):
        ResultFolder(out, force=True)
    assert sorted(p.name for p in (tmp_path / "work").iterdir()) == ["notes.txt"]


def test_a_file_joining_a_result_joins_a_manifest_without_its_last_newline(tmp_path):
    # A MANIFEST edited by hand may lack its last newline: the joining file's name goes on a
    # line of its own, so both names stay listed (and go with the result on --force).
    res = tmp_path / "res"
    with ResultFolder(res) as folder:
        (folder / "shadow.png").write_text("s")
        folder.commit()
    (res / MANIFEST).write_text("shadow.png")
    with StagedFiles([res / "print.stl"]) as files:
        files["print.stl"].write_text("p")
        files.commit()
    assert (res / MANIFEST).read_text().splitlines() == ["shadow.png", "print.stl"]
