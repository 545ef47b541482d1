"""Sphinx directives that generate pages from the code and the records.

The directives write reStructuredText, so the Markdown pages call them inside ``{eval-rst}`` blocks.

- ``api-package``: one package's public names (its ``__all__``), each through autodoc.
- ``dataset-schema``: the dataset's tables and columns from :mod:`mjcodesign.data.schema`.
- a resolver for Python cross-references written in the code's docstrings: a short name
  (``PoseError``) links to the one documented public name it ends with, and a name that exists in the
  code but is not public (a submodule, a private helper) is shown as code without a link; a name that
  exists nowhere stays an error of the nitpicky build.
- ``records-index``: one row per benchmark record (``benchmarks/records/``, the fixtures in
  ``tests/data/`` and the package's ``calibration_fem*.json``), from the provenance each carries.
"""

from __future__ import annotations

import importlib
import inspect
import json
import sys
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective

ROOT = Path(__file__).resolve().parents[2]
RECORD_DIRS = ("benchmarks/records", "tests/data", "mjcodesign/bench")
"""Folders (from the repository root) whose JSON files carry a ``provenance``."""
_CELL_MAX = 160  # characters of a command or a commit shown in the index; the record holds the rest


def _rst_table(header: list[str], rows: list[list[str]], widths: str = "auto") -> list[str]:
    """A ``list-table`` in reStructuredText."""
    out = [".. list-table::", "   :header-rows: 1", f"   :widths: {widths}", ""]
    for row in [header, *rows]:
        for i, cell in enumerate(row):
            text = " ".join(str(cell).split()) or "—"
            out.append(f"   {'* -' if i == 0 else '  -'} {text}")
    out.append("")
    return out


class _Generated(SphinxDirective):
    """Parses the reStructuredText a subclass writes into the page."""

    def lines(self) -> list[str]:
        """The reStructuredText to parse in place of the directive."""
        raise NotImplementedError

    def run(self) -> list[nodes.Node]:
        node = nodes.container()
        self.state.nested_parse(StringList(self.lines(), source=self.get_source_info()[0]), 0, node)
        return node.children


class ApiPackage(_Generated):
    """Every name in a package's ``__all__``, documented by autodoc under the package's import path."""

    required_arguments = 1

    def lines(self) -> list[str]:  # noqa: D102 (the base class says it)
        name = self.arguments[0]
        try:
            mod = importlib.import_module(name)
        except ImportError as exc:
            raise self.error(f"cannot import {name}: {exc}") from None
        out = [f".. automodule:: {name}", "   :no-members:", "", f".. currentmodule:: {name}", ""]
        for public in mod.__all__:
            obj = getattr(mod, public)
            if inspect.isclass(obj):
                kind = "exception" if issubclass(obj, BaseException) else "class"
                out += [f".. auto{kind}:: {public}", "   :members:", ""]
            elif inspect.isfunction(obj) or inspect.isbuiltin(obj):
                out += [f".. autofunction:: {public}", ""]
            elif inspect.ismodule(obj):
                out += [f".. py:data:: {public}", "", f"   The module :mod:`{obj.__name__}`.", ""]
            else:
                out += [f".. py:data:: {public}", ""]
                out += [f"   {line}" if line else "" for line in _attribute_doc(mod, public)] + [""]
        return out


def _attribute_doc(package, name: str) -> list[str]:
    """The docstring written under ``name`` where a module of ``package`` assigns it (its lines)."""
    from sphinx.pycode import ModuleAnalyzer

    prefix = package.__name__ + "."
    modules = [package.__name__] + sorted(m for m in sys.modules if m.startswith(prefix))
    for modname in modules:
        try:
            docs = ModuleAnalyzer.for_module(modname).find_attr_docs()
        except Exception:  # a module without source (extension, namespace): nothing to read
            continue
        if ("", name) in docs:
            return list(docs[("", name)])
    return ["(not documented)"]


class DatasetSchema(_Generated):
    """The dataset's Parquet tables: each column's Arrow type and meaning."""

    def lines(self) -> list[str]:  # noqa: D102
        from mjcodesign.data import schema

        out = []
        for table, sch in schema.DOCUMENTED.items():
            out += [f"**{table}**", ""]
            rows = [[f"``{f.name}``", f"``{f.type}``", schema.COLUMNS[f.name]] for f in sch]
            out += _rst_table(["column", "type", "meaning"], rows, "20 25 55")
        return out


def records() -> list[tuple[Path, dict]]:
    """Every JSON record with a provenance, with its path from the repository root."""
    out = []
    for folder in RECORD_DIRS:
        for p in sorted((ROOT / folder).glob("*.json")):
            try:
                data = json.loads(p.read_text(encoding="utf-8"))
            except ValueError:
                continue
            if isinstance(data, dict) and isinstance(data.get("provenance"), dict):
                out.append((p.relative_to(ROOT), data["provenance"]))
    return out


def _short(value) -> str:
    text = value if isinstance(value, str) else json.dumps(value)
    text = text.replace("|", "\\|")
    return text if len(text) <= _CELL_MAX else text[: _CELL_MAX - 1] + "…"


class RecordsIndex(_Generated):
    """One row per record: file, date, benchmark, command, commit."""

    option_spec = {"folder": directives.unchanged}

    def lines(self) -> list[str]:  # noqa: D102
        want = self.options.get("folder")
        rows = []
        for path, prov in records():
            if want and not str(path).startswith(want):
                continue
            commit = prov.get("commit") or prov.get("installed", {}).get("commit") or "not recorded"
            rows.append(
                [
                    f"``{path}``",
                    str(prov.get("date", "")).split("T")[0],
                    prov.get("benchmark", path.stem),
                    f"``{_short(prov.get('command', 'not recorded'))}``",
                    _short(commit),
                ]
            )
        return _rst_table(["record", "date", "benchmark", "command", "code run"], rows, "25 10 15 35 15")


def _lookup(name: str):
    """The object a dotted name denotes (a module or an attribute path under one), or None."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        except Exception:  # importing a module ran into an error of its own: not a name question
            return None
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        return obj
    return None


def _missing_reference(app, env, node, contnode):
    """Resolve a Python reference that Sphinx's exact lookup missed (see the module docstring)."""
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip("~.")
    domain = env.get_domain("py")
    documented = {name for name, *_ in domain.get_objects()}
    ends = [name for name in documented if name == target or name.endswith("." + target)]
    if len({id(_lookup(name)) for name in ends}) == 1:  # one object, maybe documented at two paths
        best = min(ends, key=len)
        return domain.resolve_xref(env, node["refdoc"], app.builder, "obj", best, node, contnode)
    if len(ends) > 1:
        return None
    module = node.get("py:module") or ""
    klass = node.get("py:class") or ""
    scopes = [target]
    if module:
        scopes += [f"{module}.{target}"] + ([f"{module}.{klass}.{target}"] if klass else [])
    scopes += [f"{m}.{target}" for m in sorted(sys.modules) if m.startswith("mjcodesign.")]
    for name in scopes:
        if _lookup(name) is not None:
            return contnode
    return None


def cli_parser():
    """``mjcodesign``'s parser with its help texts escaped for reStructuredText (``*``, ``|`` are text)."""
    import argparse

    from mjcodesign.cli.main import build_parser

    def escape(text):
        return text.replace("\\", "\\\\").replace("*", "\\*").replace("|", "\\|") if text else text

    def walk(parser):
        parser.description = escape(parser.description)
        for action in parser._actions:
            action.help = escape(action.help) if action.help is not argparse.SUPPRESS else action.help
            if isinstance(action, argparse._SubParsersAction):
                for choice in action._choices_actions:
                    choice.help = escape(choice.help)
                for sub in action.choices.values():
                    walk(sub)

    parser = build_parser()
    walk(parser)
    return parser


def _google_sections(app, what, name, obj, options, lines):
    """Google-style ``Args:`` sections of functions and classes to fields (not attributes' one-liners)."""
    if what in ("attribute", "data", "property"):
        return
    from sphinx.ext.napoleon import Config
    from sphinx.ext.napoleon.docstring import GoogleDocstring

    lines[:] = GoogleDocstring(lines, Config(), app, what, name, obj, options).lines()


def setup(app):
    """Register the directives, the reference resolver and the docstring sections."""
    app.connect("autodoc-process-docstring", _google_sections)
    app.connect("missing-reference", _missing_reference)
    app.add_directive("api-package", ApiPackage)
    app.add_directive("dataset-schema", DatasetSchema)
    app.add_directive("records-index", RecordsIndex)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
