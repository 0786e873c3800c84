"""The house's structure, read from the source with ``ast``: short functions, imports in layers.

- No function of ``tatl_mj`` is longer than 80 lines (``def`` to its last line,
  docstring included), bar the exceptions listed by name; an exception must still
  exceed the limit, so the list can only shrink as functions are split.
- ``tatl_mj``'s imports (top-level and deferred into functions alike) form no
  cycle, and none goes from a lower layer to a higher one, bar the listed ones
  (which must still exist).
"""

import ast
import collections
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "tatl_mj"
MAX_LINES = 80
MAX_MODULE_LINES = 600

LONG_FUNCTIONS = {}
"""Functions over MAX_LINES, by ``module:qualname``, each with why it is left for now."""

LAYERS = (
    # Plain data and checks that every other floor uses.
    ("tatl_mj", "tatl_mj.gl", "tatl_mj.versions", "tatl_mj.plugins", "tatl_mj.validation"),
    ("tatl_mj.description", "tatl_mj.transitions", "tatl_mj.policy"),
    # The tasks (MuJoCo and the grid) and filming them.
    ("tatl_mj.suite", "tatl_mj.render"),
    ("tatl_mj.sampling",),
    ("tatl_mj.transfer",),
    # The experiments, along their data flow; records and the verdicts sit below the runner,
    # which writes a run's summary when its last unit is done.
    ("tatl_mj.experiments", "tatl_mj.experiments.spec"),
    ("tatl_mj.experiments.results",),
    ("tatl_mj.experiments.run",),
    ("tatl_mj.experiments.report",),
    # A comparison, what its results open with, and a user's settings file for it.
    ("tatl_mj.experiments.compare", "tatl_mj.experiments.compare_report", "tatl_mj.experiments.compare_settings"),
    # Entry points: commands, the Gymnasium registration, its vector env and the SB3 adapter.
    ("tatl_mj.cli", "tatl_mj.bench", "tatl_mj.gym", "tatl_mj.vector", "tatl_mj.vector_contexts", "tatl_mj.sb3"),
)
"""``tatl_mj``'s floors, lowest first: a module may import its own floor and those below."""

UPWARD_IMPORTS = {}
"""Imports from a lower floor to a higher one that are known, each with why."""


def _modules() -> dict[str, Path]:
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


MODULES = _modules()


def _resolve(name: str) -> str:
    while name not in MODULES and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def _imports(path: Path) -> set[str]:
    """The ``tatl_mj`` modules a file imports, wherever the import statement stands."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # ``from a import b``: the module a.b where b is one, else a itself.
            names = [
                f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in MODULES else node.module for a in node.names
            ]
        else:
            continue
        found |= {_resolve(n) for n in names if n == "tatl_mj" or n.startswith("tatl_mj.")}
    return found


GRAPH = {module: _imports(path) - {module} for module, path in MODULES.items()}


def _floor(module: str) -> int:
    matches = [
        (len(prefix), i)
        for i, floor in enumerate(LAYERS)
        for prefix in floor
        if module == prefix or module.startswith(prefix + ".")
    ]
    assert matches, f"{module} is on no floor of LAYERS: place it"
    return max(matches)[1]


def _functions(node: ast.AST, prefix: str = ""):
    """(qualified name, lines) of every function in ``node``, nested ones and methods included."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            if not isinstance(child, ast.ClassDef):
                yield prefix + child.name, child.end_lineno - child.lineno + 1
            yield from _functions(child, prefix + child.name + ".")
        else:
            yield from _functions(child, prefix)


def _long_functions() -> dict[str, int]:
    found = {}
    for module, path in MODULES.items():
        for name, lines in _functions(ast.parse(path.read_text(encoding="utf-8"))):
            if lines > MAX_LINES:
                found[f"{module}:{name}"] = lines
    return found


def test_no_function_is_longer_than_80_lines():
    long = _long_functions()
    unlisted = {name: n for name, n in long.items() if name not in LONG_FUNCTIONS}
    assert not unlisted, f"functions over {MAX_LINES} lines: {unlisted}"
    split = sorted(set(LONG_FUNCTIONS) - set(long))
    assert not split, f"now at most {MAX_LINES} lines: remove them from LONG_FUNCTIONS: {split}"


def test_no_module_is_longer_than_600_lines():
    files = sorted(PACKAGE.rglob("*.py"))
    long = {
        str(p.relative_to(PACKAGE)): n
        for p in files
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


def test_a_module_and_a_package_never_share_a_name():
    # tatl_mj/x.py beside tatl_mj/x/: Python imports the package and the file is dead weight.
    clash = [str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py") if p.with_suffix("").is_dir()]
    assert not clash, f"a module beside a package of its name: {clash}"


def test_every_module_is_on_a_floor_and_imports_downward():
    upward = {
        (module, imported)
        for module, imports in GRAPH.items()
        for imported in imports
        if _floor(imported) > _floor(module)
    }
    unlisted = sorted(upward - set(UPWARD_IMPORTS))
    assert not unlisted, f"imports from a lower floor to a higher one: {unlisted}"
    gone = set(UPWARD_IMPORTS) - upward
    assert not gone, f"no longer imported upward: remove them from UPWARD_IMPORTS: {gone}"


def test_imports_form_no_cycle():
    state: dict[str, int] = collections.defaultdict(int)  # 0 unseen, 1 on the path, 2 done
    path: list[str] = []

    def visit(module: str) -> None:
        state[module] = 1
        path.append(module)
        for imported in sorted(GRAPH.get(module, ())):
            assert state[imported] != 1, f"import cycle: {' -> '.join(path[path.index(imported) :] + [imported])}"
            if state[imported] == 0:
                visit(imported)
        path.pop()
        state[module] = 2

    for module in sorted(GRAPH):
        if state[module] == 0:
            visit(module)


def test_the_structure_tests_see_the_package():
    # The checks above are only as good as what they read: the package's big rooms are there.
    assert {"tatl_mj.transfer.registry", "tatl_mj.experiments.run.runner", "tatl_mj.cli"} <= set(MODULES)
    assert "tatl_mj.transfer.roles" in GRAPH["tatl_mj.transfer.registry"]
    assert "tatl_mj.suite" in GRAPH["tatl_mj.experiments.spec.checks"]  # a deferred import counts
