"""Grasp-and-pull acceptance test of the contact law at the tissue level (no MuJoCo).

A soft tissue cylinder (mass-spring model, axis z) is squeezed by three flat box jaws 120 degrees
apart that close radially (kinematic poses computed here) and are then held. The tissue is pulled
along its axis by a body force whose magnitude comes from a soft "handle" spring whose far end moves
at constant slow speed (the usual friction-tester rig): the pull ramps up while the grasp holds and
levels off once the tissue slides through the jaws. Coulomb's law predicts gross slip when the pull
reaches mu * N, N = sum of the jaws' normal forces at that moment. Checked for mu = 0.3, 0.6, 1.0:

* while the pull is below half of mu * N the grasp holds (the tissue moves < 1 mm);
* the tissue then slides through the jaws (several mm, following the handle);
* during gross sliding the pull equals mu * N within 10 %.

The jaws are longer than the tissue so no jaw end face can catch the tissue (that would add form
closure to friction). The normal force is measured, not imposed: the spring network couples axial
shear to the squeeze, so N drifts while pulling, and the comparison uses N at the same instant.
"""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs import tissue
from surgsim_envs.contact import BOX, ContactModel, ContactParams
from surgsim_envs.tissue.materials import Material

RADIUS, LENGTH, SPACING = 0.008, 0.04, 0.003        # m
SQUEEZE = 0.0005                                    # m, jaw travel past the rest surface
JAW_HALF = np.array([0.002, 0.003, 0.035])          # m: radial thickness, width, length (> tissue)
DT = 5e-5                                           # s (explicit; tiny snapped surface masses)
HANDLE_STIFFNESS, HANDLE_SPEED = 100.0, 0.01        # N/m, m/s
T_CLOSE, T_SETTLE, T_PULL = 0.15, 0.1, 0.6          # s


def tissue_cylinder():
    """Tet volume of the cylinder (lattice + surface snapping if available, else a lattice cut)."""
    try:
        import trimesh

        from surgsim_envs.geometry.lattice import lattice_volume

        return lattice_volume(trimesh.creation.cylinder(radius=RADIUS, height=LENGTH, sections=48), SPACING)
    except ImportError:  # fallback: lattice box, keep tets whose nodes all lie inside the cylinder
        from surgsim_envs.geometry import Volume, box_volume

        box = box_volume((2 * RADIUS, 2 * RADIUS, LENGTH), SPACING)
        inside = np.hypot(box.nodes[:, 0], box.nodes[:, 1]) <= RADIUS + 1e-9
        tets = box.tets[inside[box.tets].all(axis=1)]
        used = np.unique(tets)
        remap = -np.ones(box.n_nodes, dtype=np.int64)
        remap[used] = np.arange(len(used))
        return Volume(box.nodes[used], remap[tets], name="cylinder")


def jaw_frames():
    """Unit radial directions (3,3) and row-major rotations (3,9) of the three jaws (local x = radial)."""
    ang = np.deg2rad([90.0, 210.0, 330.0])
    er = np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1)
    et = np.stack([-np.sin(ang), np.cos(ang), np.zeros(3)], axis=1)
    ez = np.tile([0.0, 0.0, 1.0], (3, 1))
    mats = np.stack([np.stack([er[k], et[k], ez[k]], axis=1).ravel() for k in range(3)])
    return er, mats


def grasp_and_pull(mu: float, volume):
    """Run the rig; returns arrays (time since pull start s, pull N, jaw normal force N, axial slide m)."""
    material = Material(young=20_000.0, poisson=0.45, density=1000.0, damping=10.0, name="gel")
    model = tissue.make("mass_spring", volume, material)
    cm = ContactModel(model.n_nodes, model.surface_nodes, [mu], ContactParams(stiffness=60.0, damping=0.02))
    er, mats = jaw_frames()
    kind, tool = np.full(3, BOX), np.zeros(3, dtype=int)
    size = np.tile(JAW_HALF, (3, 1))
    com = np.zeros((1, 3))
    weights = model.masses / model.total_mass
    forces = np.zeros_like(model.positions)
    gvel = np.zeros((3, 6))
    travel = 0.0005 + SQUEEZE                          # jaws start 0.5 mm clear of the surface
    z0 = t_pull0 = None
    out = []
    for i in range(int((T_CLOSE + T_SETTLE + T_PULL) / DT)):
        t = i * DT
        s = min(t / T_CLOSE, 1.0)                     # smooth radial closing, then held
        rho = RADIUS + 0.0005 - travel * s * s * (3 - 2 * s)
        gvel[:, 3:] = -er * travel * (6 * s * (1 - s) / T_CLOSE if t < T_CLOSE else 0.0)
        res = cm.compute(model.positions, model.velocities, kind, tool, size, er * (rho + JAW_HALF[0]),
                         mats, gvel, com, DT)
        pull = 0.0
        if t >= T_CLOSE + T_SETTLE:
            zc = weights @ model.positions[:, 2]
            if z0 is None:
                z0, t_pull0 = zc, t
            pull = max(HANDLE_STIFFNESS * (HANDLE_SPEED * (t - t_pull0) - (zc - z0)), 0.0)
            out.append((t - t_pull0, pull, res.report.normal_force[0], zc - z0))
        np.copyto(forces, res.forces)
        forces[:, 2] += pull * weights               # body force: the pull spread by mass
        model.step(DT, forces, res.stiffness)
    assert res.report.contacts[0] > 0
    return np.array(out).T


@pytest.fixture(scope="module")
def volume():
    try:
        tissue.get("mass_spring")
    except ImportError as exc:  # pragma: no cover - only before the model lands
        pytest.skip(f"mass_spring tissue model not available: {exc}")
    return tissue_cylinder()


@pytest.mark.parametrize("mu", [0.3, 0.6, 1.0])
def test_gross_slip_when_pull_reaches_mu_times_grip(mu, volume):
    t, pull, normal, slide = grasp_and_pull(mu, volume)
    ratio = pull / (mu * normal)
    # the grasp holds under a small pull
    holding = ratio < 0.5
    assert holding[:10].all() and slide[holding].max() < 1e-3
    # then the tissue slides through the jaws, following the handle
    assert slide[-1] > 3e-3
    sliding = slide > 2.5e-3                          # well past any elastic stick stretch
    assert sliding.sum() > 100
    # Coulomb: the pull at gross slip equals mu times the jaws' normal force (within 10 %)
    assert np.mean(ratio[sliding]) == pytest.approx(1.0, abs=0.10)
    assert np.all(np.abs(ratio[sliding] - 1.0) < 0.2)
    # and it never exceeded that bound noticeably while the grasp was holding
    assert ratio.max() < 1.1
