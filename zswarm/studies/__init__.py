"""Studies over many runs: ``zswarm sweep`` (a grid of field values), ``zswarm basin``
(Monte-Carlo starts), the step-size study (step_size), and ``zswarm generate`` (scenarios of
the families' recipes).  Imports every layer below (up to engines)."""
