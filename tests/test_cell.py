"""Tests of scrapcut_cli.cell: the planner contract's types, and that it stands alone.

Neither ``sim`` nor ``exploration`` owns the contract: importing it loads neither, and neither
package imports the other.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from scrapcut_cli.cell import PlannerContext, Reach, ReachAnswer, ReachQuery

PACKAGE = Path(__file__).resolve().parents[1] / "scrapcut_cli"


def test_an_answer_describes_itself_and_parses_back() -> None:
    answer = ReachAnswer(False, Reach.COLLISION, "panda_hand/observed", attempts=12)
    assert answer.describe() == "collision:panda_hand/observed"
    assert Reach.parse(answer.describe()) == (Reach.COLLISION, "panda_hand/observed")
    assert ReachAnswer(True, Reach.OK).describe() == "ok"
    assert Reach.parse("ok") == (Reach.OK, "")
    assert Reach.parse("joint_limits") == (Reach.JOINT_LIMITS, "")
    assert Reach.parse("teleported") == (Reach.NO_RECORD, "teleported")
    query = ReachQuery(np.eye(4))
    assert not query.free_dofs  # exactly the pose, unless the planner allows the free DOFs


def test_the_planner_context_holds_nothing_of_the_simulators_truth() -> None:
    names = {f.name for f in fields(PlannerContext)}
    assert names == {"camera", "start_view", "reachable", "paint", "base_frame"}


def test_importing_the_contract_loads_neither_package() -> None:
    code = (
        "import sys\nimport scrapcut_cli.cell\n"
        "print(sorted(m for m in sys.modules if m.startswith(('scrapcut_cli.sim', "
        "'scrapcut_cli.exploration', 'pybullet'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def _imports(package: str) -> set[str]:
    """Every scrapcut_cli module the package's files import (at any level, lazily too)."""
    found = set()
    for path in (PACKAGE / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                found.add(node.module)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
    return {name for name in found if name.startswith("scrapcut_cli")}


@pytest.mark.parametrize(("package", "other"), [("sim", "exploration"), ("exploration", "sim")])
def test_sim_and_exploration_do_not_import_each_other(package: str, other: str) -> None:
    imported = _imports(package)
    assert "scrapcut_cli.cell" in imported
    assert not {m for m in imported if m.startswith(f"scrapcut_cli.{other}")}
