"""Outputs get the mode the umask asks for (not mkstemp's 0600); output folders can be created."""
import os
import stat

import numpy as np
import pytest

from mitsuba_lab import images


@pytest.fixture
def umask():
    """Set the process umask for one test, and restore it afterwards."""
    old = os.umask(0o022)
    os.umask(old)

    def set_mask(mask):
        os.umask(mask)
        return mask

    yield set_mask
    os.umask(old)


def mode_of(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


IMAGE = np.linspace(0, 1, 4 * 6 * 3, dtype=np.float32).reshape(4, 6, 3)


@pytest.mark.parametrize("mask, expected", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_images_honour_the_umask(tmp_path, umask, mask, expected):
    umask(mask)
    exr, png = tmp_path / "a.exr", tmp_path / "a.png"
    images.write_exr(str(exr), IMAGE, {"k": "v"})
    images.write_png(str(png), IMAGE)
    assert mode_of(exr) == expected
    assert mode_of(png) == expected
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".")]     # no temporaries left
    pixels, meta = images.read_exr(str(exr))
    assert np.allclose(pixels, IMAGE) and meta["k"] == "v"


@pytest.mark.parametrize("mask", [0o022, 0o077])
def test_atomic_path_text_file_matches_plain_open(tmp_path, umask, mask):
    umask(mask)
    plain = tmp_path / "plain.csv"
    plain.write_text("a,b\n")
    target = tmp_path / "atomic.csv"
    with images.atomic_path(str(target)) as tmp:
        assert mode_of(tmp) == 0o600                    # private while being written
        with open(tmp, "w") as f:
            f.write("a,b\n")
    assert mode_of(target) == mode_of(plain) == 0o666 & ~mask


def test_replacing_a_file_gives_the_umask_mode(tmp_path, umask):
    umask(0o022)
    target = tmp_path / "x.exr"
    target.write_bytes(b"old")
    os.chmod(target, 0o600)
    images.write_exr(str(target), IMAGE)
    assert mode_of(target) == 0o644


def test_current_umask_reads_without_changing_it(umask):
    for mask in (0o022, 0o077, 0o027):
        umask(mask)
        assert images.current_umask() == mask
        assert images.default_file_mode() == 0o666 & ~mask
        now = os.umask(0o022)
        os.umask(now)
        assert now == mask


def test_failed_write_leaves_nothing(tmp_path):
    target = tmp_path / "x.csv"
    with pytest.raises(RuntimeError):
        with images.atomic_path(str(target)) as tmp:
            with open(tmp, "w") as f:
                f.write("half")
            raise RuntimeError("writer failed")
    assert os.listdir(tmp_path) == []


def test_ensure_parent_creates_folders(tmp_path):
    target = tmp_path / "new" / "deeper" / "x.exr"
    assert images.ensure_parent(str(target)) == str(target.parent)
    assert target.parent.is_dir()
    images.ensure_parent(str(target))                   # exists already: fine
    images.write_exr(str(target), IMAGE)
    assert target.is_file()


def test_ensure_parent_relative_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    images.ensure_parent("out/x.exr")
    assert (tmp_path / "out").is_dir()
    images.ensure_parent("y.exr")                       # the current folder


def test_ensure_parent_reports_a_file_in_the_way(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(OSError, match="output folder is a file"):
        images.ensure_parent(str(tmp_path / "file" / "x.exr"))
    with pytest.raises(OSError, match="cannot create output folder"):
        images.ensure_parent(str(tmp_path / "file" / "sub" / "x.exr"))


def test_ensure_parent_still_checks_the_path(tmp_path):
    (tmp_path / "x.exr").mkdir()
    with pytest.raises(OSError, match="output path is a folder"):
        images.ensure_parent(str(tmp_path / "x.exr"))


def test_check_writable_does_not_create(tmp_path):
    with pytest.raises(OSError, match="output folder does not exist"):
        images.check_writable(str(tmp_path / "missing" / "x.exr"))
    assert not (tmp_path / "missing").exists()
