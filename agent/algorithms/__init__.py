"""Pure algorithm modules, one per estimator/controller (numpy only, no I/O).

Each module satisfies the interface of :mod:`zswarm.algorithm`: a ``SPEC``
declaration, frozen ``Gains``/``State`` dataclasses, ``initial_state``, the
``inputs`` and pure ``step`` of each part, and ``publish``.  ``BUILTIN`` maps
the scenario's ``algorithm.name`` to the module path; a user's own algorithm
is named by its module path instead (see :func:`zswarm.algorithm.resolve`).
"""

from __future__ import annotations

from types import MappingProxyType

BUILTIN: MappingProxyType[str, str] = MappingProxyType(
    {
        name: f"agent.algorithms.{name}"
        for name in (
            "bearing_pose_fixed",
            "bearing_pose_fixed_filtered",
            "bearing_pose_moving",
            "relative_attitude_continuous",
            "relative_attitude_hybrid",
            "relative_pose_hybrid",
            "leader_pose",
            "attitude_sync_continuous",
            "attitude_sync_hybrid",
            "attitude_sync_velocity_free",
            "common_frame_formation",
        )
    }
)
