"""The package layout as the pipeline: no import cycles, one-way layers, no private names across modules.

The graph is read with ``ast`` (no module is imported), function-local imports included, so that an
import hidden inside a function cannot hold a cycle apart.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _setuptools() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]


def _package_dirs() -> dict[str, Path]:
    """Every package of the distribution and its folder, the root folders of ``package-dir`` included."""
    cfg = _setuptools()
    mapped = cfg.get("package-dir", {})
    out = {}
    for pkg in cfg["packages"]:
        # A package sits in its own mapped folder, or under its nearest mapped parent, or at its dotted path.
        parts = pkg.split(".")
        for i in range(len(parts), 0, -1):
            head = ".".join(parts[:i])
            if head in mapped:
                out[pkg] = ROOT / mapped[head] / Path(*parts[i:])
                break
        else:
            out[pkg] = ROOT / Path(*parts)
    return out


# Layer of each top-level part of the distribution: a module may import only from its own layer's part or
# a lower layer (the pipeline: design -> models -> objects -> scenarios -> poses -> sim -> jobs -> data ->
# surrogate -> co-design -> evaluation -> deploy). viz observes: it sits above everything, so nothing
# may import it (the CLI finds it through an entry point).
LAYERS = {
    "errors": -1,
    "outputs": 0,
    "optional": 0,
    "models_xml": 0,
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
    "surrogate": 9,
    "codesign": 10,
    "evaluation": 11,
    "bench": 12,
    "pipeline": 12,
    "hardware": 13,
    "cli": 14,
    "viz": 15,
}


def _modules() -> dict[str, Path]:
    """Every module of the distribution by its installed name (``mjcodesign.viz.recorder``, ...)."""
    mods = {}
    for pkg, folder in _package_dirs().items():
        for f in folder.glob("*.py"):
            name = pkg if f.stem == "__init__" else f"{pkg}.{f.stem}"
            mods[name] = f
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
    assert parts <= set(LAYERS), parts - set(LAYERS)


def test_the_root_folders_are_mapped():
    """surrogate/, hardware/, viz/ and models_xml/ install as mjcodesign.*, and the checks walk them."""
    mods = _modules()
    for part in ("surrogate", "hardware", "viz", "models_xml"):
        assert f"mjcodesign.{part}" in mods, part
    assert "mjcodesign.viz.recorder" in mods and "mjcodesign.hardware.tendon" in mods
    # Every .py file under a package folder is one of the walked modules (no folder missed).
    walked = {f.resolve() for f in mods.values()}
    for folder in _package_dirs().values():
        assert {f.resolve() for f in folder.glob("*.py")} <= walked, folder


def test_the_graph_sees_a_planted_cycle(tmp_path):
    """The cycle check follows imports across the root folders (a relative import included)."""
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("from mjcodesign.hardware import b\n")
    b.write_text("from . import a\n")
    edges = _imports({"mjcodesign.hardware.a": a, "mjcodesign.hardware.b": b})
    assert ("mjcodesign.hardware.a", "mjcodesign.hardware.b", "") in edges
    assert ("mjcodesign.hardware.b", "mjcodesign.hardware.a", "") in edges


def test_nothing_imports_viz():
    bad = [f"{a} -> {b}" for a, b, _ in _imports(_modules()) if _part(b) == "viz" and _part(a) != "viz"]
    assert not bad, bad


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
    for init in (folder / "__init__.py" for folder in _package_dirs().values()):
        tree = ast.parse(init.read_text(encoding="utf-8"))
        names = [
            t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)
        ]
        assert "__all__" in names, init


def test_every_package_is_in_the_distribution():
    """A wheel holds only the packages pyproject lists: a new folder must be listed, its data too."""
    cfg = _setuptools()
    dirs = _package_dirs()
    folder_of = {folder.resolve(): pkg for pkg, folder in dirs.items()}
    roots = {ROOT / "mjcodesign"} | {ROOT / d for d in cfg.get("package-dir", {}).values()}
    found = {f.parent.resolve() for r in roots for f in r.rglob("__init__.py")}
    missing = sorted(str(d) for d in found if d not in folder_of)
    assert not missing, f"package folders not listed in pyproject: {missing}"
    data = cfg.get("package-data", {})
    for r in roots:
        for f in r.rglob("*.json"):
            owner = next(d for d in f.resolve().parents if d in folder_of)  # the nearest package folder
            pkg = folder_of[owner]
            rel = f.resolve().relative_to(owner)
            assert any(rel.match(g) for g in data.get(pkg, [])), f"{f} is not package data of {pkg}"
