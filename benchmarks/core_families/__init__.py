"""The families that measure the numerical core in one process (no ROS): a step, the mean field,
the integrators against scipy, long horizons, sweeps, basins, reductions; with the paper's
right-hand sides written out (``paper_rhs``) and the solver harness they share (``solve``)."""
