"""Algorithm 1 (paper Sec. III-A) and its parts, one home for every planning decision.

Modules, by question:
- ``sparse``        Sparse Diffusion: N candidates in one batch, best of N (lines 2-11)
- ``rules``         our rules round SD, as one object (:class:`~ecahd_core.planning.rules.SparseStage`):
                    the free-first-leg rule, the subgoal rule, the settle rule, the forced last
                    plan; one iteration's global plan, for the offline planner and the nodes alike
- ``horizon``       how many waypoints a re-plan keeps (P^g - p; our replan spacing)
- ``dense``         the local stage (lines 13-18, Algorithm 2): J check, DD, keep-better,
                    polishing, the exact rule (DenseStage), for the offline planner,
                    local_refiner and the safety net alike
- ``hierarchical``  Algorithm 1 over a whole problem: SparseStage's plans, DenseStage's local
                    plans in one batch, backtracking: ``ecahd plan`` and the planning benchmarks
- ``full``          the Full Diffusion baseline
- ``online``        the online global half: when to re-plan (GlobalRunner) and what to plan
                    (OnlinePlanner, over SparseStage): global_planner's core
- ``local``         the online local half: segments refined ahead, pure pursuit (LocalRunner,
                    SegmentRefiner over DenseStage): local_refiner's core
- ``detour``        A* detours round what the robot knows (the fallback)
"""
