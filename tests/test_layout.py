"""The package's layout (issue 23): its import graph has no circle (no module reaches itself
through the imports of others, counting imports inside functions (a deferred import only hides a
circle) but not those made for type hints alone (``if TYPE_CHECKING:``)), and no module is over
``MAX_MODULE_LINES`` lines nor any function over ``MAX_FUNCTION_LINES`` (docstring included)."""

import ast
from pathlib import Path

import tangraph

PACKAGE = Path(tangraph.__file__).parent


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
