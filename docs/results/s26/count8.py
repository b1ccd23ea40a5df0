"""count7.py (docs/results/s25) with the planner of geo_lib.py: python count8.py MAP SEED N ROBOT
OUT.npz (ECAHD_MODELS=M, PYTHONPATH=code:this folder:docs/results/s25)"""
import runpy, sys
import geo_lib
sys.modules["count6_lib"] = geo_lib
runpy.run_path(__import__("os").path.join(__import__("os").path.dirname(__import__("os").path.abspath(__file__)), "..", "s25", "count7.py"), run_name="__main__")
