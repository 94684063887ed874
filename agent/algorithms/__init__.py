"""Pure algorithm modules, one per estimator/controller (numpy only, no I/O).

Each module satisfies the interface of :mod:`zswarm.scenario.algorithm`: a ``SPEC``
declaration, frozen ``Gains``/``State`` dataclasses, ``initial_state``, the
``inputs`` and pure ``step`` of each part, and ``publish``.  Each is registered
by name as an entry point of the group ``zswarm.algorithms`` in
``pyproject.toml``, the way a user's package registers its own; a module
can also be named by its path (see :func:`zswarm.scenario.algorithm.resolve`).
"""
