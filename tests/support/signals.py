"""Run a command line in a subprocess and send it a signal when a condition on its state holds.

:func:`signalled` starts ``python -m denoisebench.cli ARGS``, polls ``when(output_so_far)`` every
20 ms, sends ``signum`` as soon as it is true (or the process has ended: then nothing is sent) and
returns the exit status, the seconds from the signal to the exit, and the output.

The command starts with SIGINT and SIGTERM at their default disposition, as a terminal's
foreground command does. Pitfall: a test run started in the background of a non-interactive
shell (``make test &``, ``nohup``) ignores SIGINT and its children inherit that; the command then
rightly keeps ignoring it (:mod:`denoisebench.interrupts`) and runs to exit 0 with the signal sent.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True, kw_only=True)
class Signalled:
    returncode: int
    sent: bool  # False: the command ended before ``when`` held
    seconds_to_exit: float  # from the signal to the exit (0 when none was sent)
    output: str


def _default_signals() -> None:
    """In the child before exec: SIGINT and SIGTERM at their defaults, whatever the test run inherited."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def signalled(
    args: list[str],
    when: Callable[[str], bool],
    *,
    signum: int = signal.SIGINT,
    env: dict | None = None,
    cwd=None,
    timeout: float = 300.0,
) -> Signalled:
    proc = subprocess.Popen(
        [sys.executable, "-m", "denoisebench.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, **(env or {})},
        cwd=cwd,
        preexec_fn=_default_signals,
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True)
    reader.start()
    deadline = time.monotonic() + timeout
    sent_at = None
    while proc.poll() is None and time.monotonic() < deadline:
        if when("".join(lines)):
            sent_at = time.monotonic()
            proc.send_signal(signum)
            break
        time.sleep(0.02)
    try:
        proc.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    ended = time.monotonic()
    reader.join(timeout=5)
    return Signalled(
        returncode=proc.returncode,
        sent=sent_at is not None,
        seconds_to_exit=0.0 if sent_at is None else ended - sent_at,
        output="".join(lines),
    )
