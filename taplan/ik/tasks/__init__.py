"""Tasks of the differential IK: least-squares objectives on the joint displacement."""

from taplan.ik.tasks.damping_task import DampingTask
from taplan.ik.tasks.frame_task import FrameTask
from taplan.ik.tasks.posture_task import PostureTask
from taplan.ik.tasks.relative_frame_task import RelativeFrameTask
from taplan.ik.tasks.task import Task

__all__ = ["Task", "FrameTask", "RelativeFrameTask", "PostureTask", "DampingTask"]
