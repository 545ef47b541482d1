"""Cross-simulator comparisons: the MuJoCo finger models against the Warp FEM and beam theory.

The chain, flex and flex-quadratic models in the cantilever, curl and press scenarios.

* ``run``: :func:`crosscheck` (rows and curl curves) and :func:`model_curl` (a MuJoCo model's curl);
* ``rows``: the row format, :data:`SCENARIOS`, :data:`MODELS` and :data:`TOL_CROSS`;
* ``tensions``: :func:`default_tensions` and :func:`press_tension`, scaled per design;
* ``press``: the press rows; ``shapes``: rest shapes for an observer; ``plot``: :func:`plot_curves`.

Importing this package imports neither Warp nor MuJoCo; a comparison imports what it runs.
"""

from mjcodesign.crosscheck.plot import plot_curves
from mjcodesign.crosscheck.rows import MODELS, SCENARIOS, TOL_CROSS
from mjcodesign.crosscheck.run import crosscheck, model_curl
from mjcodesign.crosscheck.tensions import default_tensions, press_tension

__all__ = [
    "crosscheck",
    "model_curl",
    "default_tensions",
    "press_tension",
    "plot_curves",
    "SCENARIOS",
    "MODELS",
    "TOL_CROSS",
]
