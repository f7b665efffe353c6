"""World textures kept on disk: later processes read them instead of rendering them again."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from skeye.sim import world_textures
from skeye.sim.world_textures import KEPT_FILES, ground_texture_png, pad_texture_png
from skeye.vision.pad import SKEYE_4, render_pad

GRASS = ("grass", (0.2, 0.4, 0.1), (0.3, 0.5, 0.2))


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """An empty cache home; the process's own (lru) copies are dropped before and after."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    pad_texture_png.cache_clear()
    ground_texture_png.cache_clear()
    yield tmp_path / "skeye" / "textures"
    pad_texture_png.cache_clear()
    ground_texture_png.cache_clear()


def kept(folder: Path, kind: str) -> list[Path]:
    return sorted(folder.glob(f"{kind}-*.png"))


def a_png(value: int) -> bytes:
    ok, data = cv2.imencode(".png", np.full((4, 4, 3), value, np.uint8))
    assert ok
    return data.tobytes()


def test_a_rendered_texture_is_kept_and_a_later_process_reads_it(cache: Path) -> None:
    first = pad_texture_png(SKEYE_4, 256)
    (path,) = kept(cache, "pad")
    assert path.read_bytes() == first
    grey = cv2.imdecode(np.frombuffer(first, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(grey, render_pad(SKEYE_4, 256, supersample=2))  # the same pixels
    # Another process keyed the same way returns what the file holds, not a new rendering:
    # the file is replaced by another whole image (named by its own digest, as the cache names
    # a file), which is what comes back.
    other = a_png(77)
    kind, key, _ = path.stem.split("-")
    path.unlink()
    (cache / f"{kind}-{key}-{hashlib.sha256(other).hexdigest()[:16]}.png").write_bytes(other)
    code = ("import sys; from skeye.sim.world_textures import pad_texture_png; "
            "from skeye.vision.pad import SKEYE_4; "
            "sys.stdout.buffer.write(pad_texture_png(SKEYE_4, 256))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120,
                         env={**os.environ, "XDG_CACHE_HOME": str(cache.parent.parent)})
    assert out.returncode == 0, out.stderr.decode()
    assert out.stdout == other


def test_other_inputs_are_kept_apart(cache: Path) -> None:
    small, large = pad_texture_png(SKEYE_4, 128), pad_texture_png(SKEYE_4, 256)
    ground = ground_texture_png(*GRASS, 64)
    assert len(kept(cache, "pad")) == 2 and len(kept(cache, "ground")) == 1
    assert {p.read_bytes() for p in cache.glob("*.png")} == {small, large, ground}


def test_a_damaged_file_is_rendered_again_and_replaced(cache: Path) -> None:
    whole = ground_texture_png(*GRASS, 64)
    (path,) = kept(cache, "ground")
    middle = len(whole) // 2
    flipped = whole[:middle] + bytes([whole[middle] ^ 0xFF]) + whole[middle + 1:]
    for bad in (whole[:middle], b"", b"not a png at all", flipped):
        path.write_bytes(bad)
        ground_texture_png.cache_clear()
        assert ground_texture_png(*GRASS, 64) == whole
        assert kept(cache, "ground") == [path] and path.read_bytes() == whole
    assert not list(cache.glob(".*partial"))


def test_without_a_home_folder_the_texture_is_still_made(
        cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """No XDG_CACHE_HOME and no home folder (HOME unset, no passwd entry: a container's
    arbitrary user id): pathlib raises RuntimeError, which stopped every world's build."""
    monkeypatch.delenv("XDG_CACHE_HOME")

    def no_home() -> Path:
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.setattr(Path, "home", staticmethod(no_home))
    made = pad_texture_png(SKEYE_4, 128)
    grey = cv2.imdecode(np.frombuffer(made, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(grey, render_pad(SKEYE_4, 128, supersample=2))


def test_a_half_written_file_of_a_killed_writer_goes_in_time(cache: Path) -> None:
    cache.mkdir(parents=True)
    stale, fresh = cache / ".pad-x.png.1.2.partial", cache / ".pad-y.png.3.4.partial"
    for path in (stale, fresh):
        path.write_bytes(b"half")
    old_s = time.time() - world_textures.PARTIAL_AGE_S - 60.0
    os.utime(stale, (old_s, old_s))
    pad_texture_png(SKEYE_4, 128)  # a write, and the trim after it
    assert not stale.exists() and fresh.exists()


def test_without_a_writable_cache_the_texture_is_still_made(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    home = tmp_path / "a-file"
    home.write_text("XDG_CACHE_HOME names a file, so no folder can be made under it")
    monkeypatch.setenv("XDG_CACHE_HOME", str(home))
    pad_texture_png.cache_clear()
    try:
        made = pad_texture_png(SKEYE_4, 128)
    finally:
        pad_texture_png.cache_clear()
    grey = cv2.imdecode(np.frombuffer(made, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(grey, render_pad(SKEYE_4, 128, supersample=2))


def test_the_oldest_kept_files_go_beyond_the_limit(cache: Path) -> None:
    cache.mkdir(parents=True)
    for i in range(KEPT_FILES + 3):
        old = cache / f"pad-old{i:02d}.png"
        old.write_bytes(a_png(i))
        os.utime(old, (1_000_000 + i, 1_000_000 + i))
    pad_texture_png(SKEYE_4, 128)  # the newest
    left = sorted(p.name for p in cache.glob("*.png"))
    assert len(left) == KEPT_FILES
    assert [n for n in left if n.startswith("pad-old")] == [
        f"pad-old{i:02d}.png" for i in range(4, KEPT_FILES + 3)]


def test_the_key_follows_the_rendering_code(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pad_texture_png(SKEYE_4, 128)
    world_textures._code_key.cache_clear()
    try:
        monkeypatch.setattr(np, "__version__", "0.0-another")
        pad_texture_png.cache_clear()
        pad_texture_png(SKEYE_4, 128)
    finally:
        world_textures._code_key.cache_clear()
    assert len(kept(cache, "pad")) == 2  # another numpy: rendered and kept anew
