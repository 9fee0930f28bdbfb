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
HELPERS = {"errors", "interrupts", "mitsuba_runtime", "outputs"}


def _module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = path.relative_to(package.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _importlib_targets(node: ast.Call, project: str) -> list[str]:
    """The project modules an ``importlib.import_module(...)`` call names: its string, or for an
    f-string the package its constant head names (``f"{project}.commands.{name}"``: ``commands``)."""
    func = node.func
    name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
    if name != "import_module" or not node.args:
        return []
    arg = node.args[0]
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        text = arg.value
    elif isinstance(arg, ast.JoinedStr) and arg.values and isinstance(arg.values[0], ast.Constant):
        text = str(arg.values[0].value).rstrip(".")
    else:
        return []
    return [text] if text.split(".")[0] == project else []


def _edges(path: Path, modules: set[str], package: Path = PACKAGE) -> set[str]:
    """Modules of ``modules`` that ``path`` depends on, wherever it imports them: at module level,
    inside a function (a lazy import is still an arrow) and through
    ``importlib.import_module("<project>...")``.

    ``from pkg import name`` depends on ``pkg.name`` when that is a module and on ``pkg`` itself (its
    ``__init__``) when a name is not; relative imports are resolved; a module's own parent packages
    are initialised before it in any case and are no arrow.
    """
    project = package.name
    me = _module_name(path, package)
    here = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                module = ".".join(here[: len(here) - node.level + 1] + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            submodules = {f"{module}.{a.name}" for a in node.names} & modules
            found.update(submodules | ({module} if len(submodules) < len(node.names) else set()))
        elif isinstance(node, ast.Call):
            found.update(_importlib_targets(node, project))
    return {m for m in found if m in modules and m != me and not me.startswith(m + ".")}


def _module_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """{module: the project modules it depends on (:func:`_edges`)} for every module of ``package``."""
    paths = {_module_name(p, package): p for p in package.rglob("*.py")}
    return {name: _edges(path, set(paths), package) for name, path in paths.items()}


def _find_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle of ``graph`` as ``[a, b, ..., a]``, or [] when there is none."""
    state: dict[str, int] = {}
    cycle: list[str] = []

    def visit(node: str, trail: list[str]) -> bool:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycle.extend(trail[trail.index(nxt) :] + [nxt])
                return True
            if nxt not in state and visit(nxt, trail + [nxt]):
                return True
        state[node] = 2
        return False

    for module in sorted(graph):
        if module not in state and visit(module, [module]):
            break
    return cycle


def _graph() -> dict[str, set[str]]:
    return _module_graph()


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


def test_no_import_cycles_between_modules():
    """No circle of arrows, lazy or not: imports inside functions and ``importlib`` calls to project
    modules count (a circle looked up late still means two modules that cannot be read apart)."""
    cycle = _find_cycle(_module_graph())
    assert not cycle, " -> ".join(cycle)


def _plant(root: Path, files: dict[str, str]) -> Path:
    """A synthetic package ``root/denoisebench`` with ``files`` ({relative path: source})."""
    package = root / "denoisebench"
    for relative, text in {"__init__.py": "", **files}.items():
        path = package / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        (path.parent / "__init__.py").touch()
        path.write_text(text)
    return package


def test_the_cycle_check_sees_a_lazy_import(tmp_path):
    package = _plant(
        tmp_path,
        {
            "bench/runner.py": "from denoisebench.bench.units import pairs\n",
            "bench/units.py": "def pairs():\n    from denoisebench.bench.runner import measure  # late\n    return measure\n",
        },
    )
    assert _find_cycle(_module_graph(package)) == [
        "denoisebench.bench.runner",
        "denoisebench.bench.units",
        "denoisebench.bench.runner",
    ]
    (package / "bench" / "units.py").write_text("def pairs():\n    return 1\n")
    assert _find_cycle(_module_graph(package)) == []


def test_the_cycle_check_sees_an_importlib_arrow_and_a_relative_one(tmp_path):
    package = _plant(
        tmp_path,
        {
            "a/one.py": "import importlib\n\ndef f():\n    return importlib.import_module('denoisebench.b.two')\n",
            "b/two.py": "def g():\n    from ..a import one\n    return one\n",
        },
    )
    assert _find_cycle(_module_graph(package)) == ["denoisebench.a.one", "denoisebench.b.two", "denoisebench.a.one"]
    graph = _module_graph(package)
    assert graph["denoisebench.a.one"] == {"denoisebench.b.two"} and graph["denoisebench.b.two"] == {
        "denoisebench.a.one"
    }


def test_the_importlib_arrow_is_seen_by_the_layering(tmp_path):
    """An ``importlib`` call with an f-string names the package its constant head names."""
    package = _plant(
        tmp_path,
        {
            "cli.py": "import importlib\nm = importlib.import_module(f'denoisebench.commands.{1}')\n",
            "commands/run.py": "",
        },
    )
    assert _module_graph(package)["denoisebench.cli"] == {"denoisebench.commands"}


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


#: The benchmark side, whose calls to the project's own functions and records name their arguments.
BENCHMARK_SIDE = ("results", "analysis", "reports", "benchmark")
#: The most arguments such a call may pass by position.
MAX_POSITIONAL = 3


def _project_methods(package: Path = PACKAGE) -> set[str]:
    """Names of the methods defined on the project's classes (``obj.name(...)`` may call one)."""
    names = set()
    for path in package.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                names.update(f.name for f in node.body if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)))
    return names - {"__init__", "__call__"}


def _positional_overflows(tree: ast.Module, methods: set[str], project: str = "denoisebench") -> list[str]:
    """Calls in ``tree`` to the project's own functions, classes or methods that pass more than
    :data:`MAX_POSITIONAL` arguments by position, as ``line: callee (n)``.

    A callee is the project's when its name is defined in the module or imported from the project
    (``f(...)``, ``module.f(...)``), or when it is an attribute call whose name is a project method
    and whose object is not a third-party import (``np.clip(...)`` is not ours)."""
    ours, foreign = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            mine = node.level > 0 or (node.module or "").split(".")[0] == project
            (ours if mine else foreign).update(a.asname or a.name for a in node.names)
        elif isinstance(node, ast.Import):
            for a in node.names:
                mine = a.name.split(".")[0] == project
                (ours if mine else foreign).add(a.asname or a.name.split(".")[0])
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            ours.add(node.name)
    bad = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or len(node.args) <= MAX_POSITIONAL:
            continue
        func = node.func
        if isinstance(func, ast.Name):
            project_call = func.id in ours and func.id not in foreign
        elif isinstance(func, ast.Attribute):
            root = func.value
            while isinstance(root, ast.Attribute):
                root = root.value
            name = root.id if isinstance(root, ast.Name) else None
            project_call = name not in foreign and (name in ours or func.attr in methods)
        else:
            project_call = False
        if project_call:
            bad.append(f"{node.lineno}: {ast.unparse(func)} ({len(node.args)})")
    return bad


def test_benchmark_side_calls_name_their_arguments():
    """On the benchmark side a call to the project's own function or record passes at most
    :data:`MAX_POSITIONAL` arguments by position; the rest go by name (``ref_var=``, ``trim=``)."""
    methods = _project_methods()
    bad = [
        f"{path.relative_to(PACKAGE.parent)}:{line}"
        for stage in BENCHMARK_SIDE
        for path in sorted((PACKAGE / stage).rglob("*.py"))
        for line in _positional_overflows(ast.parse(path.read_text()), methods)
    ]
    assert not bad, f"calls passing more than {MAX_POSITIONAL} arguments by position:\n" + "\n".join(bad)


def test_the_positional_check_catches_a_planted_call():
    planted = ast.parse(
        "import numpy as np\n"
        "from denoisebench.metrics import compute_metrics\n"
        "from denoisebench.results import store as results_store\n"
        "def local(a, b, c, d): ...\n"
        "local(1, 2, 3, 4)\n"
        "compute_metrics(p, r, names, None)\n"
        "results_store.encode_image(a, b, c, d)\n"
        "store.image(run, label, scene, spp, frame)\n"
        "np.clip(x, 0, 1, out)\n"  # third-party: not ours
        "local(1, 2, 3, d=4)\n"  # by name: allowed
        "print(1, 2, 3, 4)\n"  # a builtin
    )
    found = _positional_overflows(planted, methods={"image"})
    assert found == [
        "5: local (4)",
        "6: compute_metrics (4)",
        "7: results_store.encode_image (4)",
        "8: store.image (5)",
    ]


def test_benchmark_side_records_are_keyword_only():
    """Every dataclass under the benchmark side's packages is ``kw_only=True``: built by name."""
    bad = []
    for stage in BENCHMARK_SIDE:
        for path in sorted((PACKAGE / stage).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                for deco in getattr(node, "decorator_list", []) if isinstance(node, ast.ClassDef) else []:
                    func = deco.func if isinstance(deco, ast.Call) else deco
                    if ast.unparse(func).split(".")[-1] != "dataclass":
                        continue
                    keywords = {k.arg: ast.unparse(k.value) for k in getattr(deco, "keywords", [])}
                    if keywords.get("kw_only") != "True":
                        bad.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name}")
    assert not bad, "dataclasses built by position (add kw_only=True):\n" + "\n".join(bad)


#: What an analysis may not import: the store, the dataset's readers, file formats.
ANALYSIS_FORBIDDEN_IMPORTS = (
    "sqlite3",
    "OpenEXR",
    "Imath",
    "denoisebench.results.store",
    "denoisebench.results.timings.read_timings",
    "denoisebench.dataset.reader",
    "denoisebench.dataset.exr_io",
    "denoisebench.dataset.open_dataset",
)


def _public_methods(path: Path, class_name: str) -> set[str]:
    tree = ast.parse(path.read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == class_name)
    return {f.name for f in cls.body if isinstance(f, ast.FunctionDef) and not f.name.startswith("_")}


def _storage_reads(tree: ast.Module, readers: set[str]) -> list[str]:
    """Where ``tree`` opens storage: imports of :data:`ANALYSIS_FORBIDDEN_IMPORTS`, ``open(...)``, a
    path's ``read_*``/``open``, and calls of the store's or the dataset's reading methods (``readers``)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            names = [f"{node.module}.{a.name}" for a in node.names] + [node.module or ""]
        else:
            names = []
        found += [
            f"{node.lineno}: imports {n}"
            for n in names
            if any(n == f or n.startswith(f + ".") for f in ANALYSIS_FORBIDDEN_IMPORTS)
        ]
        if isinstance(node, ast.Call):
            func = node.func
            if isinstance(func, ast.Name) and func.id in ("open", "open_dataset", "read_timings"):
                found.append(f"{node.lineno}: {func.id}(...)")
            elif isinstance(func, ast.Attribute) and (
                func.attr in readers or func.attr in ("read_text", "read_bytes", "open")
            ):
                found.append(f"{node.lineno}: .{func.attr}(...)")
    return found


def _readers() -> set[str]:
    """The store's and the dataset's public reading methods (their names, as an analysis would call them)."""
    store = _public_methods(PACKAGE / "results" / "store.py", "ResultsStore")
    dataset = _public_methods(PACKAGE / "dataset" / "reader.py", "Dataset")
    writes = {m for m in store if m.startswith(("add_", "write_", "set_", "finish", "begin", "close", "transaction"))}
    plain = set(dir(str)) | set(dir(dict)) | set(dir(list))  # ``name.split(...)`` is no read
    return (store | dataset) - writes - plain


def test_analysis_opens_no_store_and_no_file():
    """``analysis/`` takes rows and arrays: it imports no store, no dataset reader and no file format,
    and calls no store or dataset method; the callers (``reports/``, ``commands/``) load its inputs."""
    readers = _readers()
    bad = [
        f"{path.relative_to(PACKAGE.parent)}:{line}"
        for path in sorted((PACKAGE / "analysis").rglob("*.py"))
        for line in _storage_reads(ast.parse(path.read_text()), readers)
    ]
    assert not bad, "analysis/ reads storage:\n" + "\n".join(bad)


def test_the_storage_check_catches_planted_reads():
    readers = _readers()
    assert {"run", "frames", "units", "reference", "sequence"} <= readers
    planted = ast.parse(
        "import sqlite3\n"
        "from denoisebench.results.store import ResultsStore\n"
        "from denoisebench.dataset import open_dataset\n"
        "def f(store, dataset, path):\n"
        "    rows = store.frames('r')\n"
        "    layers = dataset.reference('s', 0)\n"
        "    return open(path).read(), path.read_text()\n"
        "def g(data):\n"
        "    return data.units_of('a', 1)\n"  # an analysis's own index: fine
    )
    assert sorted(_storage_reads(planted, readers)) == [
        "1: imports sqlite3",
        "2: imports denoisebench.results.store",
        "2: imports denoisebench.results.store.ResultsStore",
        "3: imports denoisebench.dataset.open_dataset",
        "5: .frames(...)",
        "6: .reference(...)",
        "7: .read_text(...)",
        "7: open(...)",
    ]


def test_the_helpers_and_commands_are_those_the_architecture_page_names():
    """:data:`HELPERS` are the package's top-level modules (but ``cli``), and docs/architecture.md names
    exactly them and exactly the commands of ``cli.COMMANDS``."""
    import re

    from denoisebench.cli import COMMANDS

    top = {p.stem for p in PACKAGE.glob("*.py")} - {"__init__", "cli"}
    assert top == HELPERS
    page = (PACKAGE.parent / "docs" / "architecture.md").read_text()
    sentence = page[page.index("top-level helpers") :].split(")", 1)[0]
    assert set(re.findall(r"`(\w+)`", sentence)) == HELPERS, sentence
    listed = re.search(r"`denoisebench\s*<([^>]*)>`", page).group(1)
    assert listed.replace("\n", "").split("|") == list(COMMANDS), listed
