"""zswarm's experiment families (the contract: :mod:`zswarm.families.contract`), each registered by name
in ``pyproject.toml``: ``leader_follower`` (thesis Chapter 3), ``tree`` (§4 observers), ``sync``
(Chapter 5 laws), ``formation`` (De Carli et al.), and :mod:`~zswarm.families.synergistic`,
the hybrid schemes' potential and its design, which the §4 and §5 algorithms share."""
