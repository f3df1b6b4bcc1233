"""Which initial states match on sparse graphs: rings and random graphs, d = 2, 3, 4.

First-order model (A-2), kappa = gamma = 1, on a communication graph with degree
normalisation (kappa/deg_i: on a ring of k neighbours a side, the size-normalised model
with time rescaled by N/2k).  The centroids start together (they follow linear consensus,
Prop. 2.1, whatever the rotations do), so "matched" (vertex diameter < 1e-6 at a sample)
is a statement about the rotations alone.  Rotations are Haar-uniform (the scene's
``rotations: uniform``), seeds 0 .. B-1 per cell; every ensemble runs (rkmk4, dt 0.5)
until it matches or is still at another equilibrium (``run_batch(settle=True)``), at
most to t_end.

1. Rings, N = 16, 32, 64, k = 1 .. N/2: fraction matched against k/N.  In d = 2 the model
   is identical Kuramoto oscillators on the ring (theta_i' = (1/2k) sum sin(theta_j -
   theta_i)), the case of Wiley, Strogatz & Girvan (Chaos 16, 015103, 2006); the q-twisted
   state theta_j = 2 pi q j / N is linearly stable iff every eigenvalue
   lambda_p = (1/k) sum_{m=1..k} cos(2 pi q m / N) (cos(2 pi p m / N) - 1), p = 1 .. N-1,
   is negative (``stable_twists``); the table gives the largest stable q beside the
   measured windings.
2. Random graphs G(32, p), conditioned on being connected (each ensemble its own draw).
3. Perturbed twisted states on a ring of 24 (k = 1, 2): O_j = exp(2 pi q j / N E_12)
   exp(eps X_j), X_j random skew of unit turn in all of so(d), q = 1, 2, 3, eps = 0.01 and
   0.3: does the twist survive, and in d >= 3, with what total turn and loop class
   (``core.sweep.rings``: the loop's class in pi_1(SO(d)) = Z2)?
"""

NAME = "basins"
HELP = "basins of consensus on rings and random graphs, d = 2, 3, 4; twisted states' fate"

RING_K = {16: list(range(1, 9)), 32: [1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 12, 16],
          64: [1, 2, 3, 4, 6, 8, 11, 14, 17, 20, 22, 24, 32]}
RANDOM_P = [0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.7]
TWIST = {"agents": 24, "k": (1, 2), "q": (1, 2, 3), "eps": (0.01, 0.3)}
#: the critical k/N of Wiley, Strogatz & Girvan (2006) above which only sync is stable
WSG_CRITICAL = 0.34
DIMS = (2, 3, 4)


def add_arguments(p):
    from ..options import at_least, int_list
    p.add_argument("--ensembles", type=at_least(1), default=100,
                   help="ensembles per ring and random-graph cell (default 100)")
    p.add_argument("--twist-ensembles", type=at_least(1), default=40,
                   help="ensembles per perturbed-twist cell (default 40)")
    p.add_argument("--dims", type=int_list(2), default=list(DIMS), help="dimensions (2,3,4)")
    p.add_argument("--t-end", type=at_least(1.0, float), default=12000.0,
                   help="longest run (default 12000)")


def template(t_end, dt=0.5):
    """The study's scene data: Fig. 1's triangles, centroids together, degree weights."""
    from polymatch_ros.core.sweep.scenes import template as load
    data = load("congruent_triangles")
    data["time"] = {"t_end": t_end, "samples": {"every": 5.0}}
    data["integrator"] = {"method": "rkmk4", "dt": dt}
    data["graph"] = {"ring": 1, "normalise": "degree"}
    data["groups"][0]["centroids"] = {"box": [0.0, 0.0]}
    return data


def stable_twists(n, k):
    """The largest q whose q-twisted Kuramoto state on the ring is linearly stable (module doc)."""
    import numpy as np
    m = np.arange(1, k + 1) if 2 * k < n else np.arange(1, n // 2 + 1)
    p = np.arange(1, n)[:, None]
    best = 0
    for q in range(1, n // 2):
        weight = np.cos(2 * np.pi * q * m / n)
        if 2 * k >= n and n % 2 == 0:            # the opposite agent is one neighbour, not two
            weight = weight * np.where(m == n // 2, 0.5, 1.0)
        lam = (weight * (np.cos(2 * np.pi * p * m / n) - 1.0)).sum(axis=1)
        if np.all(lam < -1e-12):
            best = q
    return best


def run_cell(data, cell, ensembles, seed=0, rotations=None):
    """``run_batch`` of one cell (``rotations``: (B, N, d, d) initial rotations, else Haar)."""
    from polymatch_ros.core.sweep.run import run_batch
    from polymatch_ros.core.sweep.scenes import cell_scenes, with_rotations
    scenes = cell_scenes(data, cell, ensembles, seed)
    if rotations is not None:
        scenes = [with_rotations(s, m) for s, m in zip(scenes, rotations)]
    return run_batch(scenes, settle=True)


def rings(args, data, log):
    """{(d, N, k): BatchResult} of the ring study."""
    from polymatch_ros.core.sweep.scenes import Cell
    ks = {8: [1, 4]} if args.quick else RING_K
    out = {}
    for d in _dims(args):
        for n, klist in ks.items():
            for k in klist:
                out[d, n, k] = run_cell(data, Cell(dim=d, agents=n, graph=f"ring:{k}"),
                                        4 if args.quick else args.ensembles)
                log(f"ring d = {d} N = {n} k = {k}: "
                    f"{_count(out[d, n, k], 'matched')} matched, "
                    f"{out[d, n, k].wall_time:.1f} s")
    return out


def random_graphs(args, data, log):
    """{(d, p): (BatchResult, mean degree)} of the random-graph study (N = 32)."""
    import numpy as np

    from polymatch_ros.core.sweep.scenes import Cell, cell_scenes
    n, plist = (8, [0.5]) if args.quick else (32, RANDOM_P)
    b = 4 if args.quick else args.ensembles
    out = {}
    for d in _dims(args):
        for p in plist:
            cell = Cell(dim=d, agents=n, graph=f"random:{p}")
            res = run_cell(data, cell, b)
            scenes = cell_scenes(data, cell, b, 0)
            degree = np.mean([s.model.groups[0].graph.degrees().mean() for s in scenes])
            out[d, p] = (res, degree)
            log(f"random d = {d} p = {p}: {_count(res, 'matched')} matched, "
                f"{res.wall_time:.1f} s")
    return out


def twists(args, data, log):
    """{(d, k, q, eps): BatchResult} of perturbed twisted initial states."""
    import numpy as np

    from polymatch_ros.core.sweep.rings import perturbed, twisted_rotations
    from polymatch_ros.core.sweep.scenes import Cell
    n = 8 if args.quick else TWIST["agents"]
    b = 3 if args.quick else args.twist_ensembles
    out = {}
    for d in _dims(args):
        for k in TWIST["k"][:1] if args.quick else TWIST["k"]:
            for q in TWIST["q"][:2] if args.quick else TWIST["q"]:
                for eps in TWIST["eps"][:1] if args.quick else TWIST["eps"]:
                    base = twisted_rotations(d, n, q)
                    mats = np.array([perturbed(base, eps, np.random.default_rng((s, 7)))
                                     for s in range(b)])
                    res = run_cell(data, Cell(dim=d, agents=n, graph=f"ring:{k}"), b,
                                   rotations=mats)
                    out[d, k, q, eps] = res
                    log(f"twist d = {d} k = {k} q = {q} eps = {eps}: "
                        f"{_count(res, 'matched')} matched")
    return out


def _dims(args):
    """The dimensions to run (--quick: the first two)."""
    return list(args.dims)[:2] if args.quick else list(args.dims)


def _count(result, outcome):
    import numpy as np
    return int(np.sum(result.outcome == outcome))


def run(args, log):
    data = template(200.0 if args.quick else args.t_end)
    ring = rings(args, data, log)
    rand = random_graphs(args, data, log)
    twist = twists(args, data, log)
    from .basins_report import report
    return report(NAME, args, ring, rand, twist)
