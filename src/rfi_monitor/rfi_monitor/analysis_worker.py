"""The ridge analysis of a block on a second core (issue 14 item 6, live streams).

Pure module (no ROS). The "stft" estimator's ridge analysis (``ridge.analyse``: the short-time spectrum of the
block, its noise levels, the ridge, the period and the sweep law) is about half of a block's work, and it is a
pure function of the block's samples, the frame length and the parameters. ``AnalysisWorker`` runs it in a child
process while the calling process does the rest of the block (the Welch PSD and features, the evidence over
blocks), so a block costs about the longer of the two halves instead of their sum. (The Python glue of either
half holds the GIL, so a thread does not run them side by side: measured, docs/rfi_monitor/speed.md.)

Protocol: one block at a time. ``submit`` copies the samples into a memory-mapped file both processes map (in
/dev/shm where it exists: no disk I/O) and sends a small message down a socket; ``collect`` waits for the
answer (a ``ridge.RidgeResult``); ``cancel`` drops an answer that is no longer wanted (it is still read, so that
the next answer is the next block's). Results are identical to computing them in the calling process: the same
function on the same bytes in the same interpreter and libraries (tested to the bit, test_analysis_worker.py),
so the estimates do not depend on whether a worker is used, only the speed does. A worker that fails (an
exception in the child, no answer within ``reply_timeout_s``, the child gone) is shut down and counted
(``failures``); the caller then analyses the block itself, so nothing is lost and nothing changes but speed.

The child is a fresh interpreter (``python -m rfi_monitor.analysis_worker``) with the parent's module search
path: never a fork of a process that runs middleware threads, and not multiprocessing's "spawn", which imports
the parent's main script again.

Example
-------
>>> import numpy as np
>>> from rfi_monitor.ridge import RidgeParams, analyse
>>> x = np.random.default_rng(0).standard_normal(38192)
>>> with AnalysisWorker() as w:                          # doctest: +SKIP
...     w.submit(x, False, 38.192e6, RidgeParams(), 128)
...     rr = w.collect()
>>> rr == analyse(x, False, 38.192e6, RidgeParams(), 128)   # doctest: +SKIP
True
"""

from __future__ import annotations

import mmap
import os
import socket
import subprocess
import sys
import tempfile
import traceback
from multiprocessing.connection import Connection

import numpy as np

from rfi_monitor.ridge import RidgeParams, RidgeResult, analyse, choose_frame_length

START_TIMEOUT_S = 120.0
"""How long the child may take to start (imports, and the compiled functions compiled or loaded from the cache:
about 10 s of CPU the first time after an install), s."""
REPLY_TIMEOUT_S = 5.0
"""How long ``collect`` waits for one block's analysis before the worker is declared failed, s (a block takes
about 0.5 ms at 38.192 MS/s)."""


def _shm_dir() -> str:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


def _job(x: np.ndarray, cplx: bool, fs: float, par: RidgeParams, frame_length: int, tail: int,
         fine_hook: bool = True) -> RidgeResult:
    """The worker's job (also what the caller computes without a worker): ``ridge.analyse`` of x, or of its last
    ``tail`` samples (0 < tail < x.size), at ``frame_length``, or at the length ``choose_frame_length`` picks on
    the whole of x when frame_length is 0 (the result's ``frame_length`` says which)."""
    L = frame_length if frame_length > 0 else choose_frame_length(x, cplx, par)
    part = x[-tail:] if 0 < tail < x.size else x
    return analyse(part, cplx, fs, par, L, fine_hook=fine_hook)


def _serve(conn: Connection, path: str) -> None:
    """The child: answer ("ridge", n, dtype, cplx, fs, params, frame_length, size) with ``ridge.analyse`` of the
    first n values of the shared file, until None or the socket closes."""
    fd = os.open(path, os.O_RDONLY)
    mm: mmap.mmap | None = None
    size = 0
    par = RidgeParams()
    try:
        # warm up: the compiled functions compiled or loaded now, not on the first block
        noise = np.random.default_rng(0).standard_normal(8192)
        analyse(noise, False, 4.0e6, RidgeParams())
        analyse(noise[:4096] + 1j * noise[4096:], True, 4.0e6, RidgeParams())
        conn.send(("ready", os.getpid()))
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                return
            if msg is None:
                return
            _, n, dtype, cplx, fs, new_par, L, tail, need, fine_hook = msg
            if new_par is not None:
                par = new_par                       # sent when it changes, not with every block
            try:
                if mm is None or size < need:
                    if mm is not None:
                        mm.close()
                    mm = mmap.mmap(fd, need, prot=mmap.PROT_READ)
                    size = need
                x = np.frombuffer(mm, dtype=np.dtype(dtype), count=int(n))
                rr = _job(x, bool(cplx), float(fs), par, int(L), int(tail), bool(fine_hook))
                del x
                conn.send(("ok", rr))
            except Exception:                       # noqa: BLE001 - reported to the parent, which falls back
                conn.send(("error", traceback.format_exc(limit=5)))
    finally:
        if mm is not None:
            mm.close()
        os.close(fd)


class AnalysisWorker:
    """A child process that runs ``ridge.analyse`` (module docstring).

    Args:
        reply_timeout_s: longest wait for one block's answer, s.
        start_timeout_s: longest wait for the child to start, s.

    Raises:
        RuntimeError: the child did not start (the caller then works without it).
    """

    def __init__(self, reply_timeout_s: float = REPLY_TIMEOUT_S, start_timeout_s: float = START_TIMEOUT_S) -> None:
        self.reply_timeout_s = float(reply_timeout_s)
        self.failures = 0
        """Workers declared failed (then shut down) since construction."""
        self.jobs = 0
        """Blocks the child analysed and the caller used."""
        self.last_error = ""
        self._pending = False
        self._par = RidgeParams()                   # the child's parameters (it starts with the defaults)
        fd, self._path = tempfile.mkstemp(prefix="rfi_monitor_analysis_", dir=_shm_dir())
        self._fd = fd
        self._size = 0
        self._mm: mmap.mmap | None = None
        self._grow(1 << 20)
        # a fresh interpreter (never a fork of a process that runs middleware threads; not multiprocessing's
        # spawn, which imports the parent's main script again), with the parent's module search path
        parent_sock, child_sock = socket.socketpair()
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p and os.path.isdir(p))
        self._proc: subprocess.Popen | None = None
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "rfi_monitor.analysis_worker", self._path, str(child_sock.fileno())],
                pass_fds=(child_sock.fileno(),), env=env, stdin=subprocess.DEVNULL)
        finally:
            child_sock.close()
        self._conn = Connection(parent_sock.detach())
        ok = False
        try:
            if self._conn.poll(start_timeout_s):
                msg = self._conn.recv()
                ok = isinstance(msg, tuple) and msg[0] == "ready"
        except (EOFError, OSError):
            ok = False
        if not ok:
            self.close()
            raise RuntimeError("the analysis worker process did not start")
        # both processes hold the file open now: its name can go, so nothing is left behind in /dev/shm even if
        # this process is killed
        try:
            os.unlink(self._path)
        except OSError:
            pass

    @property
    def alive(self) -> bool:
        """True while the child can take blocks."""
        return self._proc is not None and self._mm is not None

    def _grow(self, nbytes: int) -> None:
        size = max(nbytes, 2 * self._size)
        size = (size + mmap.PAGESIZE - 1) // mmap.PAGESIZE * mmap.PAGESIZE
        os.ftruncate(self._fd, size)
        if self._mm is not None:
            self._mm.close()
        self._mm = mmap.mmap(self._fd, size)
        self._size = size

    def submit(self, x: np.ndarray, cplx: bool, fs: float, par: RidgeParams, frame_length: int,
               tail: int = 0, fine_hook: bool = True) -> bool:
        """Start ``ridge.analyse`` of x (finite, float64 or complex128, shape (n,)), or of its last ``tail`` samples
        (0 < tail < n), at ``frame_length``, or at the length ``ridge.choose_frame_length`` picks on the whole of x
        when frame_length is 0 (the answer's ``frame_length`` says which), with or without its sample-resolution hook
        test (``fine_hook``). False if the worker is not alive or still busy (the caller analyses the block
        itself)."""
        if not self.alive or self._pending:
            return False
        x = np.ascontiguousarray(x)
        try:
            if x.nbytes > self._size:
                self._grow(x.nbytes)
            assert self._mm is not None
            np.copyto(np.frombuffer(self._mm, dtype=x.dtype, count=x.size), x)
            self._conn.send(("ridge", x.size, x.dtype.str, bool(cplx), float(fs), par if par != self._par else None,
                             int(frame_length), int(tail), self._size, bool(fine_hook)))
            self._par = par
        except (OSError, ValueError, EOFError) as err:
            self._fail(f"submit: {type(err).__name__}: {err}")
            return False
        self._pending = True
        return True

    def collect(self) -> RidgeResult | None:
        """The analysis of the block submitted last, or None (nothing pending, or the worker failed)."""
        st = self._receive()
        if st is not None:
            self.jobs += 1
        return st

    def cancel(self) -> None:
        """Drop the pending answer (read and discarded, so that the next answer is the next block's)."""
        self._receive()

    def _receive(self) -> RidgeResult | None:
        if not self._pending:
            return None
        self._pending = False
        try:
            if not self._conn.poll(self.reply_timeout_s):
                self._fail(f"no answer within {self.reply_timeout_s:g} s")
                return None
            kind, payload = self._conn.recv()
        except (EOFError, OSError) as err:
            self._fail(f"collect: {type(err).__name__}: {err}")
            return None
        if kind != "ok":
            self._fail(str(payload))
            return None
        return payload

    def _fail(self, why: str) -> None:
        self.failures += 1
        self.last_error = why
        self.close()

    def close(self) -> None:
        """Stop the child and release the shared file (idempotent)."""
        proc, self._proc = getattr(self, "_proc", None), None
        conn = getattr(self, "_conn", None)
        if proc is not None:
            try:
                if conn is not None:
                    conn.send(None)
            except (OSError, ValueError, EOFError):
                pass
            try:
                proc.wait(2.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(2.0)
        if conn is not None:
            try:
                conn.close()
            except OSError:
                pass
        mm = getattr(self, "_mm", None)
        if mm is not None:
            mm.close()
        self._mm = None
        if getattr(self, "_fd", -1) >= 0:
            os.close(self._fd)
            self._fd = -1
            try:
                os.unlink(self._path)
            except OSError:
                pass
        self._pending = False

    def __enter__(self) -> AnalysisWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:                           # noqa: BLE001 - interpreter shutdown
            pass


def main(argv: list[str] | None = None) -> int:
    """The child's entry point: ``python -m rfi_monitor.analysis_worker PATH FD`` (started by AnalysisWorker;
    not a user command)."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m rfi_monitor.analysis_worker SHARED_FILE SOCKET_FD (started by AnalysisWorker)",
              file=sys.stderr)
        return 2
    _serve(Connection(int(args[1])), args[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
