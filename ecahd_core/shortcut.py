"""The shortcut rule (ours, beyond the paper): a whole plan that the exact checker finds
collision-free is pulled taut where straight local plans are free by ECAHD's own test.

Why: Algorithm 1's plan is the local plans of its iterations joined end to end. Where a segment's
straight plan costs more than c_th by J, DD (and polishing) bend it round what the cost map holds.
Such bends are needed locally, but once the whole path is known, many of them, and many of SD's
waypoints, can be skipped. On a held-out 36 x 24 m office with the generalist, the joined path
was 1.05-2.18x as long as A*'s (median 1.40 over 12 problems). Pulling it taut cut the median to
1.13 (docs/RESULTS.md, "The shortcut rule").

The test for a shortcut a -> b is the one Algorithm 1 applies to a straight local plan (line 14):
its P^l points, evenly spaced, cost at most c_th by J. In addition, the exact checker must find
the segment free. J's margin keeps the shortcut as far from walls as the straight local plans
the paper accepts. A* paths, by contrast, hug the clearance. The pulled path is judged whole by
the exact checker, including its turns at the kept vertices for footprints that are not circles.
If the pulled path fails that check, the plan is returned unchanged.

Where a corridor or a door is narrower than J's margin allows, no straight plan through it
passes c_th, and the joined path kept DD's and polishing's wiggles there (maze2d-large's circle
robot: 1.12x A*'s length, a 3.2 m problem drawn 4.2 m long). With ``by_peak``, a shortcut also
passes where J's peak along it is no higher than along the stretch of the path it replaces: it
comes no nearer a wall than the path already does, to the cost map's accuracy (a distance field
of cell centres: about a cell; docs/rules.md, "shortcut").

Paths are (N, 2) [m] in the map's frame.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from ecahd_core.cost import CostTerms

# candidates a -> j whose straight plans J judges in one batch
CHUNK = 64
# J's peak a shortcut may exceed its stretch's by (float32 rounding of the same cost map reads)
PEAK_TOLERANCE = 1e-6


def shortcut_path(path: np.ndarray, *, terms: Callable[[torch.Tensor], CostTerms],
                  c_th: float, points: int,
                  exact_check: Callable[[np.ndarray], np.ndarray],
                  by_peak: bool = False) -> np.ndarray:
    """Pull ``path`` taut by straight segments that pass ECAHD's local test.

    Greedy string pulling: from each kept vertex a, the next kept vertex is the furthest vertex j
    such that the straight local plan a -> j (``points`` points, evenly spaced) costs at most
    ``c_th`` by J (or, with ``by_peak``, J's peak along it is no higher than the highest peak of
    the path's own segments from a to j, each as a straight plan of ``points`` points) and the exact
    checker finds the segment free. If no such vertex beyond a + 1 exists, the next kept vertex
    is a + 1 and the path's own segment is kept.

    Args:
        path: (N, 2) [m] the plan, a vertex list whose segments are what the robot follows.
        terms: J of straight plans: (B, P, 2) [m] float32 -> CostTerms (its collision cost and
            its peak, (B,) each; ``CollisionCost.terms``).
        c_th: Algorithm 1's threshold on c^l.
        points: P^l, the points of a straight local plan (>= 2).
        exact_check: the exact checker of a path: (M, 2) [m] -> (M - 1,) bool, True where a
            segment collides (``collision.exact_check_for``).
        by_peak: also pass segments by J's peak (False: c_th only).

    Returns:
        (M, 2) [m], M <= N: a subset of the vertices of ``path``, with the same first and last
        vertex, whose segments pass the test. ``path`` itself (a copy) when the pulled path
        collides as a whole.
    """
    path = np.asarray(path, dtype=np.float64)
    n = len(path)
    if n <= 2:
        return path.copy()
    t = torch.linspace(0.0, 1.0, int(points), dtype=torch.float32)[None, :, None]  # (1, P, 1)
    pts = torch.as_tensor(path, dtype=torch.float32)
    if by_peak:
        # each of the path's own segments as a straight plan: (N - 1, P, 2) -> (N - 1,) peaks
        segs = pts[:-1, None, :] + t * (pts[1:] - pts[:-1])[:, None, :]
        own = terms(segs).peak_cost.numpy().astype(np.float64)
    kept = [0]
    a = 0
    while a < n - 1:
        nxt = a + 1
        far = np.arange(n - 1, a + 1, -1)  # candidates beyond a + 1, furthest first
        for lo in range(0, len(far), CHUNK):
            js = far[lo:lo + CHUNK]
            ends = pts[torch.as_tensor(js)]  # (C, 2)
            plans = pts[a] + t * (ends[:, None, :] - pts[a])  # (C, P, 2)
            judged = terms(plans)  # one J call gives both tests
            ok = (judged.collision_cost <= c_th).numpy()
            if by_peak:  # no nearer a wall than the stretch a -> j already comes
                stretch = np.maximum.accumulate(own[a:])[js - a - 1]  # (C,)
                ok |= judged.peak_cost.numpy() <= stretch + PEAK_TOLERANCE
            ok = ok.tolist()
            found = next((int(j) for j, o in zip(js, ok)
                          if o and not exact_check(path[[a, int(j)]]).any()), None)
            if found is not None:
                nxt = found
                break
        kept.append(nxt)
        a = nxt
    if len(kept) == n:
        return path.copy()
    pulled = path[kept]
    if exact_check(pulled).any():  # a turn at a kept vertex sweeps into a wall
        return path.copy()
    return pulled
