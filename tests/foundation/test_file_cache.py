"""The content-keyed file cache behind the render tiles and the unchanged figures of an edit."""

import threading
import time
from pathlib import Path

import numpy as np

from physanim.store.file_cache import FileCache, content_digest


def test_digest_sees_values_shapes_and_types():
    a = np.arange(6.0)
    assert content_digest(a, {"x": 1}) == content_digest(a.copy(), {"x": 1})
    assert content_digest(a) != content_digest(a.reshape(2, 3))  # same bytes, other shape
    assert content_digest(a) != content_digest(a.astype(np.float32))
    assert content_digest(a, 1) != content_digest(a, 2)
    assert content_digest(b"ab", b"c") != content_digest(b"a", b"bc")  # parts are separated


def test_made_once_per_content_and_least_recently_used_dropped(tmp_path):
    cache, made = FileCache(tmp_path / "cache", keep=2), []

    def producer(text):
        def write(out):
            made.append(text)
            out.write_text(text)

        return write

    for text in ("one", "two", "one", "three", "two"):
        out = tmp_path / f"out-{len(made)}.txt"
        cache.make(out, content_digest(text), producer(text))
        assert out.read_text() == text
        time.sleep(0.02)  # file times are coarser than these steps (jiffies)
    # "one" reused; "three" pushed out the least recently used ("two"), made again at the end
    assert made == ["one", "two", "three", "two"]
    assert len(list((tmp_path / "cache").iterdir())) == 2


def test_two_threads_putting_the_same_digest_at_once_both_succeed(tmp_path) -> None:
    """Evaluate and export, threads of one run, embed the same scan: both write the same
    digest at the same moment (a barrier holds each inside its write) and both get the file
    (one aside-file per process used to be renamed from under the other)."""

    cache = FileCache(tmp_path / "c")
    barrier = threading.Barrier(2)
    got: list[Path] = []

    def write(path: Path) -> None:
        path.write_bytes(b"same")
        barrier.wait(timeout=10)

    threads = [
        threading.Thread(target=lambda: got.append(cache.put("d" * 8, ".bin", write)))
        for _ in range(2)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(got) == 2 and all(p.read_bytes() == b"same" for p in got)
    assert [p.name for p in cache.folder.iterdir()] == ["d" * 8 + ".bin"]
