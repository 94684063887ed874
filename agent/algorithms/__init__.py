"""Pure algorithm modules, one per estimator/controller (numpy only, no I/O).

``REGISTRY`` maps the scenario's ``algorithm.name`` to its module.  Each module
exposes frozen ``Gains``/``State``/``Inputs`` dataclasses, ``initial_state``
and ``step(state, inputs, dt, gains) -> (state, outputs)``.
"""

from __future__ import annotations

from types import MappingProxyType, ModuleType

from agent.algorithms import (
    bearing_pose_fixed,
    bearing_pose_fixed_filtered,
    bearing_pose_moving,
    relative_attitude_continuous,
    relative_attitude_hybrid,
    relative_pose_hybrid,
)

REGISTRY: MappingProxyType[str, ModuleType] = MappingProxyType(
    {
        "bearing_pose_fixed": bearing_pose_fixed,
        "bearing_pose_fixed_filtered": bearing_pose_fixed_filtered,
        "bearing_pose_moving": bearing_pose_moving,
        "relative_attitude_continuous": relative_attitude_continuous,
        "relative_attitude_hybrid": relative_attitude_hybrid,
        "relative_pose_hybrid": relative_pose_hybrid,
    }
)
