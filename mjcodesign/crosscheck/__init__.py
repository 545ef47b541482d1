"""Cross-simulator comparisons: the MuJoCo finger models against the Warp FEM and beam theory.

The chain, flex and flex-quadratic models in the cantilever, curl and press scenarios.

* ``run``: :func:`crosscheck` (rows and curl curves) and :func:`model_curl` (a MuJoCo model's curl);
* ``rows``: the row format, :data:`SCENARIOS`, :data:`MODELS` and :data:`TOL_CROSS`;
* ``tensions``: :func:`default_tensions` and :func:`press_tension`, scaled per design;
* ``press``: the press rows; ``shapes``: rest shapes for an observer; ``plot``: :func:`plot_curves`;
* ``grasp``: the grasp agreement study of the chain and the Warp FEM (:func:`grasp_study`).

Importing this package imports neither Warp nor MuJoCo; a comparison imports what it runs.
"""

from mjcodesign.crosscheck.grasp import GRASP_CASES, GRASP_MODELS, grasp_study, short_settings
from mjcodesign.crosscheck.plot import plot_curves
from mjcodesign.crosscheck.rows import MODELS, SCENARIOS, TOL_CROSS
from mjcodesign.crosscheck.run import crosscheck, model_curl, parse_sweep, summary_rows
from mjcodesign.crosscheck.tensions import default_tensions, press_tension

__all__ = [
    "crosscheck",
    "model_curl",
    "parse_sweep",
    "summary_rows",
    "default_tensions",
    "press_tension",
    "plot_curves",
    "SCENARIOS",
    "MODELS",
    "TOL_CROSS",
    "GRASP_CASES",
    "GRASP_MODELS",
    "grasp_study",
    "short_settings",
]
