"""The report of ``mjcodesign design``: ``report.md``, a self-contained ``report.html`` and their figures.

- per object, one table row: the success probability with its Wilson interval of every design at the
  table's disturbance, each design at the pose the surrogate picks for it;
- the disturbance sweep: success against the disturbance per design, pooled over the objects;
- the fingers of every design drawn block by block, coloured by Young's modulus E [MPa];
- one image per object of the optimised design's grasp at its chosen pose, rendered off screen by
  MuJoCo (:class:`~mjcodesign.pipeline.GraspImages`, in an OpenGL context of the backend it is given:
  ``egl`` or ``osmesa`` without a display; by default the one MuJoCo chose from ``MUJOCO_GL`` when it
  was imported);
- the next commands to run.

The HTML holds its images inline (base64 PNG) and no external address, so it opens anywhere.
"""

from __future__ import annotations

import base64
import html
import struct
import zlib
from pathlib import Path

import numpy as np

from mjcodesign.design import LOG_E_MAX, LOG_E_MIN, FingerDesign
from mjcodesign.errors import OutputError, UnsupportedError
from mjcodesign.outputs import new_figure, save_figure, write_atomic

__all__ = ["GL_BACKENDS", "GRASP_IMAGE_SIZE", "GraspImages", "block_outline", "png_bytes", "write_report"]

GRASP_IMAGE_SIZE = (480, 640)
"""Height and width [px] of a grasp image (MuJoCo's default offscreen buffer holds 640 × 480)."""
GL_BACKENDS = ("egl", "osmesa", "glfw")
"""MuJoCo's OpenGL backends a :class:`GraspImages` can be told to use (EGL and OSMesa need no display)."""
_MAX_GEOM = 10000  # scene capacity, as mujoco.Renderer's default
_CAMERA_DISTANCE = 0.32  # [m] from the object: the 0.1-m fingers and the palm stay in view
_CAMERA_AZIMUTH = 135.0  # [deg]
_CAMERA_ELEVATION = -12.0  # [deg]: nearly level, the fingers around the object in view
_DPI = 110
_MM = 1e3  # the finger drawing's unit: millimetres
_STIFFNESS_COLOURS = ("#d72820", "#ebc828", "#28aa3c")  # red (soft) → yellow → green (stiff), linear in ln E
_FIGURES = "figures"
_E_TICKS_MPA = (1, 2, 5, 10, 20)  # colour-bar ticks inside E's printable range, 0.73-24 MPa
_MISSING_MPL = "the report's figures need matplotlib (pip install 'mjcodesign[torch]')"


def png_bytes(rgb: np.ndarray) -> bytes:
    """An RGB image (H, W, 3) uint8 as PNG bytes (8-bit truecolour, no filter)."""
    img = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w, _ = img.shape
    raw = b"".join(b"\x00" + img[i].tobytes() for i in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    head = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", head)
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )


def _gl_context_class(gl: str | None):
    """MuJoCo's GL context class for backend ``gl`` (None: MuJoCo's import-time choice, or None if off)."""
    import importlib

    from mujoco.rendering.classic import gl_context

    if gl is None:
        return getattr(gl_context, "GLContext", None)  # absent under MUJOCO_GL=disable
    return importlib.import_module(f"mujoco.{gl}").GLContext


def _render(model, data, camera, size: tuple[int, int], *, gl: str | None = None) -> np.ndarray:
    """RGB image (H, W, 3) uint8 of ``data`` seen from ``camera``, drawn off screen in a context of ``gl``.

    ``gl`` is one of :data:`GL_BACKENDS`, or None for the backend MuJoCo chose when it was imported.
    Raises :class:`~mjcodesign.errors.UnsupportedError` (one line) when no such context can be made.
    """
    import mujoco

    h, w = size
    ctx = con = None
    try:
        try:
            cls = _gl_context_class(gl)
            if cls is None:
                raise RuntimeError("MuJoCo's OpenGL is disabled (MUJOCO_GL=disable)")
            ctx = cls(w, h)
            ctx.make_current()
            con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        except Exception as exc:  # the GL backends raise their own types (no display, no EGL device)
            first = str(exc).splitlines()[0] if str(exc) else ""
            raise UnsupportedError(
                f"MuJoCo cannot render off screen with {gl or 'its default OpenGL backend'} "
                f"({type(exc).__name__}: {first}); without a display use MUJOCO_GL=egl or MUJOCO_GL=osmesa"
            ) from exc
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, con)
        scene = mujoco.MjvScene(model, maxgeom=_MAX_GEOM)
        mujoco.mjv_updateScene(
            model, data, mujoco.MjvOption(), None, camera, mujoco.mjtCatBit.mjCAT_ALL.value, scene
        )
        rect = mujoco.MjrRect(0, 0, w, h)
        mujoco.mjr_render(rect, scene, con)
        rgb = np.empty((h, w, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(rgb, None, rect, con)
        return np.flipud(rgb)  # OpenGL's rows run bottom-up
    finally:
        if con is not None:
            con.free()
        if ctx is not None:
            ctx.free()


class GraspImages:
    """An observer that renders the ``optimised/OBJECT`` rollouts at the start of their hold phase.

    ``gl``: the OpenGL backend (one of :data:`GL_BACKENDS`) whose context each image is drawn in; None
    uses the one MuJoCo chose from ``MUJOCO_GL`` when it was imported. MuJoCo makes that choice once
    per process, so a caller that needs an offscreen context names it here rather than in the
    environment, which is read too late once anything has imported MuJoCo.
    """

    def __init__(self, size: tuple[int, int] = GRASP_IMAGE_SIZE, *, gl: str | None = None):
        if gl is not None and gl not in GL_BACKENDS:
            raise UnsupportedError(f"unknown OpenGL backend {gl!r} (one of {', '.join(GL_BACKENDS)})")
        self.size = size
        self.gl = gl
        self.images: dict[str, bytes] = {}
        """PNG bytes by object name."""

    def rollout(self, rollout) -> None:
        """Render the rollout's state when the object should hang in the fingers (hold)."""
        import mujoco

        label, _, name = rollout.label.partition("/")
        if label != "optimised" or not len(rollout.states):
            return
        m = rollout.model
        d = mujoco.MjData(m)
        t = min(int(rollout.starts.get("hold", len(rollout.states))), len(rollout.states)) - 1
        mujoco.mj_setState(
            m, d, rollout.states[t] if t >= 0 else rollout.x0, mujoco.mjtState.mjSTATE_FULLPHYSICS
        )
        mujoco.mj_forward(m, d)
        cam = mujoco.MjvCamera()
        cam.lookat[:] = d.xpos[rollout.scene.object_body]
        cam.distance, cam.azimuth, cam.elevation = _CAMERA_DISTANCE, _CAMERA_AZIMUTH, _CAMERA_ELEVATION
        self.images[name] = png_bytes(_render(m, d, cam, self.size, gl=self.gl))

    def snapshot(self, snapshot) -> None:
        """Nothing: the report draws grasps only."""

    def close(self) -> None:
        """Nothing to release."""


def _pct(p: dict) -> str:
    return f"{100 * p['value']:.0f}% [{100 * p['low']:.0f}, {100 * p['high']:.0f}]"


def _table_cells(record: dict) -> dict[tuple[str, str], dict]:
    v = record["verification"]
    imp = v["table_impulse_paper_ns"]
    return {(c["object"], c["design"]): c for c in v["cells"] if c["impulse_paper_ns"] == imp}


def _sweep_figure(record: dict, path: Path) -> Path:
    fig = new_figure((6.0, 3.4), unavailable=_MISSING_MPL)
    ax = fig.subplots()
    v = record["verification"]
    for i, label in enumerate(v["designs"]):
        pts = [s for s in v["sweep"] if s["design"] == label]
        x = np.array([s["impulse_paper_ns"] for s in pts]) * (1 + 0.03 * (i - 1.5))  # side by side
        y = np.array([100 * s["p"]["value"] for s in pts])
        lo = np.maximum(y - np.array([100 * s["p"]["low"] for s in pts]), 0.0)  # 0 up to round-off
        hi = np.maximum(np.array([100 * s["p"]["high"] for s in pts]) - y, 0.0)
        ax.errorbar(
            x, y, yerr=[lo, hi], marker="o", capsize=3, label=label, lw=2 if label == "optimised" else 1
        )
    ax.set_xscale("log")
    ax.set_xticks(v["impulses_paper_ns"], [f"{x:g}" for x in v["impulses_paper_ns"]])
    ax.set_xticks([], minor=True)
    ax.set_xlabel("disturbance impulse [N s, the paper's units]")
    ax.set_ylabel("success [%] (95% Wilson)")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path, dpi=_DPI)


def block_outline(b) -> np.ndarray:
    """Side outline of one block of :meth:`~mjcodesign.design.FingerDesign.blocks` [mm], shape (n, 2).

    The spine's underside lies at z = 0; the cuts are chamfers of the top.
    """
    if b.kind.value == "flexure":
        pts = [(b.x0, 0.0), (b.x1, 0.0), (b.x1, b.spine), (b.x0, b.spine)]
    else:
        pts = [
            (b.x0, 0.0),
            (b.x1, 0.0),
            (b.x1, b.spine),
            (b.x1 - b.cut1, b.height1),
            (b.x0 + b.cut0, b.height0),
            (b.x0, b.spine),
        ]
    return np.asarray(pts) * _MM


def _fingers_figure(designs: dict[str, np.ndarray], path: Path) -> Path:
    """Both fingers of every design, each block coloured by E [MPa] on a log scale (ln E linear)."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LinearSegmentedColormap, LogNorm
    from matplotlib.patches import Polygon

    finger = FingerDesign()
    blocks = finger.blocks()
    rows = [(name, f, log_e[f]) for name, log_e in designs.items() for f in range(2)]
    fig = new_figure((7.5, 0.55 * len(rows) + 1.0), unavailable=_MISSING_MPL)
    grid = fig.add_gridspec(len(rows), 2, width_ratios=(40, 1))
    axes = [fig.add_subplot(grid[i, 0]) for i in range(len(rows))]
    cmap = LinearSegmentedColormap.from_list("stiffness", list(_STIFFNESS_COLOURS))
    norm = LogNorm(np.exp(LOG_E_MIN) / 1e6, np.exp(LOG_E_MAX) / 1e6)
    for ax, (name, f, log_e) in zip(axes, rows, strict=True):
        for b in blocks:
            e_mpa = np.exp(log_e[b.index]) / 1e6
            ax.add_patch(
                Polygon(block_outline(b), closed=True, facecolor=cmap(norm(e_mpa)), edgecolor="0.25", lw=0.5)
            )
        ax.set_xlim(-1, blocks[-1].x1 * _MM + 1)
        ax.set_ylim(-1, max(b.height0 for b in blocks) * _MM + 1)
        ax.set_aspect("equal")
        ax.set_yticks([])
        ax.set_ylabel(f"{name} {'AB'[f]}", rotation=0, ha="right", va="center", fontsize=8)
        if ax is not axes[-1]:
            ax.set_xticklabels([])
    axes[-1].set_xlabel("along the finger, base to tip [mm]")
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=fig.add_subplot(grid[:, 1]))
    ticks = [t for t in _E_TICKS_MPA if norm.vmin <= t <= norm.vmax]
    bar.set_ticks(ticks, labels=[f"{t:g}" for t in ticks])
    bar.set_label("E [MPa]")
    return save_figure(fig, path, dpi=_DPI)


def _next_commands(record: dict, root: Path) -> list[str]:
    first = record["objects"][0]
    design = root / "design.txt" if record["mode"] == "joint" else root / "designs" / f"{first['name']}.txt"
    prusa = record["print"].get("joint") or next(iter(record["print"].values()))
    return [
        f"prusa-slicer --export-gcode {prusa['prusaslicer_3mf']}",
        f"mjcodesign grasp --object {first['source']} --design {design} --pose {first['pose_file']} --rrd grasp.rrd",
    ]


def write_report(tmp: Path, root: Path, record: dict, images: dict[str, bytes]) -> dict:
    """Write the figures, ``report.md`` and ``report.html`` into ``tmp`` (the folder ``root`` to be).

    Returns the files' paths under ``root``. Raises :class:`~mjcodesign.errors.OutputError` or :class:`~mjcodesign.errors.UnsupportedError`.
    """
    figs = tmp / _FIGURES
    figs.mkdir()
    sweep = _sweep_figure(record, figs / "sweep.png")
    designs = {"optimised" if record["mode"] == "joint" else f"optimised {n}": np.reshape(v, (2, -1))
               for n, v in (list(record["designs"].items())[:1] if record["mode"] == "joint" else record["designs"].items())}  # fmt: skip
    from mjcodesign.design.stiffness import PRESETS

    for b in record["verification"]["designs"][1:]:
        designs[b] = np.asarray(PRESETS[b], dtype=float).reshape(2, -1)
    fingers = _fingers_figure(designs, figs / "fingers.png")
    grasp_files = {}
    for name, png in images.items():
        grasp_files[name] = write_atomic(figs / f"grasp_{name}.png", png)
    md = _markdown(record, root, sorted(grasp_files))
    page = _html(record, root, sweep.read_bytes(), fingers.read_bytes(), {n: images[n] for n in grasp_files})
    try:
        (tmp / "report.md").write_text(md, encoding="utf-8")
        (tmp / "report.html").write_text(page, encoding="utf-8")
    except OSError as exc:
        raise OutputError(f"cannot write the report: {exc.strerror or exc}") from exc
    return {
        "report_md": str(root / "report.md"),
        "report_html": str(root / "report.html"),
        "figures": [str(root / _FIGURES / p.name) for p in sorted(figs.iterdir())],
    }


def _header(record: dict) -> list[str]:
    v = record["verification"]
    sim = record["simulation"]
    return [
        f"{len(record['objects'])} objects, {record['mode']} design; verified by {v['rollouts']} MuJoCo rollouts "
        f"({v['draws']} perturbed draws per object, design and disturbance; {sim['model']} model, tendon {sim['tendon']}).",
        f"Each design at the pose the surrogate picks for it; success at the paper's {v['table_impulse_paper_ns']:g} N s "
        "disturbance with its 95% Wilson interval over the draws (palm ±2 mm ±2°, mass ±10%, friction ±20%, "
        "tendon ±5%).",
        f"Surrogate: {record['checkpoint']}; "
        + (record["adapt"]["summary"] if record.get("adapt") else "not adapted to these objects (--adapt 0)")
        + ".",
    ]


def _markdown(record: dict, root: Path, grasps: list[str]) -> str:
    v = record["verification"]
    cells = _table_cells(record)
    lines = ["# Gripper design report", "", *_header(record), ""]
    lines += [
        "| object | mass [g] | " + " | ".join(v["designs"]) + " |",
        "|---" * (len(v["designs"]) + 2) + "|",
    ]
    for o in record["objects"]:
        row = [_pct(cells[(o["name"], d)]["p"]) for d in v["designs"]]
        lines.append(f"| {o['name']} | {1000 * o['mass_kg']:.0f} | " + " | ".join(row) + " |")
    lines += ["", "## Files", "", f"- design: `{record['design_file']}`"]
    lines += [f"- pose of {o['name']}: `{o['pose_file']}`" for o in record["objects"]]
    if (record.get("adapt") or {}).get("checkpoint"):
        lines.append(f"- the adapted surrogate (a `--ckpt` folder): `{record['adapt']['checkpoint']}`")
    for k, files in record["print"].items():
        lines.append(
            f"- print ({k}): `{files['prusaslicer_3mf']}`, `{files['bambu_orca_3mf']}`, `{files['print_sheet_md']}`"
        )
    lines += [
        "",
        "## Figures",
        "",
        f"![disturbance sweep]({_FIGURES}/sweep.png)",
        "",
        f"![fingers]({_FIGURES}/fingers.png)",
        "",
    ]
    lines += [f"![grasp of {n}]({_FIGURES}/grasp_{n}.png)" for n in grasps]
    lines += ["", "## Next", "", *[f"    {c}" for c in _next_commands(record, root)], ""]
    return "\n".join(lines)


def _img(png: bytes, alt: str, cls: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f'<img class="{cls}" alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'


def _html(record: dict, root: Path, sweep: bytes, fingers: bytes, grasps: dict[str, bytes]) -> str:
    v = record["verification"]
    cells = _table_cells(record)
    e = html.escape
    head = "".join(f"<th>{e(d)}</th>" for d in v["designs"])
    body = []
    for o in record["objects"]:
        tds = "".join(
            f'<td title="{cells[(o["name"], d)]["successes"]}/{cells[(o["name"], d)]["valid"]} held">'
            f"{e(_pct(cells[(o['name'], d)]['p']))}</td>"
            for d in v["designs"]
        )
        body.append(f'<tr class="object"><td>{e(o["name"])}</td><td>{1000 * o["mass_kg"]:.0f}</td>{tds}</tr>')
    figures = [f"<h3>{e(n)}</h3>" + _img(png, f"grasp of {n}", "grasp") for n, png in sorted(grasps.items())]
    return "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8"><title>Gripper design report</title>',
            "<style>body{font-family:sans-serif;max-width:60em;margin:2em auto}"
            "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:.3em .6em}"
            "img{max-width:100%}</style></head><body>",
            "<h1>Gripper design report</h1>",
            *[f"<p>{e(p)}</p>" for p in _header(record)],
            f'<table id="success"><thead><tr><th>object</th><th>mass [g]</th>{head}</tr></thead>',
            "<tbody>" + "".join(body) + "</tbody></table>",
            "<h2>Disturbance sweep</h2>",
            _img(sweep, "success against disturbance", "sweep"),
            "<h2>Fingers, coloured by Young's modulus</h2>",
            _img(fingers, "fingers coloured by E", "fingers"),
            "<h2>Chosen grasps (optimised design)</h2>",
            *figures,
            "<h2>Next</h2>",
            "<pre>" + e("\n".join(_next_commands(record, root))) + "</pre>",
            f"<p>Design file: <code>{e(record['design_file'])}</code></p>",
            "</body></html>",
        ]
    )
