"""Model and data files that declare more than they should (issue 30, findings 5 and 9): refused from the
declared sizes and headers, before anything is decompressed or allocated."""

from __future__ import annotations

import io
import json
import tracemalloc
import zipfile

import numpy as np
import pytest

import interprim as ip
import interprim.io as ipio
from interprim.core.errors import DataFileError, ModelFileError
from interprim.synthetic import two_agent_demos


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    path = tmp_path_factory.mktemp("bombs") / "good.npz"
    ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=6).fit(two_agent_demos(6, seed=0, frames=60), dt=0.01).save(
        str(path))
    return path


def _npy_header(shape, dtype="<f8") -> bytes:
    b = io.BytesIO()
    np.lib.format.write_array_header_1_0(b, {"descr": dtype, "fortran_order": False, "shape": shape})
    return b.getvalue()


def _with_member(src, dst, name, n_bytes, header_shape=None, list_in_checksums=None):
    """A copy of model file ``src`` with a member ``name`` of ``n_bytes`` zeros (compressed: a zip bomb)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "metadata.npy" and list_in_checksums is not None:
                meta = json.loads(np.load(io.BytesIO(data)).astype(np.uint8).tobytes())
                meta["checksums"][name[:-4]] = list_in_checksums
                b = io.BytesIO()
                np.save(b, np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
                data = b.getvalue()
            zout.writestr(info, data)
        with zout.open(name, "w", force_zip64=True) as f:
            f.write(_npy_header(header_shape or (n_bytes // 8,)))
            chunk = bytes(1 << 20)
            for _ in range(n_bytes >> 20):
                f.write(chunk)
    return dst


def _peak_while(fn):
    tracemalloc.start()
    try:
        fn()
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak


def test_zip_bomb_over_the_archive_limit_is_refused_before_decompressing(good, tmp_path, monkeypatch):
    """Issue 30, finding 5: a 2 MB file took 4.1 GB for 44 s before it was refused (every member read whole)."""
    bomb = _with_member(good, tmp_path / "bomb.npz", "zz.npy", 64 << 20)
    assert bomb.stat().st_size < 1 << 20
    monkeypatch.setattr(ipio, "MAX_ARCHIVE_BYTES", 16 << 20)

    def load():
        with pytest.raises(ModelFileError, match="over the limit .* refusing to decompress"):
            ip.InteractionPrimitive.load(str(bomb))

    assert _peak_while(load) < 8 << 20  # nothing near the 64 MiB the member declares


def test_member_larger_than_its_metadata_says_is_refused_before_decompressing(good, tmp_path):
    bomb = _with_member(good, tmp_path / "bomb.npz", "zz.npy", 64 << 20,
                        list_in_checksums={"dtype": "<f8", "shape": [2, 2], "sha256": "0" * 64})

    def load():
        with pytest.raises(ModelFileError, match="metadata gives it shape \\[2, 2\\].*refusing to decompress"):
            ip.InteractionPrimitive.load(str(bomb))

    assert _peak_while(load) < 8 << 20


def test_member_not_listed_in_the_metadata_is_refused_before_decompressing(good, tmp_path):
    bomb = _with_member(good, tmp_path / "bomb.npz", "zz.npy", 64 << 20)

    def load():
        with pytest.raises(ModelFileError, match="not listed in the metadata's checksums"):
            ip.InteractionPrimitive.load(str(bomb))

    assert _peak_while(load) < 8 << 20


def test_header_that_disagrees_with_the_declared_size_is_refused(good, tmp_path):
    bomb = _with_member(good, tmp_path / "bomb.npz", "zz.npy", 1 << 20, header_shape=(10**9,),
                        list_in_checksums={"dtype": "<f8", "shape": [131072], "sha256": "0" * 64})
    with pytest.raises(ModelFileError, match="truncated or corrupt"):
        ip.InteractionPrimitive.load(str(bomb))


def test_a_good_model_file_still_loads(good):
    m = ip.InteractionPrimitive.load(str(good))
    assert m.n_dofs_ == 4 or m.n_dofs_ > 0


def test_data_npz_declaring_5e12_values_is_refused_from_its_header(tmp_path):
    """Issue 30, finding 9: a data .npz declaring 5e12 elements gave a raw MemoryError."""
    from interprim.datasets import load_demonstrations

    path = tmp_path / "huge.npz"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("demo_000.npy", _npy_header((5 * 10**12 // 2, 2)) + bytes(64))
        b = io.BytesIO()
        np.save(b, np.float64(0.01))
        z.writestr("dt.npy", b.getvalue())
    with pytest.raises(DataFileError, match="demo_000.*declares shape \\(2500000000000, 2\\).*over the limit"):
        load_demonstrations(str(path))
    path2 = tmp_path / "short.npz"
    with zipfile.ZipFile(path2, "w") as z:
        z.writestr("demo_000.npy", _npy_header((1000, 2)) + bytes(64))
        z.writestr("dt.npy", b.getvalue())
    with pytest.raises(DataFileError, match="truncated or damaged"):
        load_demonstrations(str(path2))
