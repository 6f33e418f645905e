"""Weights and library arrays verified against their SHA-256 once per state of the file (issue 44), soundly:
a file changed after it was verified is refused even when its size and modification time are put back."""

from __future__ import annotations

import hashlib
import os
import shutil
import time

import pytest

from keyfill import files
from keyfill.errors import ModelError
from keyfill.learn import installed_models


@pytest.fixture
def cache(monkeypatch, tmp_path):
    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "verified"


def settled(monkeypatch):
    """Take every file as changed long enough ago to be marked (the tests wait one clock tick instead)."""
    monkeypatch.setattr(files, "RACY_S", 0.0)
    time.sleep(0.05)


def change_in_place(path, offset: int = 100):
    """Flip one byte of ``path`` and put its modification time back: same size, same mtime, new ctime."""
    st = os.stat(path)
    time.sleep(0.05)
    with open(path, "r+b") as f:
        f.seek(offset)
        byte = f.read(1)
        f.seek(offset)
        f.write(bytes([byte[0] ^ 0xFF]))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    after = os.stat(path)
    assert (after.st_size, after.st_mtime_ns) == (st.st_size, st.st_mtime_ns)
    assert after.st_ctime_ns != st.st_ctime_ns


def test_a_verified_state_is_not_hashed_again(monkeypatch, tmp_path, cache):
    path = tmp_path / "weights.bin"
    path.write_bytes(os.urandom(4096))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    assert files.sha256_file(path) == digest
    settled(monkeypatch)
    assert files.verified(path, digest) and len(list(cache.iterdir())) == 1
    assert not files.verified(path, "0" * 64)  # another digest is another mark: hashed, refused
    monkeypatch.setattr(files, "sha256_file", lambda p: pytest.fail("an unchanged, verified file was hashed"))
    assert files.verified(path, digest)


def test_a_file_changed_after_verifying_is_refused(monkeypatch, tmp_path, cache):
    path = tmp_path / "weights.bin"
    path.write_bytes(os.urandom(4096))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    settled(monkeypatch)
    assert files.verified(path, digest)
    change_in_place(path)
    assert not files.verified(path, digest)
    # another file renamed into its place, with the same bytes as the verified one: a new state, hashed again
    other = tmp_path / "other.bin"
    shutil.copyfile(path, other)
    change_in_place(other)
    os.replace(other, path)
    assert files.verified(path, digest)


def test_a_file_changed_just_now_is_verified_but_not_marked(tmp_path, cache):
    path = tmp_path / "weights.bin"
    path.write_bytes(b"fresh")
    assert files.verified(path, hashlib.sha256(b"fresh").hexdigest())
    assert not cache.exists()  # its change time may still be shared with a change in the same clock tick


def test_an_unwritable_cache_costs_a_hash_not_an_error(monkeypatch, tmp_path):
    blocker = tmp_path / "cache"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv("KEYFILL_CACHE", str(blocker))
    path = tmp_path / "weights.bin"
    path.write_bytes(b"abc")
    settled(monkeypatch)
    assert files.verified(path, hashlib.sha256(b"abc").hexdigest())
    assert not files.verified(path, "0" * 64)


@pytest.mark.skipif(installed_models.shipped("bandai2-transformer") is None
                    or not (installed_models.shipped("bandai2-transformer") / "model.onnx").is_file(),
                    reason="needs the shipped human transformer and its graph")
def test_the_weights_check_refuses_weights_changed_after_install(monkeypatch, tmp_path, cache):
    """A model folder whose graph was verified once: its weights changed afterwards (same size, modification
    time put back) are refused on the next run, which reads the marks of the first."""
    pytest.importorskip("onnxruntime")
    from keyfill.learn.onnx import check_binding, open_graph

    folder = tmp_path / "bandai2-transformer"
    shutil.copytree(installed_models.shipped("bandai2-transformer"), folder)
    settled(monkeypatch)
    graph = open_graph(folder / "model.onnx")
    check_binding(graph, folder)
    assert len(list(cache.iterdir())) == 1
    check_binding(graph, folder)  # unchanged: passes from the mark
    change_in_place(folder / "weights.safetensors", offset=(folder / "weights.safetensors").stat().st_size // 2)
    with pytest.raises(ModelError, match="exported from other weights"):
        check_binding(graph, folder)
