"""The plugin tests run on the QGIS asked for: `make test` runs them on the system's QGIS and
again on QGIS 3.40 LTR (scripts/qgis-340) with GROUNDSIEVE_EXPECT_QGIS=3.40, both in Python
and through qgis_process."""
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
EXPECT = os.environ.get("GROUNDSIEVE_EXPECT_QGIS")


@pytest.mark.skipif(not EXPECT, reason="GROUNDSIEVE_EXPECT_QGIS is not set (set by `make test-qgis340`)")
def test_python_and_qgis_process_run_the_expected_qgis(qgis_app):
    from qgis.core import Qgis
    assert Qgis.version().startswith(EXPECT + "."), Qgis.version()
    out = subprocess.run([str(REPO / "scripts" / "qgis-process"), "--version"], capture_output=True, text=True,
                         timeout=300)
    assert f"QGIS {EXPECT}." in out.stdout, out.stdout + out.stderr
