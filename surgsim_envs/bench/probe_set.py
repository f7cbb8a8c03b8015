"""A task's scripted presses for ``surgsim bench task-accuracy``: the inclusions pressed over (and at
their mirror sites), the depths and the spacings the models and the reference are run at."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Inclusion:
    name: str
    position: tuple[float, float]   # m, centre (x, y)
    depth: float                    # m, centre below the top surface
    radius: float                   # m
    contrast: float                 # E_inclusion / E_tissue

    def options(self) -> dict:
        """Palpation-v0's reset options placing this inclusion."""
        return {"inclusion_position": self.position, "inclusion_depth": (self.depth, self.depth),
                "inclusion_radius": (self.radius, self.radius), "stiffness_contrast": (self.contrast, self.contrast),
                "young_scale": (1.0, 1.0)}


@dataclass(frozen=True)
class ProbeSet:
    """A task's scripted presses: inclusions, depths (m), hold (s), the spacings (m) the models are
    run at and the reference's fine spacings (m, descending: its graded lattices' spacing at the
    press site, see :mod:`surgsim_envs.bench.task_reference`)."""

    inclusions: tuple[Inclusion, ...]
    depths: tuple[float, ...]
    hold: float
    spacings: tuple[float, ...]
    reference_spacings: tuple[float, ...]


def mirror(xy) -> tuple[float, float]:
    """The mirror site of ``xy`` (m) through the patch's centre (the origin)."""
    return (-float(xy[0]), -float(xy[1]))


__all__ = ["Inclusion", "ProbeSet", "mirror"]
