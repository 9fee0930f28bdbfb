"""The bubblewrap command that confines a plugin's worker (an isolated denoiser's or sampler's).

:func:`command` turns the worker's argv into a ``bwrap`` (Debian package ``bubblewrap``, the
sandbox under Flatpak) command line. Each choice, and why:

Namespaces and privileges
    ``--unshare-all --unshare-user``: own user, mount, PID, network, IPC, UTS and cgroup
    namespaces (``--unshare-all`` only *tries* the user namespace; as root it would skip it).
    ``--disable-userns``: the worker cannot create user namespaces of its own (no way back to
    capabilities inside a nested one). ``--cap-drop ALL``: no capabilities, also when the harness
    runs as root. ``--uid/--gid 65534``: the worker does not look like root to itself.
Network
    Its own network namespace holds only its own loopback: no TCP/UDP anywhere, and the host's
    127.0.0.1 is not this one (a connect there is refused); the host's abstract UNIX sockets are
    out of reach too.
Processes
    Its own PID namespace: the sandbox's init (bwrap, PID 1) exits when the worker exits, and the
    kernel then kills every process left in the namespace, so no descendant outlives the worker.
    ``--die-with-parent``: when the harness (or the parent's kill after a time limit) ends the
    outer bwrap, the sandbox goes with it. ``/proc`` is the namespace's own: ``/proc/<ppid>`` is
    the sandbox's init, whose command line is ``bwrap --args FD ...`` (the mount list is handed
    over through a file descriptor, :func:`command`'s ``args`` bytes, not on the command line).
    ``--new-session``: no ``TIOCSTI`` into the harness's terminal.
Files
    Nothing of the host is visible but what is bound read-only: the system (``/usr`` and the
    ``/bin``, ``/lib*`` links, the few ``/etc`` files the dynamic loader and Python read), the
    Python installation (``sys.prefix``, ``sys.base_prefix``), every entry of the harness's
    ``sys.path`` (where plugins are imported from), the plugin's own file's folder, and any
    file or folder an option names (a checkpoint). Protected paths (:func:`protect`: the dataset,
    the results store, the report folder) are covered by an empty read-only tmpfs (a folder) or
    ``/dev/null`` (a file) where they lie inside one of those, so a ``sys.path`` entry above them
    exposes nothing. ``/tmp`` is a private tmpfs of ``scratch_bytes`` (``--size``), the worker's
    working folder, ``HOME`` and ``TMPDIR``: the only writable place, gone with the worker.
    ``/dev`` is a minimal one (null, zero, random, urandom, pts), read-only, with a ``/dev/shm``
    tmpfs of ``scratch_bytes`` of its own; NVIDIA device nodes are bound where they exist so that
    a CUDA plugin keeps its GPU. The root that bwrap builds (a tmpfs holding the folders that lead
    to the bound paths) is remounted read-only last: without that, a plugin could write into it,
    and into ``/dev``, as much memory as it likes.
Environment
    ``--clearenv``; then ``PATH``, ``HOME``/``TMPDIR`` (the scratch folder), ``LANG`` and the
    thread-count variables of :data:`ENV_KEEP` where the harness has them: nothing that names a
    path of the host.

Pitfalls
--------
* Names of protected paths are visible in ``/proc/self/mountinfo`` (they are mount points);
  their contents are not.
* A ``sys.path`` entry that is ``/tmp`` or ``/`` is not bound (it would hide the scratch folder
  and expose all of it): a plugin module lying directly there does not import in the sandbox.
* What ``sys.path`` holds is readable: a harness started by ``python -m`` or pytest has its
  working folder there. The console scripts (``run-benchmark``) have only the environment.
* Resource limits (address space, processes, file size, open files) are set by the worker on
  itself before it imports the plugin (:func:`denoisebench.plugins.process.set_rlimits`); the kernel does not enforce
  ``RLIMIT_NPROC`` for a worker whose user is root outside the sandbox, so the parent also counts
  the sandbox's tasks (:class:`denoisebench.plugins.process.WorkerProcess`).
* bwrap reports a worker killed by signal N as exit status 128 + N (:func:`exit_signal`).
"""

from __future__ import annotations

import functools
import glob
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterable

import denoisebench

#: The worker's private writable folder (a tmpfs) inside the sandbox.
SCRATCH = "/tmp"
#: Unprivileged ids the worker runs as inside its user namespace.
SANDBOX_ID = "65534"
#: Host files under /etc that the dynamic loader, libc and Python read.
ETC_FILES = (
    "/etc/ld.so.cache",
    "/etc/ld.so.conf",
    "/etc/ld.so.conf.d",
    "/etc/alternatives",
    "/etc/localtime",
    "/etc/passwd",
    "/etc/group",
    "/etc/nsswitch.conf",
)
#: Top-level system folders; each is bound read-only, or recreated as the link it is (merged /usr).
SYSTEM_DIRS = ("/usr", "/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32", "/opt")
#: Environment variables passed through (none names a path).
ENV_KEEP = (
    "LANG",
    "LC_ALL",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "CUDA_VISIBLE_DEVICES",
)

_PROTECTED: set[str] = set()


def protect(*paths: str | os.PathLike | None) -> None:
    """Paths no sandboxed worker of this process may see (dataset, results store, report folder).

    The command adds the store's ``-wal``/``-shm`` files beside a protected file by itself.
    """
    for path in paths:
        if path:
            _PROTECTED.add(os.path.realpath(os.fspath(path)))


def protected() -> frozenset[str]:
    return frozenset(_PROTECTED)


def bwrap_path() -> str | None:
    return shutil.which("bwrap")


@functools.lru_cache(maxsize=1)
def version() -> str | None:
    """``bubblewrap 0.8.0`` (what the run records), or None without bwrap."""
    path = bwrap_path()
    if path is None:
        return None
    try:
        text = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return text or "bubblewrap"


@functools.lru_cache(maxsize=1)
def unavailable_reason() -> str | None:
    """None where a sandbox starts here; else why not, in one line (probed once per process)."""
    path = bwrap_path()
    if path is None:
        return "bubblewrap (bwrap) is not installed (Debian: apt-get install bubblewrap; `make setup` does it as root)"
    probe = command([sys.executable, "-c", "pass"], readable=readable_paths("", {}), scratch_bytes=1 << 20)
    try:
        done = subprocess.run(
            probe.argv, pass_fds=(probe.args_fd,), capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL
        )
    except (OSError, subprocess.SubprocessError) as error:
        return f"bwrap could not be started ({error})"
    finally:
        probe.close()
    if done.returncode != 0:
        lines = [line for line in done.stderr.strip().splitlines() if line.strip()]
        return f"the sandbox does not start here (bwrap: {lines[-1] if lines else f'exit {done.returncode}'})"
    return None


def readable_paths(spec: str, options: dict) -> list[str]:
    """What the worker may read besides the system: Python, ``sys.path``, the plugin, option files."""
    paths = [sys.prefix, sys.base_prefix, sys.exec_prefix, os.path.dirname(os.path.realpath(sys.executable))]
    paths.append(os.path.dirname(os.path.abspath(denoisebench.__file__)))
    paths += [entry for entry in sys.path if entry and os.path.isabs(entry)]
    module = spec.partition(":")[0]
    if module.endswith(".py"):
        paths.append(os.path.dirname(os.path.abspath(module)))
    paths += list(_option_paths(options))
    return paths


def _option_paths(options: dict) -> Iterable[str]:
    for value in options.values():
        for item in value if isinstance(value, (list, tuple)) else [value]:
            if isinstance(item, str) and item and os.path.exists(item):
                yield os.path.abspath(item)


def absolute_options(options: dict) -> dict:
    """``options`` with every string naming an existing path made absolute (the worker's folder is
    its scratch, so a relative checkpoint path would not resolve there)."""

    def fix(item):
        return os.path.abspath(item) if isinstance(item, str) and item and os.path.exists(item) else item

    return {
        key: [fix(v) for v in value] if isinstance(value, (list, tuple)) else fix(value)
        for key, value in options.items()
    }


class Command:
    """``argv`` for :class:`subprocess.Popen` and the file descriptor holding bwrap's arguments
    (pass it with ``pass_fds``; :meth:`close` it once the process has started)."""

    def __init__(self, argv: list[str], args_fd: int):
        self.argv = argv
        self.args_fd = args_fd

    def close(self) -> None:
        if self.args_fd >= 0:
            os.close(self.args_fd)
            self.args_fd = -1


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip("/") + "/")


def _minimal(paths: Iterable[str]) -> list[str]:
    """Existing paths as given and resolved (a link is followed by what reads it), without those
    inside another one (a bind covers its subfolders)."""
    existing = [os.path.abspath(p) for p in paths if p and os.path.exists(p)]
    real = sorted(set(existing) | {os.path.realpath(p) for p in existing})
    kept: list[str] = []
    for path in real:
        if not any(_inside(path, k) for k in kept):
            kept.append(path)
    return kept


def command(worker_argv: list[str], *, readable: Iterable[str], scratch_bytes: int) -> Command:
    """The sandboxed command running ``worker_argv`` (see the module docstring for every choice)."""
    args = [
        "--unshare-all",
        "--unshare-user",
        "--disable-userns",
        "--uid",
        SANDBOX_ID,
        "--gid",
        SANDBOX_ID,
        "--cap-drop",
        "ALL",
        "--die-with-parent",
        "--new-session",
        "--clearenv",
        "--proc",
        "/proc",
        "--dev",
        "/dev",
    ]
    for folder in SYSTEM_DIRS:
        if os.path.islink(folder):
            args += ["--symlink", os.readlink(folder), folder]
        elif os.path.isdir(folder):
            args += ["--ro-bind", folder, folder]
    for name in ETC_FILES:
        args += ["--ro-bind-try", name, name]
    for device in sorted(glob.glob("/dev/nvidia*")):
        args += ["--dev-bind-try", device, device]
    args += ["--size", str(int(scratch_bytes)), "--tmpfs", SCRATCH, "--chdir", SCRATCH]
    args += ["--size", str(int(scratch_bytes)), "--tmpfs", "/dev/shm"]  # bwrap's own /dev/shm has no size limit
    # never the scratch folder or one above it (a script in /tmp has /tmp on sys.path): that would
    # expose every file there and take the worker's writable folder away
    readable = [p for p in readable if p and not _inside(SCRATCH, os.path.abspath(p))]
    binds = [p for p in _minimal(readable) if not any(_inside(p, s) for s in SYSTEM_DIRS)]
    for path in binds:
        args += ["--ro-bind", path, path]
    for path in sorted(_PROTECTED):
        for hidden in (path, path + "-wal", path + "-shm", path + "-journal"):
            if not os.path.exists(hidden) or not any(_inside(hidden, b) for b in binds):
                continue  # not bound: invisible already (and a cover would only reveal its name)
            if os.path.isdir(hidden):
                args += ["--perms", "0555", "--tmpfs", hidden, "--remount-ro", hidden]
            else:
                args += ["--ro-bind", "/dev/null", hidden]
    # the tmpfs bwrap builds the root from (folders leading to the binds) and its /dev: read-only,
    # or a plugin could fill memory there past the scratch limit (each remount is of that mount only)
    args += ["--remount-ro", "/dev", "--remount-ro", "/"]
    env = {"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": SCRATCH, "TMPDIR": SCRATCH}
    env.update({k: os.environ[k] for k in ENV_KEEP if k in os.environ})
    for key, value in env.items():
        args += ["--setenv", key, value]
    fd = os.memfd_create("bwrap-args", 0) if hasattr(os, "memfd_create") else _tempfile_fd()
    os.write(fd, b"".join(a.encode() + b"\0" for a in args))
    os.lseek(fd, 0, os.SEEK_SET)
    return Command([bwrap_path() or "bwrap", "--args", str(fd), *worker_argv], fd)


def _tempfile_fd() -> int:

    handle, name = tempfile.mkstemp(prefix="denoisebench-bwrap-")
    os.unlink(name)
    return handle


def exit_signal(code: int | None) -> int | None:
    """The signal that ended a sandboxed worker, from bwrap's exit status (128 + N), or None."""
    if code is not None and 128 < code < 128 + 65:
        return code - 128
    return None
