"""SIGINT and SIGTERM: how a command stops within :data:`GRACE_SECONDS`, exit 130, nothing half-written.

:func:`handling_signals` (the CLI wraps every command in it) installs one handler for both signals.
The handler records the request (:func:`requested`), starts a watchdog and raises
``KeyboardInterrupt`` where the main thread is, so that plain Python code unwinds at once and the
CLI maps it to exit 130. Two things can keep that exception from arriving, and the module covers
both:

* **It is swallowed or renamed.** Dr.Jit calls Python code (a ``dr.freeze`` function) from C++; an
  exception raised in there comes back as ``RuntimeError`` (``FlatVariables::assign()``) or not at all
  (the frozen function is run again unfrozen). Code that contains failures (a frame job, a denoiser
  call, a plugin worker's exit) must therefore ask :func:`raise_if_requested` before it records a
  failure or a result: an interrupted job is neither.
* **It never arrives.** Python runs a signal handler only between bytecodes of the main thread; a
  long C++ call (a cold-cache LLVM compile: tens of seconds) delays it. The watchdog thread (the
  C++ calls release the GIL) then ends the process with ``os._exit(130)`` after
  :data:`GRACE_SECONDS`. That is safe because every file a command keeps is written whole or not at
  all (a temporary file renamed into place; SQLite transactions), exactly as after a kill; the
  writers remove stale temporaries on the next run, which resumes.

Pitfalls: a signal that was ignored when the process started (``nohup``-style, or a background job
of a non-interactive shell for SIGINT) stays ignored, as Python itself does. The handlers are
installed only from the main thread and restored when the block ends (tests run commands in-process);
only a real signal starts the watchdog, which then also bounds the interpreter's exit.
Worker processes of plugins ignore SIGINT (a Ctrl-C reaches the whole process group): their parent
stops them, and a worker's death during an interrupt is not the plugin's failure.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator

#: Seconds between a signal and the forced exit when the main thread has not unwound by then.
GRACE_SECONDS = 0.75
#: Exit status of an interrupted command (128 + SIGINT, the shell's convention).
EXIT_INTERRUPTED = 130

_requested = threading.Event()


def requested() -> bool:
    """True once SIGINT or SIGTERM arrived in a :func:`handling_signals` block."""
    return _requested.is_set()


def raise_if_requested() -> None:
    """``KeyboardInterrupt`` where a signal arrived (an exception caught on its way may be its echo)."""
    if _requested.is_set():
        raise KeyboardInterrupt


_stop_watchdog = threading.Event()


def _watchdog(grace: float) -> None:
    if _stop_watchdog.wait(grace):
        return
    try:
        sys.stderr.write("interrupted\n")
        sys.stderr.flush()
    finally:
        os._exit(EXIT_INTERRUPTED)


def exit_interrupted() -> None:
    """End the process with :data:`EXIT_INTERRUPTED` now: streams flushed and exit handlers run (the
    watchdog still bounding them), then ``os._exit``. The interpreter's own shutdown is skipped: it
    took 5 s after a benchmark (library teardown) and no thread can bound it once it has begun."""
    try:
        atexit._run_exitfuncs()
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
    finally:
        os._exit(EXIT_INTERRUPTED)


def _handler(signum, frame) -> None:
    first = not _requested.is_set()
    _requested.set()
    if first:
        threading.Thread(target=_watchdog, args=(GRACE_SECONDS,), name="interrupt-watchdog", daemon=True).start()
    raise KeyboardInterrupt


@contextlib.contextmanager
def handling_signals() -> Iterator[None]:
    """Within the block SIGINT and SIGTERM raise ``KeyboardInterrupt`` and end the process within
    :data:`GRACE_SECONDS` at the latest (module docstring); the previous handlers come back after it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        current = signal.getsignal(signum)
        if current is signal.SIG_IGN:
            continue  # ignored when the process started: the parent asked for that
        previous[signum] = current
        signal.signal(signum, _handler)
    _requested.clear()
    _stop_watchdog.clear()
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if not _requested.is_set():
            _stop_watchdog.set()
        # after a signal the watchdog stays: it also bounds the interpreter's exit (atexit handlers,
        # threads' joins), which took seconds after a benchmark
