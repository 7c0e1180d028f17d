"""Task Manager: the queue of tasks, their assignment to robots and their life cycle."""

from backend.tasks.manager import TaskManager, TaskStore
from backend.tasks.model import Task, TaskError, TaskNotFound, TaskState

__all__ = ["Task", "TaskError", "TaskManager", "TaskNotFound", "TaskState", "TaskStore"]
