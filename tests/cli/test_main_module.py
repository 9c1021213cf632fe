"""`python -m interprim` runs the command line (the signal handling of `interprim serve`:
tests/server/test_server_shutdown.py)."""

from __future__ import annotations

import subprocess
import sys


def test_python_m_interprim():
    r = subprocess.run([sys.executable, "-m", "interprim", "--version"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("interprim ")
