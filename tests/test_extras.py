"""The extras of pyproject.toml bring what the code behind them needs.

How this works: the base install is the onboard pilot's (no MuJoCo, docs/onboard.md), so an
extra whose code runs the simulator in-process must bring the ``sim`` extra itself. An extra may
name other extras of skeye (``skeye[sim]``); ``requirement_names`` expands those and returns the
distribution names an extra installs. It is a plain function, tested on a small table too.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_NAME = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[([^\]]*)\])?")


def requirement_names(extras: dict[str, list[str]], extra: str, package: str = "skeye"
                      ) -> set[str]:
    """The distributions ``pip install 'PACKAGE[EXTRA]'`` brings beyond the base dependencies
    (lower-case names), the package's own extras it names expanded."""
    names: set[str] = set()
    todo, seen = [extra], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for requirement in extras[name]:
            match = _NAME.match(requirement)
            assert match, f"extra {name}: cannot read {requirement!r}"
            dist, inner = match.group(1).lower(), match.group(2)
            if dist == package:
                todo.extend(part.strip() for part in (inner or "").split(",") if part.strip())
            else:
                names.add(dist)
    return names


def test_requirement_names_expands_the_packages_own_extras():
    extras = {"sim": ["mujoco>=3.2", "rich"], "gym": ["skeye[sim]", "Gymnasium>=1.1"],
              "all": ["skeye[gym, sim]"], "bare": ["gymnasium"]}
    assert requirement_names(extras, "gym") == {"mujoco", "rich", "gymnasium"}
    assert requirement_names(extras, "all") == {"mujoco", "rich", "gymnasium"}
    assert "mujoco" not in requirement_names(extras, "bare")


def test_the_gym_extra_brings_the_simulator():
    """skeye.gym steps the simulator in-process (docs/gym.md): ``pip install 'skeye[gym]'``
    on the base install must bring what ``skeye sim`` needs, MuJoCo first."""
    with open(ROOT / "pyproject.toml", "rb") as f:
        extras = tomllib.load(f)["project"]["optional-dependencies"]
    gym = requirement_names(extras, "gym")
    assert "gymnasium" in gym
    missing = requirement_names(extras, "sim") - gym
    assert not missing, f"the gym extra lacks {sorted(missing)} of the sim extra"
