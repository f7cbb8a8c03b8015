"""Gymnasium tasks."""

def register_envs() -> None:
    """Registers SurgSim/* tasks (filled by the envs issue)."""

