"""A plugin's worker process: loads one plugin and serves its protocol's requests.

Started by :class:`~denoisebench.plugins.process.WorkerProcess` as
``python -m denoisebench.plugins.worker FD SERVICE [ARG ...]``: FD is one end of a socket pair (a
:class:`multiprocessing.connection.Connection`), SERVICE (``"module:Class"``, named by the trusted
parent) the protocol's worker side, constructed as ``Class(conn, *ARGS)``; it has

``load(spec, options) -> dict``
    import and construct the plugin; the dict (JSON) is what the parent learns of it (name, needs, ...).
``handle(message) -> None``
    serve one request of the protocol (``message[0]`` names it), answering with :func:`reply`.

This module does what every plugin kind shares: the first request ``("load", spec, options, sys_path,
rlimits)`` sets the :func:`~denoisebench.plugins.process.set_rlimits` on this process (soft and hard,
before the plugin is imported, so the plugin can lower them but never raise them again), takes the
harness's ``sys.path``, and answers ``{"ok": true, ...}`` or the failure; ``("close",)`` or a closed
pipe ends the loop.

The parent is trusted, so its requests are pickles. The worker is not trusted, so its replies are
**never pickles**: one JSON header (``send_bytes``), followed, where the header says ``payload``, by
raw bytes. Everything a plugin raises, ``SystemExit`` included, goes back as :func:`failure`: one
line (``error``, with ``error_type``) and the plugin's traceback (``traceback``, at most
:data:`TRACEBACK_CHARS` characters); ``os._exit()``, a crash or a signal ends the process, which the
parent reports with the exit status.
"""

from __future__ import annotations

import importlib
import json
import signal
import sys
import traceback
from multiprocessing.connection import Connection

from denoisebench.errors import one_line
from denoisebench.plugins.process import set_rlimits

#: The most characters of a plugin's traceback that travel back (its last ones: where it raised).
TRACEBACK_CHARS = 8000


def reply(conn, header: dict, payload: bytes | memoryview | None = None) -> None:
    """Send ``header`` as JSON, then ``payload``'s bytes where given (the header says which)."""
    header["payload"] = payload is not None
    conn.send_bytes(json.dumps(header).encode("utf-8"))
    if payload is not None:
        conn.send_bytes(payload)


def failure(error: BaseException, prefix: str = "") -> dict:
    """A failed request's header fields: ``error`` (one line), ``error_type`` and ``traceback``."""
    text = "".join(traceback.format_exception(type(error), error, error.__traceback__))
    return {
        "error_type": type(error).__name__,
        "error": f"{prefix}{one_line(error)}",
        "traceback": text[-TRACEBACK_CHARS:],
    }


def _service(path: str, conn, args: list[str]):
    module, _, attr = path.partition(":")
    return getattr(importlib.import_module(module), attr)(conn, *args)


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C reaches the process group: the parent stops us
    conn = Connection(int(argv[0]))
    service = _service(argv[1], conn, argv[2:])
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return 0  # the parent has gone
        op = message[0]
        if op == "close":
            return 0
        if op == "load":
            _, spec, options, sys_path, rlimits = message
            set_rlimits(rlimits)
            sys.path[:] = list(sys_path)
            try:
                info = service.load(spec, options)
            except BaseException as error:  # noqa: BLE001 - every failure goes back, SystemExit included
                reply(conn, {"ok": False, **failure(error)})
                continue
            reply(conn, {"ok": True, **info})
        else:
            service.handle(message)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
