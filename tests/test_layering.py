"""The package's import graph runs downwards: no module imports the command line, and no workflow reaches a
private name (``_x``) of another module (a private module, ``growjax._x``, is imported by its public names)."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "growjax"


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


def _attribute_uses(tree):
    """``alias._name`` uses where ``alias`` is bound to a growjax module by an import."""
    aliases = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("growjax"):
            for alias in node.names:
                aliases[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("growjax") and alias.asname:
                    aliases[alias.asname] = alias.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            yield aliases[node.value.id], node.attr


def test_the_package_is_walked():
    names = [name for name, _, _ in _modules()]
    assert "growjax.simulate" in names and "growjax.control.plant" in names and len(names) > 30


def test_no_module_imports_the_command_line():
    offenders = [(name, imported) for name, _, tree in _modules() if name != "growjax.cli"
                 for imported, names in _imports(tree)
                 if imported == "growjax.cli" or (imported == "growjax" and names and "cli" in names)]
    assert not offenders, offenders


def test_no_module_imports_a_private_name_of_another():
    modules = {name for name, _, _ in _modules()}

    def private(owner, attr):  # a private name of a module, not a private module imported by its name
        return attr.startswith("_") and not attr.startswith("__") and f"{owner}.{attr}" not in modules

    offenders = []
    for name, _, tree in _modules():
        for imported, names in _imports(tree):
            if imported.startswith("growjax") and imported != name:
                offenders += [(name, f"{imported}.{n}") for n in names or () if private(imported, n)]
        for owner, attr in _attribute_uses(tree):
            if owner != name and private(owner, attr):
                offenders.append((name, f"{owner}.{attr}"))
    assert not offenders, offenders


def test_no_library_module_selects_a_matplotlib_backend():
    offenders = [name for name, path, _ in _modules() if name != "growjax.cli" and "matplotlib.use(" in path.read_text()]
    assert not offenders, offenders
