import os
from pathlib import Path

import pytest

os.environ.setdefault("RERUN_ANALYTICS", "0")

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
REFERENCE = SHARED / "reference" / "codesign-soft-gripper"


@pytest.fixture
def reference_dir():
    if not REFERENCE.is_dir():
        pytest.skip("shared/reference/codesign-soft-gripper is absent")
    return REFERENCE
