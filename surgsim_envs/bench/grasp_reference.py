"""A force reference for the grasp tasks' closures and pulls: quasi-static FEM in the task's own scene.

The grasp tasks (Grasp-v0, Slippage-v0) close a three-jaw grasper on the tip of an organ held by
its ligaments (:func:`surgsim_envs.scene.grasp_config`; spleen by default, lattice 11 mm). The
reference solves the same closures and pulls as a continuum: the task's scene config (organ,
anchors, grasper and its placement, time step, tissue sub-cycles, friction) with

* ``fem_static`` (linear tets, averaged nodal pressure, equilibrium at every physics step) on the
  organ's lattice at a finer spacing, the material elastic (``relax_fraction`` 0, the task's
  friction kept: :func:`surgsim_envs.bench.task_reference.elastic`);
* a contact stiffness per unit surface area (:data:`CONTACT_STIFFNESS_PER_AREA`, the node's penalty
  ``k = that x h^2``, normal and tangential): the task's contact is a fixed 200 N/m per node, so
  its stiffness per area grows as 1/h^2 under refinement and would change the contact law with the
  mesh. The jaws are flat boxes wider than the lattice, so nodes alone sample them (no surface
  samples: they help a sphere meet the faces between nodes, not a flat jaw).

The organ's lattice is uniform (the grasp scene fills the organ's mesh), so the reference refines
the whole lattice; the jaws are driven by the task's own commands (:func:`jaw_opening` targets at
the task's closing speed for Grasp-v0; the jaw and pull-motor schedule of Slippage-v0,
:func:`surgsim_envs.envs.slippage.terms.control_schedule`) and read by the same functions the tasks'
rewards read (``Simulation.jaw_forces``, :class:`surgsim_envs.envs.grasp.terms.SlipTracker`).

Not converged to 1 % (measured on a 2-core host, friction on): Grasp-v0's closures (mu 0.8) from
11 to 1.94 mm changed the jaws' summed normal by 1-80 % per refinement, by 2.4-3.1 % from 3.9 to
2.75 mm and by 6.1-10.1 % from 2.75 to 1.94 mm (22,700 nodes, 11 minutes at load 3.5, 3.9 GB),
single jaws by up to 20 % there: the sequence alternates and shows no sign of settling;
Slippage-v0's pulls from 11 to 3.9 mm changed by 2.2-7.4 % in the last refinement. The readings
also move with the contact stiffness per area (:data:`CONTACT_STIFFNESS_PER_AREA`): the organ tip
is stiff in confined compression and each jaw meets a few nodes, so the penalty's penetration is
not negligible against the squeeze. With the jaws' edges rounded (``jaw_edges="round"``) and contact
samples at h/3 the contact is resolved (h/3 and h/4 within 1 %; at 1.375 mm the nodes alone read
within 1 % of the samples), but the lattice is not: each refinement from 3.89 to 1.375 mm (61,508
nodes, 17 minutes, 7.9 GB) lowers the closures' summed normals by 3.5-12 %, the change not
shrinking; on a lattice graded towards the tip (``graded_tip``) the change from 1.375 to 0.97 mm
was 1.8-4.6 %, after 7.8-9.6 % (docs/task_accuracy.md). Units: m, N, s.
"""

from __future__ import annotations

import copy


#: N/m^3, normal and tangential contact stiffness per unit surface area of the reference, the value
#: task_reference uses for the palpation presses. The grasp readings depend on it (measured at 7.8 mm,
#: mu 0.8: the jaws' summed normal at the open-most closure read 0.93, 0.54, 1.10 and 1.04 N at 1e7,
#: 3e7, 1e8 and 3e8; frictionless 0.44, 0.40 and 0.34 N at 3e7, 1e8 and 3e8; 1e9 diverged), so it is
#: part of the reference's definition, stated with its results
CONTACT_STIFFNESS_PER_AREA = 1e8
REFERENCE_MODEL = "fem_static"
REFERENCE_OPTIONS = {"solver": "auto", "cache_mb": 1000.0}


def reference_simulation(env, spacing: float, jaw_edges: str | None = None, surface_samples: int | None = None,
                         cache_mb: float | None = None, graded_tip: float | None = None):
    """A Simulation of ``env``'s grasp scene (its organ, anchors, grasper and the grasper's placement,
    dt, sub-cycles; ``env`` built by the task at its default lattice with ``fem_static`` and the
    elastic material) with the organ's lattice at ``spacing`` (m) and the reference's contact:
    stiffness :data:`CONTACT_STIFFNESS_PER_AREA` x spacing^2 per node, nodes only.

    The grasper keeps the placement the task gave it on its default lattice: the task places it
    around the lattice's tip nodes (:func:`surgsim_envs.scene.builder.place_grasper_around_tip`), so
    its open radius (34.2-36.2 mm), its axis's height (24.8-25.8 mm) and its sideways offset
    (4.2-6.3 mm) change with the lattice from 15 to 2.75 mm, and with them the jaw opening of a
    closure action; the reference refines the organ only, under one grasper. ``jaw_edges`` ("sharp"
    or "round", :class:`~surgsim_envs.scene.config.GrasperConfig`) overrides the task's jaws' edges
    in the tissue contact; None keeps them. ``surface_samples`` (n >= 2 edge subdivisions,
    ``ContactConfig.surface_samples``) adds contact samples between the nodes, each with the per-node
    stiffness shared by area; None: nodes only. ``cache_mb``: the memory (MB) of fem_static's cached
    compliance columns (72 x nodes bytes each), None: :data:`REFERENCE_OPTIONS`' 1000 MB, which holds
    the loaded nodes of a step down to about 2 mm (the 1.375 mm lattice, 61,508 nodes, ran with 6000).
    ``graded_tip`` (m): the lattice is ``spacing`` only over that length of the organ's +x end, where
    the jaws grasp, and grows to 2.75 mm along the held rest
    (:func:`surgsim_envs.bench.grasp_tip_lattice.tip_graded_volume`, filled into the task's placed organ
    surface); the per-node contact stiffness is that of ``spacing``, so the jaws must meet the organ
    within that length (0.036 m covers the loaded nodes of the probe sets). None: the uniform lattice."""
    from surgsim_envs.scene import Simulation, build_scene

    sim = env.sim
    cfg = copy.deepcopy(sim.scene.config)
    tissue = cfg.tissues[0]
    if graded_tip is not None:
        from surgsim_envs.bench.grasp_tip_lattice import tip_graded_volume

        volume = tip_graded_volume(tissue, spacing, graded_tip)
        lo, hi = volume.bounds()
        tissue.organ, tissue.volume_options = volume, {}
        tissue.position = tuple(float(c) for c in (lo + hi) / 2.0)   # placed where it was filled
    tissue.spacing = tissue.resolution = float(spacing)
    tissue.options = {**dict(tissue.options), **REFERENCE_OPTIONS}
    if cache_mb is not None:
        tissue.options["cache_mb"] = float(cache_mb)
    cfg.contact.stiffness = CONTACT_STIFFNESS_PER_AREA * float(spacing) ** 2
    cfg.contact.stiffness_per_area = None            # the task's "auto" would scale by the median edge instead
    cfg.contact.tangential_stiffness = None          # = the normal one
    cfg.contact.surface_samples = surface_samples
    if jaw_edges is not None:
        for tool in cfg.tools:
            if hasattr(tool, "jaw_edges"):
                tool.jaw_edges = jaw_edges
    return Simulation(build_scene(cfg), dt=sim.dt, substeps=sim.substeps, tissue_subcycles=sim.tissue_subcycles)


def set_friction(sim, mu: float, static_ratio: float) -> None:
    """Every tool's Coulomb coefficient ``mu`` (static ``static_ratio * mu``), as the tasks set it per episode."""
    for contact in sim.contacts.values():
        contact.tool_friction[:] = mu
        contact.tool_static_friction[:] = static_ratio * mu


__all__ = ["CONTACT_STIFFNESS_PER_AREA", "REFERENCE_MODEL", "REFERENCE_OPTIONS", "reference_simulation",
           "set_friction"]
