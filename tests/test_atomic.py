"""Atomic output: complete files only, the usual permissions, nothing left on failure."""

import os

import pytest

from leafview.atomic import atomic_output


def test_written_file_gets_umask_permissions(tmp_path):
    with atomic_output(tmp_path / "a.txt") as tmp:
        tmp.write_text("hello")
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o666 & ~mask
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_failure_leaves_target_untouched_and_no_temp_file(tmp_path):
    target = tmp_path / "b.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_output(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["b.txt"]


def test_empty_output_is_an_error(tmp_path):
    with pytest.raises(OSError, match="nothing was written"):
        with atomic_output(tmp_path / "c.txt"):
            pass
    assert list(tmp_path.iterdir()) == []
