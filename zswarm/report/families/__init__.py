"""zswarm's report families (see :mod:`zswarm.report.family`), each registered by name in
``pyproject.toml``: ``leader_follower``, ``tree``, ``sync``, ``formation``."""
