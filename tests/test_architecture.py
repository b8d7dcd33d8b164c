"""The layering of pygran_core and the plugins, read from their source: no import cycle inside
the core or a plugin, the core imports no plugin, the applications (``pygran_core.apps``,
the CLI) and test helpers (``pygran_core.testing``) stay out of the library, and a plugin's
engine overrides no name of the ``Engine`` base class but its declared hooks
(``pygran_core.simulation.engine_hooks.HOOKS``).

Every import statement counts, wherever it stands (in a function, under ``TYPE_CHECKING``), with
the package ``__init__`` modules it runs: an import moved into a function cannot hide a cycle.
So does ``importlib.import_module`` (or ``__import__``) of a literal name, and a compiled
module (``.pyx``) is a module whose Python imports count too.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

PACKAGE = "pygran_core"
ROOT = Path(__file__).resolve().parents[1]
#: Modules the library may not import: they are built on it.
ON_TOP = ("pygran_core.apps", "pygran_core.testing", "pygran_core.cli")
#: The Python import lines of a compiled module (not its ``cimport`` lines).
_PYX_IMPORT = re.compile(r"\s*(import|from\s+\S+\s+import)\s")


def packages() -> dict[str, Path]:
    """Package name -> source folder: the core and each plugin."""
    found = {PACKAGE: ROOT / PACKAGE}
    for init in sorted(ROOT.glob("plugins/*/src/*/__init__.py")):
        found[init.parent.name] = init.parent
    return found


def modules() -> dict[str, Path]:
    """Module name -> source file (``.py`` or ``.pyx``) of every package, packages under their
    own name."""
    found = {}
    for package, folder in packages().items():
        for path in sorted([*folder.rglob("*.py"), *folder.rglob("*.pyx")]):
            parts = (package, *path.relative_to(folder).with_suffix("").parts)
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def source(path: Path) -> str:
    """The Python a module's imports are read from: a ``.pyx`` file's import lines only."""
    text = path.read_text()
    if path.suffix == ".pyx":
        return "\n".join(line.strip() for line in text.splitlines() if _PYX_IMPORT.match(line))
    return text


def imported(name: str, path: Path, known: set[str]) -> set[str]:
    """The modules of ``known`` that importing ``name`` may run, besides its own packages."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(ast.parse(source(path))):
        if isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if called in ("import_module", "__import__") and isinstance(node.args[0].value, str):
                targets.add(node.args[0].value)
        elif isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            targets.update(f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names)
    deps = set()
    for target in targets:
        while target and target not in known:
            target = target.rpartition(".")[0]
        parts = target.split(".") if target else []
        for i in range(1, len(parts) + 1):  # the target and the packages above it
            prefix = ".".join(parts[:i])
            if prefix != name and not name.startswith(prefix + "."):
                deps.add(prefix)
    return deps


@functools.cache
def import_graph() -> dict[str, set[str]]:
    found = modules()
    return {name: imported(name, path, set(found)) for name, path in found.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a path that ends where it starts, or ``None``."""
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        state[node] = 2
        path.pop()
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


def within(package: str, module: str) -> bool:
    return module == package or module.startswith(package + ".")


def test_the_graph_is_read_from_the_source():
    graph = import_graph()
    assert {"pygran_core.hookspecs", "pygran_core.errors"} <= graph["pygran_core.registry"]
    # a submodule import runs the packages above it
    assert "pygran_core.simulation" in graph["pygran_core.testing.engines.base"]
    # a literal import_module counts; the compiled kernels are a module of the core
    assert "pygran_core.analysis" in graph["pygran_core"]
    assert graph["pygran_core._compiled"] == {"pygran_core._accel"}
    assert "pygran_readers.series" in graph["pygran_readers.vtk"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


@pytest.mark.parametrize("package", sorted(packages()))
def test_no_import_cycle(package):
    graph = {
        name: {dep for dep in deps if within(package, dep)}
        for name, deps in import_graph().items()
        if within(package, name)
    }
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or ())


def test_core_imports_no_plugin():
    wrong = {
        name: sorted(dep for dep in deps if not within(PACKAGE, dep))
        for name, deps in import_graph().items()
        if within(PACKAGE, name) and any(not within(PACKAGE, dep) for dep in deps)
    }
    assert not wrong, f"core modules import plugins: {wrong}"


def test_library_does_not_import_applications_or_test_helpers():
    def on_top(module: str) -> bool:
        return any(module == top or module.startswith(top + ".") for top in ON_TOP)

    wrong = {
        name: sorted(dep for dep in deps if on_top(dep))
        for name, deps in import_graph().items()
        if not on_top(name) and any(on_top(dep) for dep in deps)
    }
    assert not wrong, f"library modules import applications or test helpers: {wrong}"


def assigned_to_self(node: ast.AST) -> set[str]:
    """The attributes ``self.<name>`` that code under ``node`` assigns to."""
    return {
        leaf.attr
        for leaf in ast.walk(node)
        if isinstance(leaf, ast.Attribute)
        and isinstance(leaf.ctx, ast.Store)
        and isinstance(leaf.value, ast.Name)
        and leaf.value.id == "self"
    }


def engine_overrides(tree: ast.Module, base: set[str]) -> dict[str, set[str]]:
    """Engine class -> the names of ``base`` it defines: in its body, or as ``self.<name> = ...``
    in its methods. Engine classes are those deriving from ``Engine`` or from one of them."""
    engines = {"Engine"}
    found: dict[str, set[str]] = {}
    for node in tree.body:
        if not isinstance(node, ast.ClassDef):
            continue
        if not {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases} & engines:
            continue
        engines.add(node.name)
        names = assigned_to_self(node)
        for item in node.body:
            if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                names.add(item.name)
            elif isinstance(item, (ast.Assign, ast.AnnAssign)):
                targets = item.targets if isinstance(item, ast.Assign) else [item.target]
                names.update(t.id for t in targets if isinstance(t, ast.Name))
        found[node.name] = {n for n in names & base if not (n.startswith("__") and n.endswith("__"))}
    return found


@functools.cache
def engine_base_names() -> set[str]:
    """Every name of the ``Engine`` base class: its attributes and methods, and the attributes
    its constructor and methods set."""
    from pygran_core.simulation.engine import Engine

    tree = ast.parse((ROOT / PACKAGE / "simulation" / "engine.py").read_text())
    return set(dir(Engine)) | assigned_to_self(tree)


def test_overrides_are_read_from_the_source():
    from pygran_core.simulation.engine_hooks import HOOKS, EngineHooks

    assert set(HOOKS) <= set(dir(EngineHooks))
    assert {"mesh_force", "_advance", "_native_trajectories", "inserter"} <= set(HOOKS)
    base = engine_base_names()
    assert {"_on_event", "files", "journal", "run", "log", "messages", "obstacles", "dt"} <= base
    source = """
class Mine(Engine):
    name = "mine"
    def _on_event(self): ...
    def _advance(self, n):
        self.dt = 1.0
        self.solver = None
class Theirs(Mine):
    def log(self, message): ...
"""
    found = engine_overrides(ast.parse(source), base)
    assert found == {"Mine": {"name", "_on_event", "_advance", "dt"}, "Theirs": {"log"}}


def test_plugin_engines_override_only_hooks():
    from pygran_core.simulation.engine_hooks import HOOKS

    base = engine_base_names()
    wrong = {}
    for package, folder in packages().items():
        if package == PACKAGE:
            continue
        for path in sorted(folder.rglob("*.py")):
            for engine, names in engine_overrides(ast.parse(path.read_text()), base).items():
                if names - set(HOOKS):
                    wrong[f"{package}.{engine}"] = sorted(names - set(HOOKS))
    assert not wrong, f"plugin engines override names of the Engine base class that are no hooks: {wrong}"


#: The most lines a class of library code may span: past it, it holds more than one job.
CLASS_LINES = 400


def long_classes(text: str) -> list[str]:
    """``name (lines)`` of each class in the module ``text`` spanning more than :data:`CLASS_LINES`."""
    return [
        f"{node.name} ({node.end_lineno - node.lineno + 1})"
        for node in ast.walk(ast.parse(text))
        if isinstance(node, ast.ClassDef) and node.end_lineno - node.lineno + 1 > CLASS_LINES
    ]


def test_long_classes_are_found():
    body = "\n".join(f"    x{i} = {i}" for i in range(CLASS_LINES))
    assert long_classes(f"class Big:\n{body}\n") == [f"Big ({CLASS_LINES + 1})"]
    assert long_classes("class Small:\n    x = 1\n") == []


def test_no_class_in_the_library_is_over_400_lines():
    found = {
        name: long
        for name, path in modules().items()
        if path.suffix == ".py"
        and not any(within(top, name) for top in ON_TOP)
        and (long := long_classes(path.read_text()))
    }
    assert not found, f"split these classes by responsibility: {found}"
