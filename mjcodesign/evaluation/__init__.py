"""Evaluation by re-simulation: designs compared on a frozen suite, with intervals (``mjcodesign evaluate``).

Success always comes from the simulator; the surrogate (optional, imported lazily) only chooses poses.

- :mod:`~mjcodesign.evaluation.suite`: :class:`Suite`, objects with frozen poses and the perturbation
  model, versioned files (``--suite``), :func:`build_suite` for an ad-hoc one, :func:`add_objects` and
  :func:`egad_sources` to extend one, :func:`deal_folds` and :func:`suite_folds` for object-level folds;
- :mod:`~mjcodesign.evaluation.config`: design groups (``--designs``) and the paper's Table 1 figures;
- :mod:`~mjcodesign.evaluation.candidates`: per object, its first candidates and their point clouds;
- :mod:`~mjcodesign.evaluation.rollouts`: :func:`run_suite`, every rollout (objects × poses × draws ×
  designs) under common random numbers;
- :mod:`~mjcodesign.evaluation.stats` and :mod:`~mjcodesign.evaluation.analysis`: Wilson intervals per
  object, bootstrap intervals over objects, paired differences with permutation p-values;
- :mod:`~mjcodesign.evaluation.oracle`: :func:`oracle_search`, CMA-ES on the simulator alone on the
  evaluation's objective (``bench oracle``), and :func:`score_designs`;
- :mod:`~mjcodesign.evaluation.suite_report`: ``results.json``, ``summary.json``, ``table.md``,
  ``paired.md``, ``per_object.csv`` and ``forest.png``.
"""

from mjcodesign.evaluation.analysis import ALL_POSES, analyse, per_object_cells, select_policy
from mjcodesign.evaluation.candidates import ObjectCandidates, object_candidates, predict_candidates
from mjcodesign.evaluation.config import PAPER_TABLE1, DesignGroup, parse_design_groups, parse_list
from mjcodesign.evaluation.oracle import OracleConfig, OracleResult, oracle_search, score_designs
from mjcodesign.evaluation.rollouts import (
    MAX_REDRAWS,
    POSE_POLICIES,
    SuiteRun,
    check_real_masses,
    record_suite_examples,
    run_suite,
)
from mjcodesign.evaluation.stats import (
    Interval,
    PairedDifference,
    bootstrap_mean,
    mean_interval,
    paired_difference,
    wilson,
)
from mjcodesign.evaluation.suite import (
    DEFAULT_SUITE,
    SUITE_FORMAT,
    SUITE_VERSION,
    Suite,
    SuiteError,
    SuiteObject,
    add_objects,
    build_suite,
    deal_folds,
    egad_sources,
    load_suite,
    suite_folds,
)
from mjcodesign.evaluation.suite_report import PAPER_MEASURED, suite_header, write_suite_report
from mjcodesign.scenarios.perturb import PerturbationModel

__all__ = [
    "OracleConfig",
    "OracleResult",
    "oracle_search",
    "score_designs",
    "ALL_POSES",
    "DEFAULT_SUITE",
    "MAX_REDRAWS",
    "PAPER_MEASURED",
    "PAPER_TABLE1",
    "POSE_POLICIES",
    "SUITE_FORMAT",
    "SUITE_VERSION",
    "DesignGroup",
    "Interval",
    "ObjectCandidates",
    "PairedDifference",
    "PerturbationModel",
    "Suite",
    "SuiteError",
    "SuiteObject",
    "SuiteRun",
    "add_objects",
    "analyse",
    "bootstrap_mean",
    "build_suite",
    "check_real_masses",
    "deal_folds",
    "egad_sources",
    "load_suite",
    "mean_interval",
    "object_candidates",
    "paired_difference",
    "parse_design_groups",
    "parse_list",
    "per_object_cells",
    "predict_candidates",
    "record_suite_examples",
    "run_suite",
    "select_policy",
    "suite_folds",
    "suite_header",
    "wilson",
    "write_suite_report",
]
