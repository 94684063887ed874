"""zswarm example: ``spin``, an experiment family of its own (docs/tutorial-own-algorithm.md)."""
