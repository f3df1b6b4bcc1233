"""Sweeps: many random ensembles of one scene, integrated together along a batch axis.

    scenes.py    the ensembles: a template scene, a grid of cells, B seeds per cell
    batch.py     B ensembles as one system (every sum over k runs over the agent's ensemble)
    graphs.py    their communication graphs: block-diagonal weights, each graph's centroid modes
    rings.py     twisted states on rings: winding number (d = 2), total turn, loop class in SO(d)
    chart_rk.py  RKMK8, DOP853's 8th-order tableau on a fixed grid, for long batched runs
    run.py       ``run_batch``: integrate, record the matching time, classify the others

``polymatch sweep`` (``polymatch_ros.cli.sweep``) is the command over it.
"""

from .run import OUTCOMES, BatchResult, batch_plan, classify, run_batch
from .scenes import Cell, cell_scenes, grid, template

__all__ = ["OUTCOMES", "BatchResult", "Cell", "batch_plan", "cell_scenes", "classify", "grid",
           "run_batch", "template"]
