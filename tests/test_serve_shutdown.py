"""`interprim serve` stops cleanly on Ctrl-C (SIGINT) and SIGTERM: exit status 0, no traceback; `python -m interprim`."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest



@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    import interprim as ip
    from interprim.synthetic import two_agent_demos

    path = tmp_path_factory.mktemp("serve") / "pair.npz"
    ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=8, sigma2="auto").fit(two_agent_demos(6), dt=0.01).save(path)
    return path


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_serve_stops_cleanly_on_signal(model_file, sig):
    proc = subprocess.Popen([sys.executable, "-m", "interprim", "serve", str(model_file), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()  # the address line: the server is listening
        assert "WebSocket ws://127.0.0.1:" in line, (line, proc.stderr.read() if proc.poll() is not None else "")
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert f"interprim serve: stopped ({sig.name})" in out
    assert "Traceback" not in err and "Exception ignored" not in err, err


def test_python_m_interprim():
    r = subprocess.run([sys.executable, "-m", "interprim", "--version"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("interprim ")
