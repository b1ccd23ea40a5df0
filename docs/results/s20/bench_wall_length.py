import sys, time, math, numpy as np
from ecahd_core.maps import load_map
from ecahd_core.footprint import make_footprint
from ecahd_core.placement import WaypointPlacer
g = load_map("/tmp/s19/office2.yaml"); fp = make_footprint("circle")
pl = WaypointPlacer(g, fp)
rng = np.random.default_rng(0)
a = rng.uniform(5, 55, 2); b = a + rng.uniform(-4, 4, (2000, 2))
A = rng.uniform(5, 55, (500, 2)); B = A + rng.uniform(-8, 8, (500, 2))

# candidate fast version
near_pad = np.pad(g.free_distance < pl._near, 1, constant_values=True)
H, W = g.height, g.width
ox, oy = g.origin[0], g.origin[1]; res = g.resolution
def fast(a, b):
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), b.shape)
    d = b - a
    length = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2)
    counts = np.maximum(np.ceil(length / res).astype(np.int64) + 1, 2)
    n = int(counts.max(initial=2))
    j = np.arange(n)[None, :]
    valid = j < counts[:, None]
    t = np.minimum(j / (counts[:, None] - 1), 1.0)
    x = a[:, 0:1] + t * d[:, 0:1]
    y = a[:, 1:2] + t * d[:, 1:2]
    col = np.clip(np.floor((x - ox) / res), -1, W).astype(np.intp) + 1
    row = np.clip(np.floor((y - oy) / res), -1, H).astype(np.intp) + 1
    near = near_pad[row, col]
    return (near & valid).sum(axis=1) / counts * length
for name, f in (("old", pl.wall_length), ("new", fast)):
    t0 = time.perf_counter()
    for _ in range(5): r1 = f(a, b); r2 = f(A, B)
    print(name, f"{(time.perf_counter()-t0)/5*1e3:.1f} ms")
print("equal", np.array_equal(pl.wall_length(a, b), fast(a, b)), np.array_equal(pl.wall_length(A, B), fast(A, B)), np.abs(pl.wall_length(A,B)-fast(A,B)).max())
from ecahd_core.collision import wall_distance
def ref(a, b):  # the previous implementation
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), b.shape)
    length = np.linalg.norm(b - a, axis=1)
    counts = np.maximum(np.ceil(length / res).astype(np.int64) + 1, 2)
    n = int(counts.max(initial=2)); j = np.arange(n)[None, :]; valid = j < counts[:, None]
    t = np.minimum(j / (counts[:, None] - 1), 1.0)
    pts = a[:, None, :] + t[:, :, None] * (b - a)[:, None, :]
    near = wall_distance(g, pts.reshape(-1, 2)).reshape(len(b), n) < pl._near
    return (near & valid).sum(axis=1) / counts * length
C = rng.uniform(-5, 65, (3000, 2)); D = C + rng.uniform(-10, 10, (3000, 2))
print("committed == previous:", np.array_equal(ref(C, D), pl.wall_length(C, D)), np.array_equal(ref(a, b), pl.wall_length(a, b)))
