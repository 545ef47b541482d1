"""mjcodesign: co-design of tendon-driven soft grippers on MuJoCo.

The package itself stays light (no torch, warp, rerun or hardware SDK on import); import the subpackages:
``mjcodesign.design``, ``.models``, ``.objects``, ``.scenarios``, ``.poses``, ``.sim``, ``.fabrication``,
``.bench`` and ``.cli``.
"""

__all__ = []
