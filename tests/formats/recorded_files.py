"""The real recorded files beside the checkout: the multibeam files of ``../shared/data/multibeam``
(the folder of the ``multibeam`` fixture) and the SonTek run the malformed-file tests cut down."""

from __future__ import annotations

from pathlib import Path

#: ``../shared/data`` beside the checkout, as in tests/conftest.py
SHARED_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
XTF = "r2sonic_2026_qinsy.xtf"
GSF = "GSF3_08_test_file.gsf"
XTF_CRS = "EPSG:32610"  # UTM 10N: San Francisco Bay
GSF_CRS = "EPSG:32658"  # UTM 58N: 8.7 N, 167.5 E (Kwajalein, Marshall Islands)
LONG_RUN = "20250327110103.sum"


def _write(tmp_path, caputh, edit, name="run.sum"):
    lines = (caputh / LONG_RUN).read_bytes().decode("latin-1").split("\r")[:20]
    lines = edit(lines)
    path = tmp_path / name
    path.write_bytes("\r".join(lines).encode("latin-1"))
    return path
