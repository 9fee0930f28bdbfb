"""Memory of the test run: a pytest plugin and a command wrapper that sample the whole process tree.

As a plugin (``python -m pytest -p tests.support.memory_profile ...``) a background thread samples, every
``DENOISEBENCH_MEMPROFILE_PERIOD`` seconds (default 0.25), the resident memory of the pytest process and
of every process below it (subprocesses, Ray workers and raylets, plugin workers), and records per test:
the tree's peak while the test ran (set-up, call and tear-down), the tree's and the pytest process's
memory after it, and the process's ``ru_maxrss``. The table goes to the file named by
``DENOISEBENCH_MEMPROFILE`` (tab-separated, one line per test), and the heaviest tests to the terminal.

As a command (``python -m tests.support.memory_profile [--log FILE] -- COMMAND ...``) it runs COMMAND and
prints the peak of the summed resident memory of COMMAND's process tree and its wall time.

Pitfalls
--------
* Summed RSS counts pages shared between processes (a forked worker's copy-on-write pages, shared
  libraries) once per process, so it is an upper bound; the proportional set size (PSS, from
  ``/proc/PID/smaps_rollup``) splits each shared page among its users and is what the machine pays.
  Both are recorded; PSS costs more to read, and it is read at every sample too.
* A process started and ended between two samples is not seen; keep the period below the life of the
  subprocesses that matter (a CLI run, a Ray worker: seconds).
* Processes that leave the tree (Ray's daemonised GCS server re-parents to init) are followed only
  while their parent chain reaches the root; Ray started by a test runs its raylet and workers under
  the pytest process, but its ``gcs_server`` may be counted only until it is re-parented.
* Linux only: it reads ``/proc`` (psutil is not a dependency of the project).
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import threading
import time

_PAGE = os.sysconf("SC_PAGE_SIZE")


def _children_map() -> dict[int, list[int]]:
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as handle:
                stat = handle.read()
        except OSError:
            continue
        # The command name may hold spaces and parentheses: the fields after the last ')' are fixed.
        fields = stat[stat.rfind(b")") + 2 :].split()
        children.setdefault(int(fields[1]), []).append(int(entry))
    return children


def tree(root: int) -> list[int]:
    """``root`` and every process below it (one walk of ``/proc``)."""
    children = _children_map()
    found, todo = [], [root]
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo.extend(children.get(pid, ()))
    return found


def rss_bytes(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/statm", "rb") as handle:
            return int(handle.read().split()[1]) * _PAGE
    except (OSError, IndexError, ValueError):
        return 0


def pss_bytes(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/smaps_rollup", "rb") as handle:
            for line in handle:
                if line.startswith(b"Pss:"):
                    return int(line.split()[1]) * 1024
    except (OSError, IndexError, ValueError):
        return 0
    return 0


class TreeSampler:
    """Samples the summed RSS and PSS of a process tree in a daemon thread; ``peak()`` since the last reset."""

    def __init__(self, root: int, period: float = 0.25):
        self.root, self.period = root, period
        self._lock = threading.Lock()
        self.now_rss = self.now_pss = self.now_count = 0
        self.window_rss = self.window_pss = 0
        self.max_rss = self.max_pss = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="memory-profile", daemon=True)

    def start(self) -> TreeSampler:
        self.sample()
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sample()

    def sample(self) -> None:
        pids = tree(self.root)
        rss = sum(rss_bytes(pid) for pid in pids)
        pss = sum(pss_bytes(pid) for pid in pids)
        with self._lock:
            self.now_rss, self.now_pss, self.now_count = rss, pss, len(pids)
            self.window_rss, self.window_pss = max(self.window_rss, rss), max(self.window_pss, pss)
            self.max_rss, self.max_pss = max(self.max_rss, rss), max(self.max_pss, pss)

    def reset_window(self) -> tuple[int, int]:
        """The window's peaks (RSS, PSS), then a new window from the current values."""
        with self._lock:
            peaks = self.window_rss, self.window_pss
            self.window_rss, self.window_pss = self.now_rss, self.now_pss
        return peaks

    def _loop(self) -> None:
        while not self._stop.wait(self.period):
            self.sample()


def _mb(value: int) -> float:
    return value / 2**20


# ---------------------------------------------------------------------------------------------------------------
# pytest plugin


class _Plugin:
    def __init__(self, path: str | None, period: float):
        self.path = path
        self.sampler = TreeSampler(os.getpid(), period).start()
        self.rows: list[tuple] = []
        self.started = time.perf_counter()

    def pytest_runtest_logstart(self, nodeid, location):
        self.sampler.sample()
        self.sampler.reset_window()

    def pytest_runtest_logfinish(self, nodeid, location):
        self.sampler.sample()
        peak_rss, peak_pss = self.sampler.reset_window()
        maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
        self.rows.append(
            (
                nodeid,
                _mb(peak_rss),
                _mb(peak_pss),
                _mb(self.sampler.now_rss),
                _mb(rss_bytes(os.getpid())),
                _mb(maxrss),
                _mb(children),
                self.sampler.now_count,
                time.perf_counter() - self.started,
            )
        )

    def pytest_terminal_summary(self, terminalreporter):
        self.sampler.stop()
        header = (
            "test\tpeak_tree_rss_mb\tpeak_tree_pss_mb\tafter_tree_rss_mb\tafter_self_rss_mb"
            "\tru_maxrss_self_mb\tru_maxrss_children_mb\tprocesses_after\telapsed_s"
        )
        if self.path:
            with open(self.path, "w") as handle:
                handle.write(header + "\n")
                for row in self.rows:
                    handle.write("\t".join([row[0], *(f"{value:.1f}" for value in row[1:])]) + "\n")
        write = terminalreporter.write_line
        terminalreporter.section("memory (process tree, MiB)")
        write(
            f"peak tree RSS {_mb(self.sampler.max_rss):.0f}, peak tree PSS {_mb(self.sampler.max_pss):.0f}, "
            f"ru_maxrss self {_mb(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024):.0f}, "
            f"children {_mb(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024):.0f}"
        )
        for row in sorted(self.rows, key=lambda row: -row[1])[:25]:
            write(f"{row[1]:8.0f} peak {row[2]:8.0f} pss {row[3]:8.0f} after {row[4]:8.0f} self  {row[0]}")
        left = [pid for pid in tree(os.getpid()) if pid != os.getpid()]
        write(f"processes below pytest at the end of the run: {len(left)}")
        for pid in left[:40]:
            write(f"{_mb(rss_bytes(pid)):8.0f} MiB  {pid}  {command_line(pid)[:160]}")


def command_line(pid: int) -> str:
    """``pid``'s command line, arguments joined by spaces ("" once it has exited)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as handle:
            return handle.read().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return ""


def pytest_configure(config):
    if not hasattr(config, "workerinput"):
        period = float(os.environ.get("DENOISEBENCH_MEMPROFILE_PERIOD", "0.25"))
        config.pluginmanager.register(_Plugin(os.environ.get("DENOISEBENCH_MEMPROFILE"), period), "memory-profile")


# ---------------------------------------------------------------------------------------------------------------
# command wrapper


def main(argv: list[str]) -> int:
    log = None
    if argv[:1] == ["--log"]:
        log, argv = argv[1], argv[2:]
    if argv[:1] == ["--"]:
        argv = argv[1:]
    if not argv:
        print("usage: python -m tests.support.memory_profile [--log FILE] -- COMMAND ...", file=sys.stderr)
        return 2
    started = time.perf_counter()
    process = subprocess.Popen(argv)
    sampler = TreeSampler(process.pid, 0.5).start()
    trace = open(log, "w") if log else None
    try:
        while process.poll() is None:
            time.sleep(0.5)
            if trace:
                trace.write(
                    f"{time.perf_counter() - started:.1f}\t{_mb(sampler.now_rss):.0f}\t{_mb(sampler.now_pss):.0f}"
                    f"\t{sampler.now_count}\t{os.getloadavg()[0]:.2f}\n"
                )
                trace.flush()
    finally:
        sampler.stop()
        if trace:
            trace.close()
    wall = time.perf_counter() - started
    print(
        f"memory_profile: exit {process.returncode}, wall {wall:.1f} s, peak tree RSS {_mb(sampler.max_rss):.0f} MiB, "
        f"peak tree PSS {_mb(sampler.max_pss):.0f} MiB, load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}",
        file=sys.stderr,
    )
    return process.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
