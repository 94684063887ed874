"""The math: SO(3) (so3), its compiled loops (kernels, _kernels.c), trigonometry with the same
bits everywhere (trig), the timing library that brings measurements to a step (timing), and
the bounds every value is held to (limits).  Imports numpy and the standard library only."""
