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
    # a study combines the stages (generate, train, benchmark, read results); no stage imports it
    "study": {
        "generator",
        "dataset",
        "scenes",
        "models",
        "denoisers",
        "baselines",
        "metrics",
        "benchmark",
        "results",
        "analysis",
        "reports",
        "sampling",
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


#: The benchmark side's typed packages: records read by attribute, no dict shims.
TYPED_PACKAGES = ("results", "analysis", "reports")
#: Methods that make a record answer like a dict (``row["key"]``, ``row.get(key)``, ``key in row``).
DICT_METHODS = {"__getitem__", "get", "keys", "__contains__"}


def test_typed_records_have_no_dict_shims():
    """No class in ``results/``, ``analysis/`` or ``reports/`` answers by key: the store's rows, the
    analyses' results and the report model are read by attribute (``row.status``), and results.json is
    written from their attributes."""
    bad = []
    for package in TYPED_PACKAGES:
        for path in sorted((PACKAGE / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, ast.ClassDef):
                    continue
                shims = sorted(
                    f.name
                    for f in node.body
                    if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)) and f.name in DICT_METHODS
                )
                bases = {b.id for b in node.bases if isinstance(b, ast.Name)}
                if shims or node.name == "ByKey" or "ByKey" in bases:
                    bad.append(f"{path.relative_to(PACKAGE.parent)}: {node.name} {shims or 'ByKey'}")
    assert not bad, "dict shims on typed records (read them by attribute instead):\n" + "\n".join(bad)


#: Annotations that say nothing of what they hold.
UNTYPED = {"dict", "list", "tuple", "set", "Any", "object", "Dict", "List", "Tuple"}


def _bare_names(annotation: ast.expr) -> list[str]:
    """Names in ``annotation`` used bare (``dict``, not ``dict[str, int]``): the parts it leaves untyped."""
    subscripted = {id(n.value) for n in ast.walk(annotation) if isinstance(n, ast.Subscript)}
    found = []
    for n in ast.walk(annotation):
        name = n.id if isinstance(n, ast.Name) else n.attr if isinstance(n, ast.Attribute) else None
        if name in UNTYPED and id(n) not in subscripted:
            found.append(name)
    return found


def test_the_report_model_is_typed_to_its_parts():
    """Every field of the report model and of its parts (``reports/model.py``) says what it holds: no bare
    ``dict``/``list``/``Any`` and no ``list[dict]``; a part of the report is a dataclass of its own."""
    tree = ast.parse((PACKAGE / "reports" / "model.py").read_text())
    bad, classes = [], [n for n in tree.body if isinstance(n, ast.ClassDef)]
    assert any(c.name == "ReportModel" for c in classes)
    for cls in classes:
        for node in cls.body:
            if isinstance(node, ast.AnnAssign):
                bare = _bare_names(node.annotation)
                if bare:
                    bad.append(f"{cls.name}.{ast.unparse(node.target)}: {ast.unparse(node.annotation)}")
    assert not bad, "untyped fields in reports/model.py:\n" + "\n".join(bad)


def test_the_untyped_annotation_check_catches_what_it_should():
    def bare(text: str) -> list[str]:
        return _bare_names(ast.parse(text, mode="eval").body)

    assert bare("dict") == ["dict"] and bare("list[dict]") == ["dict"] and bare("dict[str, dict] | None")
    assert bare("list") and bare("Any") and bare("typing.Any") and bare("tuple")
    assert not bare("dict[str, list[int]]") and not bare("list[FrameRow]") and not bare("tuple[bytes, str]")
    assert not bare("dict[tuple[str, str, int], tuple[int, np.ndarray]] | None")


#: Lines a module of the package may have before its docstring must say why it stays whole.
MODULE_LINES = 600
#: How that docstring says it: a line starting with this marker, followed by the reason.
ONE_UNIT = "One unit:"


def _one_unit_reason(docstring: str) -> str:
    """The reason after the ``One unit:`` marker on a line of ``docstring`` ("" when none is given)."""
    for line in docstring.splitlines():
        line = line.strip()
        if line.startswith(ONE_UNIT):
            return line[len(ONE_UNIT) :].strip()
    return ""


def test_long_modules_are_split_or_say_why_they_are_one_unit():
    """A module over :data:`MODULE_LINES` lines holds more than one concern unless its docstring has a line
    ``One unit: <the reason it stays whole>``; split it into modules named for their concerns otherwise."""
    unexplained = []
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text()
        lines = len(text.splitlines())
        if lines > MODULE_LINES and not _one_unit_reason(ast.get_docstring(ast.parse(text)) or ""):
            unexplained.append(f"{path.relative_to(PACKAGE.parent)}: {lines} lines")
    assert not unexplained, (
        f"modules over {MODULE_LINES} lines without a '{ONE_UNIT} <reason>' line in their docstring "
        "(split them by concern, or say why they are one):\n" + "\n".join(unexplained)
    )


def test_the_one_unit_marker_needs_a_reason():
    assert _one_unit_reason("Render a frame.\n\nOne unit: the kernel and its state are traced together.")
    assert not _one_unit_reason("Render a frame.\n\nOne unit:") and not _one_unit_reason("Render a frame.")
    assert not _one_unit_reason("It is not One unit: of anything")  # the marker starts a line
