"""ecahd_core: the ECAHD algorithms as a plain torch/numpy library (no rclpy).

Modules, by question:
- ``errors``      what went wrong (one exception family for bad input)
- ``maps``        occupancy grids: D4RL mazes, Nav2 map_server YAML, OccupancyGrid layout
- ``costmap``     the differentiable collision cost map read by bilinear interpolation (Eqs. 10-13)
- ``footprint``   robot shapes and their interior sample points R (Sec. III-B)
- ``cost``        the cost function J of Algorithm 2 (lines 11-25), batched
- ``collision``   the exact (non-differentiable) swept-footprint collision checker for evaluation
- ``astar``       A* with footprint clearance, the expert and the classical baseline
- ``dataset``     expert data for the SD / DD / FD models (Sec. IV-A)
- ``diffusion``   schedule + DDIM, denoisers (Transformer, FD's temporal U-Net), sampler, training
- ``guidance``    the cost J as a guide for the sampler (Algorithm 2 line 5)
- ``model_zoo``   training recipes, shipped models and their identity checks
- ``planning``    Algorithm 1: SparseDiffusion (best of N), the rules round it, HierarchicalPlanner
                  (Algorithms 1-2), FullDiffusion, and the online runners the nodes call
- ``validation``  checks of poses and plans from outside, with errors naming the problem
- ``problems``    seeded held-out benchmark problems
- ``viz``         figures
- ``bench``       benchmarks; ``commands``: the ``ecahd`` subcommands that need no ROS
"""

__version__ = "0.1.0"
