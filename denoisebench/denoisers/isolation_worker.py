"""The worker process of :mod:`denoisebench.denoisers.isolation`: loads one denoiser and serves calls.

Started as ``python -m denoisebench.denoisers.isolation_worker FD [MEMFD]`` where FD is one end
of a socket pair (a :class:`multiprocessing.connection.Connection`) and MEMFD, where given, the
parent's shared memory file (:mod:`.shared_frames`). The parent is trusted, so its requests are
pickles: ``("load", spec, options, sys_path, rlimits)``, ``("reset",)``, ``("denoise", frame)`` (the frame
pickled), ``("denoise_shm", descriptor)`` (the frame in the shared file) and ``("close",)``. The worker is not trusted, so its replies are **never pickles**: one JSON
header (``send_bytes``), followed, for an array output, by the array's raw bytes. The parent
rebuilds arrays from a whitelisted dtype and a shape whose size must match the bytes, so nothing a
plugin does in here can run code in the parent.

``rlimits`` (None outside the sandbox) maps ``resource.RLIMIT_*`` names to values; the worker
sets them, soft and hard, on itself before it imports the plugin, so the plugin can lower them but
never raise them again (the sandbox leaves it no capabilities).

Everything a plugin raises, including ``SystemExit`` from ``sys.exit()``, is caught and reported
as a one-line error; ``os._exit()``, a crash or a signal ends the process, which the parent sees
as the pipe closing and reports with the exit status.
"""

from __future__ import annotations

import json
import sys
import time
from multiprocessing.connection import Connection

import numpy as np

from denoisebench.denoisers.protocol import describe
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.shared_frames import WorkerView
from denoisebench.errors import one_line
from denoisebench.plugin_worker import set_rlimits


def _reply(conn, header: dict, payload: bytes | memoryview | None = None) -> None:
    header["payload"] = payload is not None
    conn.send_bytes(json.dumps(header).encode("utf-8"))
    if payload is not None:
        conn.send_bytes(payload)


def _load(conn, spec: str, options: dict, sys_path: list[str], rlimits: dict[str, int] | None = None):

    set_rlimits(rlimits)
    sys.path[:] = list(sys_path)
    try:
        denoiser = load_denoiser(spec, **options)
        info = describe(denoiser, fallback_name=spec)
    except BaseException as error:  # noqa: BLE001 - every failure goes back as one line
        _reply(
            conn,
            {
                "ok": False,
                "error_type": type(error).__name__,
                "error": str(error).strip().splitlines()[0] if str(error).strip() else one_line(error),
            },
        )
        return None
    _reply(
        conn,
        {
            "ok": True,
            "name": str(info.name),
            "needs": sorted(str(n) for n in info.needs),
            "temporal": bool(info.temporal),
            "trained_scenes": sorted(info.trained_scenes),
        },
    )
    return denoiser


def _denoise(conn, denoiser, frame, view=None, descriptor=None) -> None:

    for array in list(frame.buffers.values()) + list((frame.samples or {}).values()):
        array.flags.writeable = False  # the same contract as in-process; these are this process's copies
    started = time.perf_counter()
    try:
        output = denoiser.denoise(frame)
    except BaseException as error:  # noqa: BLE001 - SystemExit included: contained and reported
        _reply(conn, {"ok": False, "error": f"raised {one_line(error)}", "seconds": time.perf_counter() - started})
        return
    seconds = time.perf_counter() - started
    if not isinstance(output, np.ndarray):
        _reply(conn, {"ok": True, "seconds": seconds, "kind": "other", "type": type(output).__name__})
        return
    if output.dtype.kind not in "fiub" or output.dtype.hasobject:
        _reply(conn, {"ok": True, "seconds": seconds, "kind": "other", "type": f"ndarray of dtype {output.dtype}"})
        return
    plain = np.ascontiguousarray(output)
    header = {"ok": True, "seconds": seconds, "kind": "array", "dtype": plain.dtype.str, "shape": list(plain.shape)}
    if view is not None and view.write_output(descriptor, plain):
        _reply(conn, {**header, "in_shm": True})
        return
    _reply(conn, header, memoryview(plain).cast("B") if plain.size else b"")


def main(fd: int, memfd: int | None = None) -> None:

    conn = Connection(fd)
    view = None
    if memfd is not None:
        view = WorkerView(memfd)
    denoiser = None
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return  # the parent has gone
        op = message[0]
        if op == "close":
            return
        if op == "load":
            denoiser = _load(conn, *message[1:])
        elif op == "reset":
            reset = getattr(denoiser, "reset", None)
            try:
                if callable(reset):
                    reset()
            except BaseException as error:  # noqa: BLE001
                _reply(conn, {"ok": False, "error": f"reset() raised {one_line(error)}"})
                continue
            _reply(conn, {"ok": True})
        elif op == "denoise":
            _denoise(conn, denoiser, message[1])
        elif op == "denoise_shm" and view is not None:
            _denoise(conn, denoiser, view.unpack(message[1]), view, message[1])
        else:
            _reply(conn, {"ok": False, "error": f"unknown request {op!r}"})


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else None)
