"""robosuite arm tasks of the paper (Sec. 4): StackCubes, PushAnyOne, CollectThreeBalls.

Each is a ``ManipulationEnv`` subclass (one per module) sharing
:class:`~hubsgo_ppl.envs.robosuite.base.SubgoalManipulationEnv`; Gymnasium access goes through
:func:`~hubsgo_ppl.envs.robosuite.gym_wrapper.make_robosuite_task` (``hubsgo_ppl.envs.make``).
"""

from .base import SubgoalKind, SubgoalManipulationEnv, osc_position_controller, set_sampler_rng
from .collect_three_balls import CollectThreeBalls
from .gym_wrapper import TASK_CLASSES, RobosuiteTaskEnv, make_robosuite_task
from .push_any_one import PushAnyOne
from .stack_cubes import StackCubes

__all__ = ["SubgoalManipulationEnv", "SubgoalKind", "osc_position_controller", "set_sampler_rng",
           "StackCubes", "PushAnyOne", "CollectThreeBalls",
           "TASK_CLASSES", "RobosuiteTaskEnv", "make_robosuite_task"]
