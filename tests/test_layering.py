"""The package's layers, in the order the tree shows them: each imports only the layers below it.

    utilities (plotting, progress) → the model → simulation → data → calibration → the workflows → the command line

No import circle; no private name (``_x``) crosses a module boundary (a private module, ``growjax.x._y``, is
imported by its public names, inside its own folder); every public module declares ``__all__``.
"""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "growjax"
REPO = PACKAGE.parents[1]

UTILITIES = ("hashing", "progress", "plotting")
WORKFLOWS = ("sweep", "posterior", "discover", "design", "control", "track")
# rank of each top-level name: a module may import names of a lower rank, and of its own folder
RANKS = {
    **dict.fromkeys(UTILITIES, 0),
    "model": 1,
    "simulation": 2,
    "data": 3,
    "calibration": 4,
    **dict.fromkeys(WORKFLOWS, 5),
    "cli": 6,
    "__main__": 7,  # ``python -m growjax`` runs the command line
}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        yield name, path, ast.parse(path.read_text(), filename=str(path))


def _imports(tree):
    """(module imported, names taken from it or None) of every import statement, nested ones included."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, None
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module, [alias.name for alias in node.names]


def _top(module: str) -> str | None:
    """The top-level folder or module of ``growjax.<top>...``; None for the package itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "growjax" else None


def _targets(imported: str, names):
    """The growjax modules an import reaches: ``from growjax import x`` reaches ``growjax.x``."""
    if imported == "growjax" and names:
        return [f"growjax.{n}" for n in names]
    return [imported]


def test_every_module_belongs_to_a_layer():
    tops = {
        p.stem if p.is_file() else p.name
        for p in PACKAGE.iterdir()
        if (p.suffix == ".py" and p.stem not in ("__init__", "__main__")) or (p / "__init__.py").is_file()
    }
    assert tops <= set(RANKS), f"not placed in a layer: {sorted(tops - set(RANKS))}"


def test_the_top_level_holds_the_layer_folders_and_a_few_modules():
    modules = [p for p in PACKAGE.glob("*.py") if p.stem not in ("__init__", "__main__")]
    assert len(modules) <= 8, [p.name for p in modules]


def test_each_layer_imports_only_the_layers_below_it():
    offenders = []
    for name, _, tree in _modules():
        own = _top(name)
        if own is None:
            continue  # the package's __init__ re-exports the public names of every layer
        for imported, names in _imports(tree):
            for target in _targets(imported, names):
                top = _top(target)
                if top is None or top == own or top not in RANKS:
                    continue
                if RANKS[top] >= RANKS[own]:
                    offenders.append(f"{name} imports {target}")
    assert not offenders, "\n".join(offenders)


def test_no_import_circle():
    graph: dict[str, set] = {}
    modules = {name for name, _, _ in _modules()}
    for name, _, tree in _modules():
        deps = set()
        for imported, names in _imports(tree):
            for target in _targets(imported, names):
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target and target != name and target != "growjax":
                    deps.add(target)
        graph[name] = deps
    done, stack, circles = set(), [], []

    def visit(node):
        if node in stack:
            circles.append(stack[stack.index(node) :] + [node])
            return
        if node in done:
            return
        stack.append(node)
        for dep in sorted(graph.get(node, ())):
            visit(dep)
        stack.pop()
        done.add(node)

    for node in sorted(graph):
        visit(node)
    assert not circles, circles[:5]


def _private(owner: str, attr: str, modules) -> bool:
    """A private name of a module; a private module imported by its name from within its own folder is not."""
    return attr.startswith("_") and not attr.startswith("__") and f"{owner}.{attr}" not in modules


def _attribute_uses(tree):
    """``alias._name`` uses where ``alias`` is bound to a growjax module by an import."""
    aliases = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("growjax"):
            for alias in node.names:
                aliases[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("growjax"):
                    aliases[alias.asname or alias.name] = alias.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            yield aliases[node.value.id], node.attr


def _private_crossings(name: str, tree, modules) -> list:
    folder = name.rpartition(".")[0] if name.count(".") > 1 else name

    def inside(module: str) -> bool:
        return module == folder or module.startswith(folder + ".")

    out = []
    for imported, names in _imports(tree):
        if not imported.startswith("growjax") or imported == name:
            continue
        for n in names or ():
            if _private(imported, n, modules):
                out.append(f"{name}: {imported}.{n}")
            elif n.startswith("_") and not n.startswith("__") and not inside(f"{imported}.{n}"):
                out.append(f"{name}: the private module {imported}.{n}")
        last = imported.rpartition(".")[2]
        if last.startswith("_") and not last.startswith("__") and not inside(imported):
            out.append(f"{name}: the private module {imported}")
    for owner, attr in _attribute_uses(tree):
        if owner != name and _private(owner, attr, modules):
            out.append(f"{name}: {owner}.{attr}")
    return out


def test_no_private_name_crosses_a_module_boundary():
    modules = {name for name, _, _ in _modules()}
    offenders = [x for name, _, tree in _modules() for x in _private_crossings(name, tree, modules)]
    assert not offenders, "\n".join(offenders)


def test_tests_and_benchmarks_use_public_names_only():
    modules = {name for name, _, _ in _modules()}
    offenders = []
    for folder in ("tests", "benchmarks", "calibration", "data"):
        for path in sorted((REPO / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(), filename=str(path))
            offenders += [
                x.replace(str(path.stem), str(path.relative_to(REPO)), 1)
                for x in _private_crossings(path.stem, tree, modules)
            ]
    assert not offenders, "\n".join(offenders)


def test_every_public_module_declares_all():
    missing = [
        name
        for name, path, tree in _modules()
        if not any(part.startswith("_") and part != "__init__" for part in path.relative_to(PACKAGE).parts)
        and not any(
            isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in n.targets) for n in tree.body
        )
    ]
    assert not missing, missing


def test_no_library_module_selects_a_matplotlib_backend():
    offenders = [
        name
        for name, path, _ in _modules()
        if not name.startswith("growjax.cli") and "matplotlib.use(" in path.read_text()
    ]
    assert not offenders, offenders


def _uses_mock(tree) -> bool:
    """Whether a module imports ``unittest.mock`` (``import unittest.mock``, ``from unittest import mock``, ...)."""
    return any(
        imported == "unittest.mock" or (imported == "unittest" and (names is None or "mock" in names))
        for imported, names in _imports(tree)
    )


def test_no_library_module_uses_unittest_mock():
    offenders = [name for name, path, tree in _modules() if "unittest.mock" in path.read_text() or _uses_mock(tree)]
    assert not offenders, offenders


def test_no_test_or_benchmark_mocks_growjax():
    offenders = [
        str(path.relative_to(REPO))
        for folder in ("tests", "benchmarks")
        for path in sorted((REPO / folder).rglob("*.py"))
        if _uses_mock(ast.parse(path.read_text(), filename=str(path)))
    ]
    assert not offenders, offenders
