"""Per-session folders: separate, and gone when the session ends or the app stops."""

from handshadow.app import SessionStore, _drawing


def test_sessions_are_separate_and_cleaned_up():
    store = SessionStore()
    a, b = store.get("alice"), store.get("bob")
    assert a.dir != b.dir and a.dir.parent == b.dir.parent == store.root
    (a.dir / "secret.png").write_bytes(b"x")
    assert not (b.dir / "secret.png").exists()
    assert store.get("alice") is a
    store.drop("alice")
    assert not a.dir.exists() and b.dir.exists()
    assert a.cancel.is_set()  # a job still running for a closed page stops
    store.close()
    assert not store.root.exists()


def test_empty_drawing_is_recognised():
    import numpy as np

    blank = {"composite": np.zeros((20, 20, 4), np.uint8), "layers": [], "background": None}
    assert _drawing(blank) is None
    inked = {"composite": np.zeros((20, 20, 4), np.uint8)}
    inked["composite"][5:9, 5:9, 3] = 255
    assert _drawing(inked) is not None
