"""The package layout as the pipeline: no import cycles, one-way layers, no private names across modules.

The graph is read with ``ast`` (no module is imported), function-local imports included, so that an
import hidden inside a function cannot hold a cycle apart.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "mjcodesign"

# Layer of each top-level part of mjcodesign/: a module may import only from its own layer's part or a
# lower layer (the pipeline: design -> models -> objects -> scenarios -> poses -> sim -> jobs -> ...).
LAYERS = {
    "errors": 0,
    "optional": 0,
    "design": 1,
    "models": 2,
    "fabrication": 2,
    "objects": 3,
    "scenarios": 4,
    "poses": 5,
    "sim": 6,
    "jobs": 7,
    "data": 8,
    "crosscheck": 8,
    "codesign": 9,
    "evaluation": 10,
    "bench": 11,
    "cli": 12,
}


def _modules() -> dict[str, Path]:
    mods = {}
    for f in PKG.rglob("*.py"):
        parts = list(f.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = f
    return mods


def _imports(mods: dict[str, Path]) -> list[tuple[str, str, str]]:
    """(importer, imported module, imported name or '') for every import of an mjcodesign module."""
    out = []
    for m, f in mods.items():
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    pkg = m.split(".")[: len(m.split(".")) - node.level + (f.name == "__init__.py")]
                    base = ".".join(pkg + ([base] if base else []))
                for a in node.names:
                    full = f"{base}.{a.name}"
                    if full in mods:
                        out.append((m, full, ""))
                    elif base in mods:
                        out.append((m, base, a.name))
            elif isinstance(node, ast.Import):
                out.extend((m, a.name, "") for a in node.names if a.name in mods)
    return out


def _part(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_every_part_has_a_layer():
    parts = {_part(m) for m in _modules()} - {""}
    # mjcodesign.viz, .hardware, .surrogate and .models_xml install from the repository root.
    assert parts <= set(LAYERS), parts - set(LAYERS)


def test_no_import_cycles():
    mods = _modules()
    edges: dict[str, set[str]] = {}
    for a, b, _ in _imports(mods):
        # A package's __init__ re-exports its modules: that edge is not a dependency of the package.
        if a != b and not b.startswith(a + "."):
            edges.setdefault(a, set()).add(b)
    # Tarjan's strongly connected components.
    index, low, stack, on, sccs = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    for v in list(mods):
        if v not in index:
            visit(v)
    assert not sccs, sccs


def test_layers_point_one_way():
    bad = [
        f"{a} -> {b}"
        for a, b, _ in _imports(_modules())
        if _part(a) and _part(b) and LAYERS[_part(a)] < LAYERS[_part(b)]
    ]
    assert not bad, bad


def test_same_layer_parts_do_not_import_each_other():
    bad = [
        f"{a} -> {b}"
        for a, b, _ in _imports(_modules())
        if _part(a) and _part(b) and _part(a) != _part(b) and LAYERS[_part(a)] == LAYERS[_part(b)]
    ]
    assert not bad, bad


def test_no_private_names_across_modules():
    bad = [
        f"{a} <- {b}.{name}"
        for a, b, name in _imports(_modules())
        if name.startswith("_") and not name.startswith("__") and a != b
    ]
    assert not bad, bad


def test_every_package_lists_its_public_names():
    for init in PKG.rglob("__init__.py"):
        tree = ast.parse(init.read_text(encoding="utf-8"))
        names = [
            t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)
        ]
        assert "__all__" in names, init


def test_every_package_is_in_the_distribution():
    """A wheel holds only the packages pyproject lists: a new folder must be listed, its data too."""
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    listed = set(cfg["packages"])
    found = {".".join(f.parent.relative_to(ROOT).parts) for f in PKG.rglob("__init__.py")}
    assert found <= listed, sorted(found - listed)
    data = cfg.get("package-data", {})
    for f in PKG.rglob("*.json"):
        pkg = ".".join(f.parent.relative_to(ROOT).parts)
        assert "*.json" in data.get(pkg, []), f"{f} is not package data of {pkg}"
