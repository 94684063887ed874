"""The hybrid attitude synchronization law of thesis §5 ((5.19), (5.21), (5.7)), reported by
the ``spin`` family: the very same law as ``attitude_sync_hybrid``, its SPEC naming another
experiment family."""

from __future__ import annotations

import dataclasses

from agent.algorithms import attitude_sync_hybrid as law
from agent.algorithms.attitude_sync_hybrid import Gains, Inputs, Outputs, State, initial_state, inputs, publish, step

__all__ = ["SPEC", "Gains", "Inputs", "Outputs", "State", "initial_state", "inputs", "publish", "step"]

SPEC = dataclasses.replace(law.SPEC, report="spin")
