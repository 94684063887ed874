"""The ways to run a scenario: ``zswarm sim`` (one process, virtual clock: sim), ``zswarm run``
(processes over Zenoh: launch), docker-compose (compose), the recorder and replay processes,
and the worker pools of sweeps and basins (cluster).  The batched engine is the agent
program's (agent/batched.py), found by entry point.  Imports every layer below (up to
results)."""
