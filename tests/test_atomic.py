"""Atomic writes: the target changes only when the write completes."""
import pytest

from petsc_htp.atomic import atomic_open, write_text


def test_failed_write_leaves_the_old_file_and_no_temp(tmp_path):
    path = write_text(tmp_path / "sub" / "a.txt", "old")
    with pytest.raises(RuntimeError):
        with atomic_open(path) as fh:
            fh.write("half")
            raise RuntimeError("interrupted")
    assert path.read_text() == "old" and [p.name for p in path.parent.iterdir()] == ["a.txt"]
    with atomic_open(path, "wb") as fh:
        fh.write(b"new")
    assert path.read_bytes() == b"new"
