"""atomic_write: a failed write keeps the previous file and leaves no temporary behind."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapkit.io.atomic import atomic_save_npz, atomic_write


class WriterCrash(RuntimeError):
    pass


def test_failed_text_write_keeps_old_file_and_no_temp(tmp_path: Path) -> None:
    target = tmp_path / "joints.csv"
    target.write_text("old contents\n")
    with pytest.raises(WriterCrash), atomic_write(target, "w") as fh:
        fh.write("new header\n")
        fh.write("half a row,")
        fh.flush()
        raise WriterCrash("disk full half way")
    assert target.read_text() == "old contents\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["joints.csv"]


def test_failed_binary_write_of_new_file_leaves_nothing(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "motion.npz"
    with pytest.raises(WriterCrash), atomic_write(target, "wb") as fh:
        fh.write(b"\x00" * 1000)
        raise WriterCrash
    assert not target.exists()
    assert list((tmp_path / "sub").iterdir()) == []


def test_interrupt_also_cleans_up(tmp_path: Path) -> None:
    target = tmp_path / "a.txt"
    target.write_text("keep")
    with pytest.raises(KeyboardInterrupt), atomic_write(target) as fh:
        fh.write("partial")
        raise KeyboardInterrupt
    assert target.read_text() == "keep"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_success_replaces_and_creates_folder(tmp_path: Path) -> None:
    target = tmp_path / "new" / "out.txt"
    with atomic_write(target, "w") as fh:
        fh.write("é")
    assert target.read_text(encoding="utf-8") == "é"
    with atomic_write(target, "w") as fh:
        fh.write("second")
    assert target.read_text() == "second"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]


def test_failed_npz_save_keeps_old_file(tmp_path: Path) -> None:
    target = tmp_path / "truth.npz"
    atomic_save_npz(target, a=np.arange(3))

    class Unsaveable:
        def __array__(self, dtype: object = None, copy: object = None) -> np.ndarray:
            raise WriterCrash("cannot convert")

    with pytest.raises(WriterCrash):
        atomic_save_npz(target, a=np.arange(5), b=Unsaveable())
    with np.load(target) as data:
        np.testing.assert_array_equal(data["a"], np.arange(3))
    assert [p.name for p in tmp_path.iterdir()] == ["truth.npz"]


def test_bad_mode_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"mode must be 'w' or 'wb', found 'a'"):
        with atomic_write(tmp_path / "x", "a"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_atomic_file_gets_the_umask_mode(tmp_path: Path) -> None:
    import os

    old = os.umask(0o022)
    try:
        with atomic_write(tmp_path / "a.txt") as fh:
            fh.write("x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


def test_atomic_folder_swaps_whole_or_not_at_all(tmp_path: Path) -> None:
    from mocapkit.io.atomic import atomic_folder

    target = tmp_path / "result"
    with atomic_folder(target) as tmp:
        (tmp / "a.csv").write_text("1")
        (tmp / "b.csv").write_text("1")
    with pytest.raises(WriterCrash), atomic_folder(target) as tmp:
        (tmp / "a.csv").write_text("2")
        raise WriterCrash
    assert {p.name: p.read_text() for p in target.iterdir()} == {"a.csv": "1", "b.csv": "1"}
    with atomic_folder(target) as tmp:
        (tmp / "c.csv").write_text("3")
    assert [p.name for p in target.iterdir()] == ["c.csv"]  # no old file mixed in
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result"]


def test_stale_temporaries_are_cleared_and_a_folder_caught_mid_swap_restored(
    tmp_path: Path,
) -> None:
    from mocapkit.io.atomic import remove_stale_temporaries

    # a kill between the swap's two renames: NAME is aside, whole, and the new one unfinished
    aside = tmp_path / ".res.old-abc"
    (aside / "res").mkdir(parents=True)
    (aside / "res" / "joints.csv").write_text("old result")
    (tmp_path / ".res.new-def").mkdir()
    (tmp_path / ".res.new-def" / "motion.npz").write_bytes(b"half")
    (tmp_path / ".res.joints.csv.x1.tmp").write_text("half")
    (tmp_path / "..res.new-def.new-ghi").mkdir()
    (tmp_path / "other").mkdir()
    remove_stale_temporaries(tmp_path, "res")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other", "res"]
    assert (tmp_path / "res" / "joints.csv").read_text() == "old result"
    # with NAME in place, an aside copy is the remains of a finished swap: deleted
    (tmp_path / ".res.old-jkl" / "res").mkdir(parents=True)
    remove_stale_temporaries(tmp_path, "res")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other", "res"]
    assert (tmp_path / "res" / "joints.csv").read_text() == "old result"


def test_writing_a_file_over_a_folder_names_the_folder(tmp_path: Path) -> None:
    """Not the internal temporary's name (issue 14: calibrate --out DIR)."""
    target = tmp_path / "cameras.json"
    target.mkdir()
    with pytest.raises(IsADirectoryError, match="expected a file to write, found a folder") as e:
        with atomic_write(target) as fh:
            fh.write("{}")
    assert e.value.filename == str(target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cameras.json"]
