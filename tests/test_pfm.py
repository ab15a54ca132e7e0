import numpy as np
import pytest

from stablemarks.errors import ImageError
from stablemarks.io.pfm import read_pfm, write_pfm


def test_round_trip_with_invalid_pixels(tmp_path):
    rng = np.random.default_rng(0)
    d = rng.uniform(0, 64, (7, 11)).astype(np.float32)
    d[2, 3] = np.nan
    d[4, 5] = np.inf
    p = write_pfm(tmp_path / "d.pfm", d)
    back = read_pfm(p)
    assert back.shape == (7, 11) and back.dtype == np.float32
    assert np.isinf(back[2, 3]) and np.isinf(back[4, 5])
    ok = np.isfinite(d)
    np.testing.assert_array_equal(back[ok], d[ok])
    assert p.read_bytes().startswith(b"Pf\n11 7\n-1.0\n")


def test_big_endian_and_bottom_to_top_rows(tmp_path):
    rows = np.array([[1.0, 2.0], [3.0, 4.0]], dtype=">f4")  # stored bottom row first
    (tmp_path / "b.pfm").write_bytes(b"Pf\n2 2\n1.0\n" + rows.tobytes())
    np.testing.assert_array_equal(read_pfm(tmp_path / "b.pfm"), [[3.0, 4.0], [1.0, 2.0]])


@pytest.mark.parametrize(
    "content,match",
    [(b"P6\n2 2\n255\n", "not a PFM"), (b"PF\n2 2\n-1.0\n" + bytes(48), "colour PFM"),
     (b"Pf\n2 x\n-1.0\n", "width, height"), (b"Pf\n2 2\n-1.0\n" + bytes(8), "expected 16 bytes")],
)
def test_malformed_files(tmp_path, content, match):
    (tmp_path / "x.pfm").write_bytes(content)
    with pytest.raises(ImageError, match=match):
        read_pfm(tmp_path / "x.pfm")
    with pytest.raises(ImageError, match="cannot read"):
        read_pfm(tmp_path / "missing.pfm")
