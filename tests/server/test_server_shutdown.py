"""``interprim serve`` stops cleanly on SIGINT (Ctrl-C) and SIGTERM.

A real ``interprim serve`` subprocess on a loopback port, with a client streaming frames when the signal
arrives (sent to the server's whole process group, as a terminal's Ctrl-C or systemd's stop do): the
client's frames received so far are answered, then it is closed with 1001 and a reason naming the last
frame answered; worker processes are stopped; the exit status is 130 after SIGINT and 0 after SIGTERM;
stderr has no traceback and no warning.  Waits on the server's "open http://..." line and on the client's
close, not on sleeps.
"""

from __future__ import annotations

import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading

import pytest

pytest.importorskip("websockets")
if not hasattr(os, "killpg"):  # pragma: no cover - POSIX signals
    pytest.skip("POSIX signals and process groups", allow_module_level=True)

from _server_support import connect, covered, frame_msg  # noqa: E402
from websockets.exceptions import ConnectionClosed  # noqa: E402

import interprim as ip  # noqa: E402
from interprim.synthetic import two_agent_demos  # noqa: E402

START_TIMEOUT = 300  # s: a fresh interpreter imports interprim and loads the compiled kernels (slow when busy)
BAD_STDERR = ("Traceback", "Warning", "WARNING", "ERROR", "Exception", "never awaited", "interrupted")


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    train = two_agent_demos(12, seed=0, frames=100)
    path = tmp_path_factory.mktemp("serve") / "pair.npz"
    ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=8).fit(train, dt=0.01).save(str(path))
    return path


def _lines(stream, q):
    for line in iter(stream.readline, ""):
        q.put(line)
    q.put(None)


class Served:
    """``interprim serve MODEL --port 0 ...`` in its own process group; stdout/stderr read by threads."""

    def __init__(self, model_file, *extra):
        code = "import sys; from interprim.cli import main; sys.exit(main())"
        self.proc = subprocess.Popen([sys.executable, "-c", code, "serve", str(model_file), "--port", "0", *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     start_new_session=True)
        self.out, self.err = queue.Queue(), queue.Queue()
        for stream, q in ((self.proc.stdout, self.out), (self.proc.stderr, self.err)):
            threading.Thread(target=_lines, args=(stream, q), daemon=True).start()
        self.stderr = []

    def wait_listening(self) -> str:
        """The WebSocket URL, from the line the server prints once it listens."""
        while True:
            line = self.out.get(timeout=START_TIMEOUT)
            assert line is not None, f"the server exited before listening: {self.drain_stderr()}"
            m = re.search(r"open (http://\S+)", line)
            if m:
                return m.group(1).replace("http://", "ws://") + "ws"

    def drain_stderr(self) -> str:
        while True:
            try:
                line = self.err.get(timeout=0 if self.proc.poll() is None else 30)
            except queue.Empty:
                break
            if line is None:
                break
            self.stderr.append(line)
        return "".join(self.stderr)

    def kill(self):
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(30)


def _stream_until_closed(url, sig, served, n_before_signal=30):
    """Stream frames (a sender thread) and read the replies; after ``n_before_signal`` replies signal the
    server's process group.  Returns (replies, close code, close reason)."""
    ws = connect(url)
    ws.send(json.dumps({"type": "hello"}))
    assert json.loads(ws.recv(timeout=30))["type"] == "welcome"
    ws.send(json.dumps({"type": "open", "model": "pair", "points": 10}))
    assert json.loads(ws.recv(timeout=30))["type"] == "opened"
    done = threading.Event()

    def sender():
        k = 0
        try:
            while not done.wait(0.003):  # < 333 frames/s: under the rate limit (500/s), fast enough to be mid-stream
                k += 1
                ws.send(frame_msg([0.01 * (k % 100), -0.01 * (k % 100)]))
        except (ConnectionClosed, OSError):
            pass

    thread = threading.Thread(target=sender, daemon=True)
    thread.start()
    replies, code, reason = [], None, ""
    try:
        while True:
            replies.append(json.loads(ws.recv(timeout=60)))
            if len(replies) == n_before_signal:
                os.killpg(served.proc.pid, sig)  # mid-stream
    except ConnectionClosed as exc:
        if exc.rcvd is not None:
            code, reason = exc.rcvd.code, exc.rcvd.reason
    finally:
        done.set()
        thread.join(30)
        ws.close()
    return replies, code, reason


@pytest.mark.slow  # starts `interprim serve` in a subprocess per case
@pytest.mark.parametrize("mode,sig", [
    ("inline", signal.SIGINT), ("inline", signal.SIGTERM),
    ("processes", signal.SIGINT), ("processes", signal.SIGTERM),
    ("threads", signal.SIGTERM),
])
def test_serve_stops_cleanly_on_a_signal(model_file, mode, sig):
    extra = {"inline": [], "processes": ["--processes", "2"], "threads": ["--workers", "2"]}[mode]
    served = Served(model_file, *extra)
    try:
        url = served.wait_listening()
        replies, code, reason = _stream_until_closed(url, sig, served)
        rc = served.proc.wait(120)
    finally:
        served.kill()
    err = served.drain_stderr()
    # the client was told, and every frame the server took was answered (in order, none twice)
    assert code == 1001, (code, reason, err)
    m = re.fullmatch(rf"server shutting down \({sig.name}\); frames up to seq (\d+) answered", reason)
    assert m, reason
    last = int(m.group(1))
    assert last >= 30 and [q for r in replies for q in covered(r)] == list(range(1, last + 1))
    assert all(r["type"] == "prediction" for r in replies)
    # exit status and a clean stderr
    assert rc == (130 if sig == signal.SIGINT else 0), err
    assert f"{sig.name}: shutting down" in err and "stopped (" in err
    bad = [line for line in err.splitlines() if any(b in line for b in BAD_STDERR)]
    assert not bad, err
    if mode == "processes":  # the workers were stopped and joined (not left running as orphans)
        pids = [int(p) for p in re.search(r"pids \[([\d, ]+)\]", err).group(1).split(",")]
        assert len(pids) == 2 and "worker processes stopped" in err
        for pid in pids:
            with pytest.raises(ProcessLookupError):
                os.kill(pid, 0)
