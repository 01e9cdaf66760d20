"""robosuite arm tasks of the paper (Sec. 4): StackCubes, PushAnyOne, CollectThreeBalls.

Each is a ``ManipulationEnv`` subclass (one per module) sharing
:class:`~hubsgo_ppl.envs.robosuite.base.SubgoalManipulationEnv`; Gymnasium access goes through
:func:`~hubsgo_ppl.envs.robosuite.gym_wrapper.make_robosuite_task` (``hubsgo_ppl.envs.make``).
"""

import logging

# robosuite prints notices about its own installation on every import and env build (no private macro
# file, the optional robot models and whole-body IK these tasks do not use, the controller file it
# loads); they are dropped so that a run's output and a refusal's one line stay readable. Any other
# robosuite message still shows.
_NOTICES = ("No private macro file", "It is recommended to use a private macro file", "To setup, run:",
            "Could not import robosuite_models", "Could not load the mink-based",
            "Loading controller configuration")


class _InstallNotices(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(_NOTICES)


logging.getLogger("robosuite_logs").addFilter(_InstallNotices())

from .base import SubgoalKind, SubgoalManipulationEnv, osc_position_controller, set_sampler_rng
from .collect_three_balls import CollectThreeBalls
from .gym_wrapper import TASK_CLASSES, RobosuiteTaskEnv, make_robosuite_task
from .push_any_one import PushAnyOne
from .stack_cubes import StackCubes

__all__ = ["SubgoalManipulationEnv", "SubgoalKind", "osc_position_controller", "set_sampler_rng",
           "StackCubes", "PushAnyOne", "CollectThreeBalls",
           "TASK_CLASSES", "RobosuiteTaskEnv", "make_robosuite_task"]
