"""Evaluation by re-simulation: the paper's Table 1 and its disturbance sweep (``mjcodesign evaluate``).

Success always comes from the simulator; the surrogate (optional, imported lazily) only chooses poses.

- :mod:`~mjcodesign.evaluation.config`: :class:`EvalConfig`, design groups and design files;
- :mod:`~mjcodesign.evaluation.candidates`: per object, its first candidates and their point clouds;
- :mod:`~mjcodesign.evaluation.run`: :func:`run_evaluation`, one row per rollout;
- :mod:`~mjcodesign.evaluation.report`: the tables, ``results.json`` and a bar chart.
"""

from mjcodesign.evaluation.candidates import ObjectCandidates, object_candidates
from mjcodesign.evaluation.config import (
    DENSITIES,
    DOMAINS,
    PAPER_TABLE1,
    POSE_SAMPLING,
    DesignGroup,
    EvalConfig,
    parse_design_groups,
    parse_list,
)
from mjcodesign.evaluation.report import (
    cell,
    disturbance_markdown,
    disturbance_table,
    summary_table,
    table1_markdown,
    write_report,
)
from mjcodesign.evaluation.run import EvalObject, domain_of, prepare_objects, record_examples, run_evaluation

__all__ = [
    "DENSITIES",
    "DOMAINS",
    "PAPER_TABLE1",
    "POSE_SAMPLING",
    "DesignGroup",
    "EvalConfig",
    "EvalObject",
    "ObjectCandidates",
    "cell",
    "disturbance_markdown",
    "disturbance_table",
    "domain_of",
    "object_candidates",
    "parse_design_groups",
    "parse_list",
    "prepare_objects",
    "record_examples",
    "run_evaluation",
    "summary_table",
    "table1_markdown",
    "write_report",
]
