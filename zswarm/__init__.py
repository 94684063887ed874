"""zswarm: multi-agent distributed estimation as a real distributed system."""

__version__ = "0.1.0"
