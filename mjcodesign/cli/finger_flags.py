"""Finger-model flags that several commands share: the grasping ``--model`` check and ``--routing``.

A command that grasps gives its ``--model`` the :func:`grasp_model_name` type, so that a flex model is
refused at parsing, before any work, with the library's reason
(:func:`mjcodesign.models.types.grasp_model`); :func:`add_routing` adds ``--routing`` and
:func:`routing_options` turns it into the :class:`~mjcodesign.models.types.SimOptions` of the run.
"""

from __future__ import annotations

import argparse

__all__ = ["grasp_model_name", "add_routing", "routing_options"]

_ROUTING_HELP = (
    "chain tendon path: guided (default; over every hinge, constant levers) or printed (through the "
    "segments' channels at the printed finger's heights, straight across each flexure gap; each flexure "
    "two hinges tied to one angle, at a 1 ms step)"
)


def grasp_model_name(text: str) -> str:
    """The argparse type of a grasping command's ``--model``: ``text`` unchanged, or a usage error.

    The flex models are refused with the library's one-line reason; other names pass to the parser's
    ``choices``.
    """
    from mjcodesign.errors import UnsupportedError
    from mjcodesign.models.types import FingerModel, grasp_model

    try:
        grasp_model(FingerModel(text))
    except ValueError:  # not a MuJoCo finger model (e.g. fem): the parser's choices decide
        return text
    except UnsupportedError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def add_routing(p: argparse.ArgumentParser) -> None:
    """``--routing guided|printed`` on parser ``p`` (:attr:`mjcodesign.models.types.SimOptions.routing`)."""
    from mjcodesign.models.types import ROUTINGS

    p.add_argument("--routing", choices=ROUTINGS, default=ROUTINGS[0], help=_ROUTING_HELP)


def routing_options(args: argparse.Namespace):
    """The run's :class:`~mjcodesign.models.types.SimOptions` for ``args.routing``; None for the default."""
    from mjcodesign.models.types import ROUTINGS, SimOptions

    routing = getattr(args, "routing", ROUTINGS[0])
    return None if routing == ROUTINGS[0] else SimOptions(routing=routing)
