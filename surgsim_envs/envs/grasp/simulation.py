"""The coarse grasp scene of the grasp tasks (Grasp-v0, Slippage-v0).

The scene is :func:`surgsim_envs.scene.grasp_config` with a coarse lattice (spleen 11 mm: 232
nodes; liver lobe 15 mm: 296 nodes), the explicit (symplectic) integrator when it is stable over
the whole stiffness randomisation (mass_spring: critical dt 0.67 ms / 0.95 ms against a 0.4 ms
step), else the model's "auto", built once per organ and cached by the env.
"""

from __future__ import annotations

from surgsim_envs.errors import ConfigError

#: lattice spacing (m) per organ for the RL tasks (stable explicit step at 0.5 ms)
ORGAN_SPACING = {"spleen": 0.011, "liver_lobe": 0.015}
#: lattice spacing (m) of any other organ (a surface mesh file) in the grasp tasks
MESH_SPACING = 0.011


def check_grasp_organ(organ, what: str = "organ") -> None:
    """ConfigError unless ``organ`` is one of :data:`ORGAN_SPACING`, an existing mesh file (surface:
    filled with a lattice; .vtk: tets) or a :class:`surgsim_envs.geometry.Volume`. The mesh itself
    is checked (closed, no self-intersections) when the task builds it
    (:func:`surgsim_envs.geometry.organ_volume`)."""
    from pathlib import Path

    from surgsim_envs.geometry.loaders import SURFACE_SUFFIXES, TET_SUFFIXES
    from surgsim_envs.geometry.volume import Volume

    if isinstance(organ, Volume) or (isinstance(organ, str) and organ in ORGAN_SPACING):
        return
    suffixes = SURFACE_SUFFIXES + TET_SUFFIXES
    if isinstance(organ, (str, Path)) and Path(organ).suffix.lower() in suffixes:
        if not Path(organ).is_file():
            raise ConfigError(f"{what}={str(organ)!r}: no such mesh file; give an existing closed mesh "
                              f"({', '.join(suffixes)})")
        return
    raise ConfigError(f"{what}={organ!r}; choose one of {sorted(ORGAN_SPACING)}, a closed mesh file "
                      f"({', '.join(suffixes)}) or a surgsim_envs.geometry.Volume")


def organ_key(organ):
    """Cache key of an organ: its name or path, or the Volume object's id."""
    from pathlib import Path

    return str(organ) if isinstance(organ, (str, Path)) else id(organ)


def build_grasp_simulation(organ: str, dt: float, substeps: int, closing_speed: float, resolution=None,
                           error_tolerance: float = 0.1, step_budget_us: float = 5_000.0, model: str = "mass_spring",
                           integrator: str = "symplectic", max_young_scale: float = 1.0, tissue_subcycles: int = 1,
                           material="spleen", contact_stiffness_per_area=None, jaw_edges: str = "sharp"):
    """A Simulation of the grasp scene for ``organ``: "spleen" or "liver_lobe", a closed mesh file
    (lattice spacing :data:`MESH_SPACING`) or a Volume (:func:`check_grasp_organ`).

    resolution: None (the organ's :data:`ORGAN_SPACING`), a spacing in m, or "auto" (the cheapest
    measured mass-spring/symplectic spacing meeting ``error_tolerance`` (fraction) and
    ``step_budget_us`` (us per simulated ms); see :class:`surgsim_envs.scene.TissueConfig`).
    integrator: asked for (if the model has it); an explicit one that is not stable at ``dt`` over
    the whole stiffness randomisation (Young's modulus up to ``max_young_scale``) is replaced by
    the model's "auto" (:func:`surgsim_envs.envs.tissue_setup.integrator_for_range`).
    tissue_subcycles: tissue + contact steps of ``dt`` per MuJoCo step (see :class:`Simulation`).
    material: the organ's material (a preset name, a Material or a dict, :func:`surgsim_envs.materials.get_material`).
    contact_stiffness_per_area: the jaws' contact stiffness per unit surface area (N/m^3), "auto" or None
    (the scene's stiffness per node); ``ContactConfig.stiffness_per_area``.
    jaw_edges: "sharp" or "round", the jaws' edges in the tissue contact (``GrasperConfig.jaw_edges``).
    """
    from surgsim_envs.envs.tissue_setup import integrator_for_range, tissue_options
    from surgsim_envs.scene import Simulation, grasp_config, grasp_scene

    check_grasp_organ(organ)
    cfg = grasp_config(organ=organ, model=model)
    t = cfg.tissues[0]
    t.material = material
    t.spacing = ORGAN_SPACING.get(organ, MESH_SPACING) if isinstance(organ, str) else MESH_SPACING
    t.resolution, t.error_tolerance, t.step_budget_us = resolution, error_tolerance, step_budget_us
    t.options = tissue_options(model, integrator)
    cfg.tool("grasper").closing_speed = float(closing_speed)
    cfg.tool("grasper").jaw_edges = jaw_edges
    cfg.dt = float(dt)
    cfg.contact.stiffness_per_area = contact_stiffness_per_area
    sim = Simulation(grasp_scene(cfg), dt=dt, substeps=substeps, tissue_subcycles=tissue_subcycles)
    switch = integrator_for_range(sim.tissue(), dt, max_young_scale)
    if switch is None:
        return sim
    t.options = {**t.options, "integrator": switch}
    return Simulation(grasp_scene(cfg), dt=dt, substeps=substeps, tissue_subcycles=tissue_subcycles)
