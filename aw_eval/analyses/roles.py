"""What each system of a study is: a real ``system``, a ``calibration`` upper bound (it read the
hidden targets: the oracle) or a ``floor`` (it made no attempt: idle, random). Reports bold the
best only among real systems and mark the others.

A system's role comes from the ``agent`` its runs' ``run.json`` names (``aw.agents.ROLES``);
one run by a calibration agent makes the whole system calibration. Systems whose runs name no
known agent (own clients, official packages) are real systems, except for the names the baseline
runners give: ``oracle``/``oracle-*``/``oracle_*`` (calibration) and ``idle``/``random`` (floor).
"""

from __future__ import annotations

import re

from aw.agents import ROLES
from aw_eval.study.table import Study

__all__ = ["system_roles", "ROLE_NAMES"]

ROLE_NAMES = ("system", "floor", "calibration")
_NAMED = ((re.compile(r"oracle([-_].*)?"), "calibration"), (re.compile(r"(idle|random)([-_].*)?"), "floor"))


def _by_name(system: str) -> str:
    for pattern, role in _NAMED:
        if pattern.fullmatch(system):
            return role
    return "system"


def system_roles(study: Study) -> dict[str, str]:
    """``system -> role`` (one of :data:`ROLE_NAMES`) for every system of ``study``."""
    out = {}
    for s in study.systems:
        agents = {
            rec.info.agent
            for (sys_, _), rec in study.runs.items()
            if sys_ == s and rec.info is not None and rec.info.agent in ROLES
        }
        roles = {ROLES[a] for a in agents}
        if "calibration" in roles:
            out[s] = "calibration"
        elif roles:
            out[s] = "system" if "system" in roles else "floor"
        else:
            out[s] = _by_name(s)
    return out
