"""The package's layout (issue 23): its import graph has no circle (no module reaches itself
through the imports of others, counting imports inside functions (a deferred import only hides a
circle) but not those made for type hints alone (``if TYPE_CHECKING:``)), no module is over
``MAX_MODULE_LINES`` lines nor any function over ``MAX_FUNCTION_LINES`` (docstring included),
and every module has its test module (``tangraph/PKG/MOD.py``: ``tests/PKG/test_MOD.py``) or is
listed, with the test modules that test it through its users, in ``TESTED_THROUGH``."""

import ast
from pathlib import Path

import tangraph

PACKAGE = Path(tangraph.__file__).parent
TESTS = Path(__file__).parent
# Modules with no test module of their own, and the test modules that test them through their users.
TESTED_THROUGH: dict[str, tuple[str, ...]] = {
    "tangraph._lazy": ("test_toplevel.py", "maps/test_maps.py"),
    "tangraph.errors": ("test_hostile.py",),
    "tangraph.tomlfile": ("cli/test_tracks.py", "graph/test_config.py"),
    "tangraph.track_outputs": ("cli/test_tracks.py",),
    "tangraph.cli.simulate": ("sim/test_scenario.py",),
    "tangraph.experiments.registry": ("cli/test_experiment.py", "experiments/test_caputh_replay.py"),
    "tangraph.experiments.scheduling": ("experiments/test_runner.py",),
    "tangraph.experiments.tables": ("experiments/test_runner.py",),
    "tangraph.experiments.tasks": ("experiments/test_runner.py",),
    "tangraph.filters.pmf_bank": ("filters/test_pmf.py",),
    "tangraph.filters.pmf_grid": ("filters/test_pmf.py",),
    "tangraph.formats._checks": ("formats/test_csv_xyz.py", "formats/test_sontek.py", "formats/test_xtf.py"),
    "tangraph.graph.batch": ("graph/test_smoother.py",),
    "tangraph.maps._common": ("maps/test_hostile_maps.py", "maps/test_netcdf.py"),
    "tangraph.maps._grid_checks": ("maps/test_grid.py", "maps/test_hostile_maps.py"),
    "tangraph.matching.search_direct": ("matching/test_search.py",),
    "tangraph.matching.search_fft": ("matching/test_search.py",),
    "tangraph.matching.tap_noise": ("matching/test_tap.py",),
    "tangraph.matching.tap_types": ("matching/test_tap.py",),
}


def _graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a package's ``__init__`` by its name)."""
    files = {".".join(f.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__"): f
             for f in PACKAGE.rglob("*.py")}
    edges = {}
    for name, path in files.items():
        tree = ast.parse(path.read_text())
        typing_only = {id(node) for block in ast.walk(tree)
                       if isinstance(block, ast.If) and "TYPE_CHECKING" in ast.unparse(block.test)
                       for stmt in block.body for node in ast.walk(stmt)}
        found = set()
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("tangraph"):
                for alias in node.names:  # a submodule imported from its package, else the module
                    whole = f"{node.module}.{alias.name}"
                    found.add(whole if whole in files else node.module)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names if alias.name.startswith("tangraph"))
        edges[name] = {m for m in found if m in files and m != name}
    return edges


def _circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected parts of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    parts = []
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    part = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        part.append(member)
                        if member == node:
                            break
                    if len(part) > 1:
                        parts.append(sorted(part))
    return parts


def test_the_circle_finder_finds_a_circle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _circles(edges) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


def test_no_import_circle():
    edges = _graph()
    assert len(edges) > 100 and "tangraph.graph.smoother" in edges
    assert _circles(edges) == []


MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80  # from its ``def`` line to its last, docstring included, decorators not

# The modules and functions allowed to be longer, with the reason; each entry is its own limit, so
# none of them may grow, and one that no longer needs its entry makes the test fail until removed.
LONG_MODULES: dict[str, int] = {}  # none: a module over the limit is split by role
LONG_FUNCTIONS: dict[str, int] = {}  # none: a function over the limit is cut into helpers


def _sizes() -> tuple[dict[str, int], dict[str, int]]:
    """Lines of every module of the package and of every function in them (methods and nested
    functions by their dotted path)."""
    modules, functions = {}, {}
    for path in sorted(PACKAGE.rglob("*.py")):
        name = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__")
        text = path.read_text()
        modules[name] = len(text.splitlines())
        work = [(name, node) for node in ast.parse(text).body]
        while work:
            prefix, node = work.pop()
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                dotted = f"{prefix}.{node.name}"
                if not isinstance(node, ast.ClassDef):
                    functions[dotted] = node.end_lineno - node.lineno + 1
                work.extend((dotted, child) for child in ast.iter_child_nodes(node))
            else:
                work.extend((prefix, child) for child in ast.iter_child_nodes(node))
    return modules, functions


def _too_long(sizes: dict[str, int], limit: int, allowed: dict[str, int]) -> list[str]:
    return sorted(f"{name}: {size} lines (at most {allowed.get(name, limit)})"
                  for name, size in sizes.items() if size > allowed.get(name, limit))


def test_no_module_and_no_function_too_long():
    modules, functions = _sizes()
    assert "tangraph.graph.online.GraphNavigator.step" in functions
    assert _too_long(modules, MAX_MODULE_LINES, LONG_MODULES) == []
    assert _too_long(functions, MAX_FUNCTION_LINES, LONG_FUNCTIONS) == []
    stale = ([name for name in LONG_MODULES if modules.get(name, 0) <= MAX_MODULE_LINES]
             + [name for name in LONG_FUNCTIONS if functions.get(name, 0) <= MAX_FUNCTION_LINES])
    assert stale == [], "exempt but no longer too long (or gone): remove the entries"


def _test_module(path: Path) -> Path | None:
    """The test module of a module of the package (None for a package's ``__init__`` and
    ``__main__``): ``tangraph/PKG/MOD.py`` -> ``tests/PKG/test_MOD.py``, a private module's
    leading underscore dropped."""
    if path.name in ("__init__.py", "__main__.py"):
        return None
    parts = path.relative_to(PACKAGE).parts
    return TESTS.joinpath(*parts[:-1], "test_" + parts[-1].removeprefix("_"))


def test_every_module_has_its_test_module():
    missing, stale = [], []
    for path in sorted(PACKAGE.rglob("*.py")):
        if "_experiments" in path.parts or (test := _test_module(path)) is None:
            continue
        name = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if name in TESTED_THROUGH:
            stale += [name] if test.exists() else []
            missing += [f"{name}: {t}" for t in TESTED_THROUGH[name] if not (TESTS / t).exists()]
        elif not test.exists():
            missing.append(f"{name}: {test.relative_to(TESTS.parent)}")
    assert missing == [], "a module without its test module (or TESTED_THROUGH naming one that is gone)"
    assert stale == [], "listed in TESTED_THROUGH but has its own test module: remove the entry"
