"""Frames into, and outputs out of, an isolated denoiser's worker through one shared memory file.

Pickling a demo-sized frame (128×128, every buffer and variance: 2.75 MB) through a pipe costs a
copy into the pickle, many pipe round trips (each a context switch, slow on a busy machine) and a
copy out. Here the parent owns an anonymous memory file (``os.memfd_create``, Linux), handed to
the worker once at start-up (``pass_fds``); per call it writes every array at an aligned offset,
sends a small descriptor (names, dtypes, shapes, offsets, the frame's scalars and meta) over the
pipe, and the worker copies the arrays out into arrays of its own (a temporal plugin may keep
last frame's buffers, so they must not be overwritten by the next call). The worker writes a
numeric output into the file's output region and answers with its dtype and shape; the parent
copies it out. The file only grows (``ftruncate``), and the descriptor carries its size so the
worker re-maps when it changed.

Pitfalls:
    * The worker can write anywhere in the file at any time. The parent never reads input regions
      back, and copies the output out at once, so a plugin can only spoil its own result.
    * Only Linux has ``memfd_create``; elsewhere :func:`available` is False and the worker's pipe
      carries pickled frames instead (same contract, slower).
"""

from __future__ import annotations

import mmap
import os

import numpy as np

from denoisebench.dataset.frame import Frame

ALIGN = 64


def available() -> bool:
    return hasattr(os, "memfd_create")


def _aligned(n: int) -> int:
    return (n + ALIGN - 1) // ALIGN * ALIGN


class FrameChannel:
    """The parent's side: the memory file, mapped, growing on demand."""

    def __init__(self) -> None:
        self.fd = os.memfd_create("denoisebench-frames", 0)
        self.size = 0
        self._map: mmap.mmap | None = None

    def _ensure(self, size: int) -> None:
        if size <= self.size:
            return
        size = max(size, self.size * 2, 1 << 20)
        os.ftruncate(self.fd, size)
        if self._map is not None:
            self._map.close()
        self._map = mmap.mmap(self.fd, size)
        self.size = size

    def pack(self, frame, output_capacity: int) -> dict:
        """Write ``frame``'s arrays into the file; the descriptor the worker rebuilds it from."""
        entries, offset = [], 0
        groups = [("buffers", frame.buffers)] + ([("samples", frame.samples)] if frame.samples is not None else [])
        arrays = []
        for group, mapping in groups:
            for name, array in mapping.items():
                array = np.ascontiguousarray(array)
                entries.append((group, name, array.dtype.str, list(array.shape), offset))
                arrays.append((offset, array))
                offset = _aligned(offset + array.nbytes)
        output_offset = offset
        self._ensure(output_offset + output_capacity)
        for start, array in arrays:
            np.frombuffer(self._map, dtype=array.dtype, count=array.size, offset=start).reshape(array.shape)[...] = (
                array
            )
        return {
            "size": self.size,
            "entries": entries,
            "has_samples": frame.samples is not None,
            "spp": int(frame.spp),
            "scene": str(frame.scene),
            "index": int(frame.index),
            "meta": dict(frame.meta),
            "output_offset": output_offset,
            "output_capacity": output_capacity,
        }

    def read_output(self, descriptor: dict, dtype: np.dtype, shape: tuple[int, ...]) -> np.ndarray | None:
        """A copy of the output the worker wrote, or None when it would not fit the output region."""
        count = int(np.prod(shape, dtype=np.int64))
        if count * dtype.itemsize > descriptor["output_capacity"]:
            return None
        return (
            np.frombuffer(self._map, dtype=dtype, count=count, offset=descriptor["output_offset"]).reshape(shape).copy()
        )

    def close(self) -> None:
        if self._map is not None:
            self._map.close()
            self._map = None
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class WorkerView:
    """The worker's side: maps the parent's file (re-mapping when it grew)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.size = 0
        self._map: mmap.mmap | None = None

    def _mapped(self, size: int) -> mmap.mmap:
        if size != self.size:
            if self._map is not None:
                self._map.close()
            self._map = mmap.mmap(self.fd, size)
            self.size = size
        return self._map

    def unpack(self, descriptor: dict):
        """The frame the descriptor describes, as read-only arrays this process owns."""
        data = self._mapped(descriptor["size"])
        groups: dict[str, dict] = {"buffers": {}, "samples": {}}
        for group, name, dtype, shape, offset in descriptor["entries"]:
            dtype = np.dtype(dtype)
            count = int(np.prod(shape, dtype=np.int64))
            array = np.frombuffer(data, dtype=dtype, count=count, offset=offset).reshape(shape).copy()
            array.flags.writeable = False
            groups[group][name] = array
        return Frame(
            buffers=groups["buffers"],
            spp=descriptor["spp"],
            scene=descriptor["scene"],
            index=descriptor["index"],
            reference=None,
            samples=groups["samples"] if descriptor["has_samples"] else None,
            meta=descriptor["meta"],
        )

    def write_output(self, descriptor: dict, array: np.ndarray) -> bool:
        """Put ``array`` into the output region; False when it does not fit there."""
        if array.nbytes > descriptor["output_capacity"]:
            return False
        data = self._mapped(descriptor["size"])
        np.frombuffer(data, dtype=array.dtype, count=array.size, offset=descriptor["output_offset"]).reshape(
            array.shape
        )[...] = array
        return True
