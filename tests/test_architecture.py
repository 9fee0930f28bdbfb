"""The whiteboard of parts, held by the code: who may import whom, and no import cycles.

Reads every module's imports with ``ast`` (module level and inside functions alike: a lazy
import is still an arrow) and checks them against the layering of ``docs/architecture.md``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "denoisebench"

#: Each stage and the stages it may import (besides itself and the package's top-level helpers).
ALLOWED = {
    "plugins": set(),  # the shell for untrusted code: knows no protocol (a worker's side is named to it at run time)
    "scenes": set(),
    "generator": {"scenes", "dataset"},
    "sampling": {"generator", "dataset", "scenes", "plugins"},
    "dataset": set(),
    "denoisers": {"dataset", "plugins"},
    "baselines": {"dataset", "denoisers", "metrics"},
    "models": {"dataset", "denoisers", "metrics", "baselines"},
    "metrics": set(),
    # the benchmark side, imports one way: benchmark → results ← analysis ← reports
    "results": {"dataset", "metrics"},  # the store: the only package that speaks SQL
    "analysis": {"results", "dataset", "metrics"},  # pure functions over a run's typed rows
    "reports": {"analysis", "results", "dataset", "metrics", "plugins"},  # runs nothing (plugins: isolation_text)
    "benchmark": {
        "results",
        "dataset",
        "denoisers",
        "baselines",
        "models",
        "metrics",
        "sampling",
        "generator",
        "scenes",
        "plugins",
    },
}
#: Top-level helper modules every stage may use (no stage of their own).
HELPERS = {"errors", "mitsuba_runtime", "outputs", "progress"}


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Absolute names of the project modules that ``path`` imports (relative imports resolved)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    here = _module_name(path).split(".")
    if path.name != "__init__.py":
        here = here[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.startswith("denoisebench"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            if module.startswith("denoisebench"):
                found.add(module)
                found.update(f"{module}.{alias.name}" for alias in node.names)
    return found


def _graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        graph[name] = {m for m in _imports(path) if m in modules and m != name}
    return graph


def _stage(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_stages_import_only_to_their_left():
    bad = []
    for module, targets in _graph().items():
        stage = _stage(module)
        if stage not in ALLOWED:
            continue
        for target in targets:
            other = _stage(target)
            if other in (stage, None) or other in HELPERS or other in ALLOWED[stage]:
                continue
            if other in ALLOWED:
                bad.append(f"{module} -> {target}")
    assert not bad, "arrows against the data flow:\n" + "\n".join(sorted(bad))


@pytest.mark.parametrize("side,other", [("usd", "render"), ("render", "usd")])
def test_usd_and_render_meet_only_in_the_contract(side, other):
    prefix, forbidden = f"denoisebench.generator.{side}", f"denoisebench.generator.{other}"
    bad = sorted(
        f"{module} -> {target}"
        for module, targets in _graph().items()
        if module.startswith(prefix)
        for target in targets
        if target.startswith(forbidden)
    )
    assert not bad, "\n".join(bad)


def test_contract_imports_neither_side():
    graph = _graph()
    bad = sorted(
        f"{module} -> {target}"
        for module, targets in graph.items()
        if module.startswith("denoisebench.generator.contract")
        for target in targets
        if target.startswith(("denoisebench.generator.usd", "denoisebench.generator.render"))
    )
    assert not bad, "\n".join(bad)
    sources = "".join(p.read_text() for p in (PACKAGE / "generator" / "contract").glob("*.py"))
    assert "import mitsuba" not in sources and "from pxr" not in sources and "import drjit" not in sources


def test_usd_side_never_loads_mitsuba_and_render_side_never_loads_pxr():
    for side, forbidden in (("usd", ("mitsuba", "drjit", "denoisebench.mitsuba_runtime")), ("render", ("pxr",))):
        for path in (PACKAGE / "generator" / side).glob("*.py"):
            tree = ast.parse(path.read_text())
            for node in ast.walk(tree):
                names = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and not node.level:
                    names = [node.module or ""]
                for name in names:
                    assert not name.startswith(forbidden), f"{path.name} imports {name}"


def test_no_import_cycles_between_modules_at_import_time():
    """Module-level imports only (lazy ones inside functions cannot deadlock an import)."""
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        top = ast.Module(body=[n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))], type_ignores=[])
        found = set()
        for node in top.body:
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                # `from pkg import submodule` depends on the submodule, not on the package's own __init__
                submodules = {f"{node.module}.{a.name}" for a in node.names} & modules.keys()
                names_only = len(submodules) < len(node.names)
                found.update(submodules | ({node.module} if names_only else set()))
            elif isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
        # a module's own parent packages are initialised before it in any case: not an edge
        graph[name] = {m for m in found if m in modules and m != name and not name.startswith(m + ".")}
    state: dict[str, int] = {}
    cycle: list[str] = []

    def visit(node: str, trail: list[str]) -> bool:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycle.extend(trail[trail.index(nxt) :] + [nxt] if nxt in trail else [node, nxt])
                return True
            if nxt not in state and visit(nxt, trail + [nxt]):
                return True
        state[node] = 2
        return False

    for module in sorted(graph):
        if module not in state and visit(module, [module]):
            break
    assert not cycle, " -> ".join(cycle)


def test_one_plugin_shell():
    """Worker processes, their limits, the sandbox and the reply format live in ``plugins/`` only."""
    shell = ("WorkerProcess(", "Connection(", "set_rlimits(", "send_bytes(", "class Limits", "sandbox.command(")
    bad = sorted(
        f"{path.relative_to(PACKAGE.parent)}: {needle}"
        for path in PACKAGE.rglob("*.py")
        if "plugins" not in path.relative_to(PACKAGE).parts
        for needle in shell
        if needle in path.read_text()
    )
    assert not bad, "plugin-shell code outside denoisebench/plugins/:\n" + "\n".join(bad)


def test_only_the_results_store_speaks_sql():
    """``sqlite3`` and SQL statements live in ``results/`` (and ``dataset/``'s own frame index) only."""
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        stage = _stage(_module_name(path))
        if stage in ("results", "dataset"):
            continue
        text = path.read_text()
        if "import sqlite3" in text or ".execute(" in text and "SELECT " in text:
            offenders.append(_module_name(path))
    assert not offenders, offenders


def test_tests_mirror_the_package():
    """Every test module lies under ``tests/<package>/`` for a package of denoisebench, and imports no other test module."""
    tests = Path(__file__).resolve().parent
    misplaced, cross = [], []
    for path in sorted(tests.rglob("test_*.py")):
        relative = path.relative_to(tests)
        if relative == Path("test_architecture.py") or relative.parts[0] == "data":
            continue
        if not (PACKAGE / relative.parent).is_dir():
            misplaced.append(str(relative))
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = (
                [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else []
            )
            cross += [
                f"{relative}: {name}"
                for name in names
                if name.split(".")[-1].startswith("test_") and (name.startswith("tests.") or "." not in name)
            ]
    assert not misplaced, f"test modules outside tests/<package>/: {misplaced}"
    assert not cross, f"test modules importing test modules (move the shared part to tests/support/): {cross}"
