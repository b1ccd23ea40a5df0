import os
from ecahd_core.progress import GoalField
GEO = os.environ.get("GEO", "1") == "1"
from ecahd_core.collision import exact_check_for
from ecahd_core.cost import CollisionCost
from ecahd_core.model_zoo import load_model
from ecahd_core.placement import placer_for
from ecahd_core.planner import DenseConfig, HierarchicalPlanner, SparseConfig, SparseDiffusion
from ecahd_core.navigation import auto_replan_spacing
def build(grid, fp):
    cost = CollisionCost.build(grid, fp).as_tuple()
    sd = SparseDiffusion(load_model("sd", grid, footprint=fp), SparseConfig(selection="collision_aware", precision="auto"), cost=cost, placer=placer_for(grid, fp, None))
    return HierarchicalPlanner(sd, load_model("dd", grid, footprint=fp), costmap=cost[0], footprint_points=cost[1], cost_config=cost[2], dense=DenseConfig(), exact_check=exact_check_for(grid, fp), replan_spacing=auto_replan_spacing(grid, sd.expert_spacing), backtracks=2, goal_field=GoalField(grid, fp) if GEO else None)
