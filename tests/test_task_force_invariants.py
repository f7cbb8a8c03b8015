"""Task-level force invariants in the palpation scene (Palpation-v0; PalpationPress-v0 builds the same
scene), for every registered tissue model the task accepts.

Each check drives the task's own scene (``env.unwrapped.sim``): the probe hovers 2 mm above a site,
descends at the task's probe speed to a depth below the rest surface, and is held there; the
quasi-static force is the mean F_z on the probe over the last 50 ms of the hold.

* contact is unilateral: frictionless, the tissue never pulls the probe towards itself (F_z >= 0 on
  a probe pressed from above), at any physics step of a press, its hold and the retraction;
* the force rises with depth at one site;
* a stiffer inclusion never lowers the force above it (contrast C against contrast 1, the same
  press), and raises it where the converged reference does (REFERENCE_RATIOS: graded fem_static,
  0.25 ms steps; scripts/contrast_reference_ratios.py);
* the dent follows the probe: frictionless, no surface node lies inside the pressed tip deeper than
  half the press depth (the penalty contact's compliance), so the probe does not sink through;
* frictionless, the quasi-static force at a pose does not depend on how the probe got there
  (straight down, or down beside the site and slid in at depth), within 2 %;
* forces converge under refinement: the task-accuracy reference (quasi-static FEM with a contact
  stiffness per unit area, surface samples, the task's friction) changes less with each refinement
  at an observed order that Richardson extrapolation can use (bench/task_reference.py).

The default model runs in the default test run (one case per invariant); every model under
``-m slow``. Models the task refuses (capability) are skipped by name: the surface-only ``diffusion``
lacks ``subsurface_stiffness`` (its interior carries nothing), and a slow test measures why.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs import tissue
from surgsim_envs.envs.palpation import PalpationConfig
from surgsim_envs.tissue.capabilities import CapabilityError

TASK = "SurgSim/Palpation-v0"
DEFAULT_MODEL = PalpationConfig.model
#: the reported case: 5x inclusion of radius 7 mm, centre 11 mm deep under (0.02, 0), seed 5
INCLUSION = {"inclusion_position": (0.02, 0.0), "inclusion_depth": (0.011, 0.011),
             "inclusion_radius": (0.007, 0.007)}
SEED = 5
#: materials: the liver preset frictionless (the contact-only invariants); elastic as well for the path
#: test (the liver's Maxwell branches remember the path, which is physics, not contact)
FRICTIONLESS = {"preset": "liver", "friction": 0.0}
FRICTIONLESS_ELASTIC = {"preset": "liver", "friction": 0.0, "relax_fraction": 0.0}
HOVER = 0.002          # m above the rest surface before a press
READ_WINDOW = 0.05     # s, the quasi-static reading averages F_z over this
#: numerical allowance of "never lowers": a contrast-1 and a contrast-C press read within this
#: fraction of each other when the inclusion is too deep to matter
NEVER_LOWER_SLACK = 0.01


def _accepted_models() -> list:
    """Every registered model, those Palpation-v0 refuses (a capability it lacks) marked skip by name."""
    from surgsim_envs.envs.palpation import PalpationEnv

    out = []
    for name in tissue.names():
        caps = tissue.registry.get(name).capabilities
        needed = list(PalpationEnv.REQUIRES) + (["implicit_contact"] if "quasi_static" in caps else [])
        missing = [c for c in needed if c not in caps]
        if missing:
            out.append(pytest.param(name, marks=pytest.mark.skip(reason=f"{TASK} refuses {name}: no {missing[0]!r}")))
        else:
            out.append(name)
    return out


def _env(model: str, material=None, resolution=None):
    """The task with ``model``: at its default lattice for the default model, on the 10 mm lattice for
    the others (where the mass-spring family steps explicitly; the slow matrix stays affordable)."""
    kw = {"model": model}
    if resolution is None and model != DEFAULT_MODEL:
        resolution = 0.01
    if material is not None:
        kw["material"] = material
    if resolution is not None:
        kw["resolution"] = resolution
    return gym.make(TASK, **kw)


def _reset(env, contrast: float, seed: int = SEED, **options):
    env.reset(seed=seed, options={**INCLUSION, "stiffness_contrast": (contrast, contrast), **options})


def _run(env, target, duration: float, speed: float | None = None, trace: list | None = None) -> None:
    """Move the probe target to ``target`` (m) and advance ``duration`` s; F_z of every physics step
    into ``trace`` if given."""
    u = env.unwrapped
    sim = u.sim
    speed = u.config.probe_speed if speed is None else speed
    sim.set_tool_target("probe", np.asarray(target, dtype=float), speed=speed)
    steps = int(round(duration / sim.dt))
    if trace is None:
        sim.physics_step(steps)
        return
    for _ in range(steps):
        sim.physics_step(1)
        trace.append(float(sim.tool_force("probe")[2]))


def _tip_z(env, depth: float) -> float:
    """Tip-centre height (m) with the tip's lowest point ``depth`` m below the rest surface."""
    u = env.unwrapped
    return u.surface_z + u.config.tip_radius - depth


def _reading(env) -> float:
    """Quasi-static F_z (N): mean over the next READ_WINDOW s with the target held."""
    trace: list = []
    sim = env.unwrapped.sim
    for _ in range(int(round(READ_WINDOW / sim.dt))):
        sim.physics_step(1)
        trace.append(float(sim.tool_force("probe")[2]))
    return float(np.mean(trace))


def press_force(env, site, depth: float, hold: float = 0.5, trace: list | None = None) -> float:
    """Straight-down press at ``site`` (x, y) m to ``depth`` m, held ``hold`` s: the quasi-static F_z (N)."""
    x, y = site
    _run(env, (x, y, _tip_z(env, -HOVER)), 0.35, trace=trace)          # over the site, 2 mm above
    descend = (depth + HOVER) / env.unwrapped.config.probe_speed
    _run(env, (x, y, _tip_z(env, depth)), descend + hold, trace=trace)
    return _reading(env)


def slide_in_force(env, site, depth: float, offset: float = 0.008, slide_speed: float = 0.02,
                   hold: float = 0.5) -> float:
    """Press ``offset`` m beside ``site`` (-x) to ``depth``, slide in at depth at ``slide_speed`` m/s, hold."""
    x, y = site
    _run(env, (x - offset, y, _tip_z(env, -HOVER)), 0.35)
    _run(env, (x - offset, y, _tip_z(env, depth)), (depth + HOVER) / env.unwrapped.config.probe_speed + 0.05)
    _run(env, (x, y, _tip_z(env, depth)), offset / slide_speed, speed=slide_speed)
    _run(env, (x, y, _tip_z(env, depth)), hold)
    return _reading(env)


# ----------------------------------------------------------------------------------------------
# the invariants, one function each (model in, assertion out)
def check_unilateral(model: str, site=(0.02, 0.0), depth: float = 0.008) -> None:
    env = _env(model, FRICTIONLESS)
    _reset(env, 5.0)
    trace: list = []
    f = press_force(env, site, depth, trace=trace)
    x, y = site
    _run(env, (x, y, _tip_z(env, -HOVER)), (depth + HOVER) / env.unwrapped.config.probe_speed + 0.2, trace=trace)
    env.close()
    trace = np.asarray(trace)
    assert f > 0.0, f"{model}: a press {depth * 1e3:.0f} mm deep reads {f:.4f} N"
    # the only force on a probe pressed from above onto a flat slab is the tissue pushing it up
    assert trace.min() >= -1e-9 * max(f, 1e-3), (
        f"{model}: frictionless contact pulls the probe towards the tissue: F_z = {trace.min():.4g} N at physics "
        f"step {int(trace.argmin())} of the press, hold and retraction")
    assert trace[-1] == 0.0, f"{model}: the retracted probe (2 mm above the rest surface) still reads {trace[-1]:.4g} N"


def check_depth_monotone(model: str, site=(0.02, 0.0), depths=(0.002, 0.004, 0.006, 0.008)) -> list:
    env = _env(model)
    forces = []
    for d in depths:
        _reset(env, 5.0)
        forces.append(press_force(env, site, d))
    env.close()
    assert all(b > a for a, b in zip(forces, forces[1:])), (
        f"{model}: force at {site} m against depth {[round(d * 1e3) for d in depths]} mm: "
        f"{[round(f, 4) for f in forces]} N does not rise")
    return forces


def contrast_ratio(model: str, site=(0.02, 0.0), depth: float = 0.008, contrast: float = 5.0, material=None,
                   resolution=None) -> float:
    """F(contrast) / F(contrast 1) of the same press over the inclusion (``resolution``: lattice spacing, m)."""
    env = _env(model, material, resolution)
    _reset(env, contrast)
    stiff = press_force(env, site, depth)
    _reset(env, 1.0)
    plain = press_force(env, site, depth)
    env.close()
    return stiff / plain


def path_difference(model: str, site=(0.02, 0.0), depth: float = 0.005) -> tuple[float, float]:
    """(straight-down, slid-in) quasi-static forces (N), frictionless and elastic; same total time."""
    env = _env(model, FRICTIONLESS_ELASTIC)
    _reset(env, 5.0)
    straight = press_force(env, site, depth, hold=0.5 + 0.008 / 0.02 + 0.05)
    _reset(env, 5.0)
    slid = slide_in_force(env, site, depth)
    env.close()
    return straight, slid


def probe_penetration(env) -> float:
    """m: how far the deepest surface node lies inside the probe's spherical tip (0 if none does): the
    surface dents under the probe, so only the penalty contact's own compliance puts nodes inside."""
    u = env.unwrapped
    tissue = u.sim.tissue()
    tip, radius = u.sim.tool_position("probe"), u.config.tip_radius
    top = np.abs(tissue.rest_positions[:, 2] - u.surface_z) < 1e-9
    p = tissue.positions[top]
    r2 = ((p[:, :2] - tip[:2]) ** 2).sum(axis=1)
    under = r2 < radius ** 2
    lowest = tip[2] - np.sqrt(radius ** 2 - r2[under])         # the tip's underside above each node
    return float(max(0.0, (p[under, 2] - lowest).max(initial=0.0)))


#: the dent follows the probe: frictionless, no surface node lies deeper inside the tip than this
#: fraction of the press depth (measured, 4 and 8 mm presses on and off the lattice nodes: mass_spring
#: 0.14-0.23 and fem 0.19-0.31, the penalty contact's compliance; the surface-only diffusion 0.78-0.85
#: on a node, where nothing under the surface holds the pressed node up)
MAX_PENETRATION = 0.5


def check_dent_follows_probe(model: str, site=(0.02, 0.0), depth: float = 0.008) -> float:
    env = _env(model, FRICTIONLESS)
    _reset(env, 5.0)
    f = press_force(env, site, depth)
    sunk = probe_penetration(env)
    env.close()
    assert sunk <= MAX_PENETRATION * depth, (
        f"{model}: the probe pressed {depth * 1e3:.0f} mm at {site} m ({f:.3f} N) sinks {sunk * 1e3:.2f} mm "
        f"through the surface (more than {MAX_PENETRATION:.2f} of the depth)")
    return sunk


# ----------------------------------------------------------------------------------------------
# default run: the default model, one case each
def test_default_model_contact_is_unilateral_through_press_and_retraction():
    check_unilateral(DEFAULT_MODEL)


def test_default_model_force_rises_with_depth_over_the_inclusion():
    check_depth_monotone(DEFAULT_MODEL, depths=(0.003, 0.0055, 0.008))


def reference_contrast(depth_mm: int = 7) -> float:
    """The converged reference's force over the 5x lump / at its mirror site (the same press on
    homogeneous tissue) at ``depth_mm``: the shipped task-accuracy table (docs/task_accuracy.md)."""
    import json
    from importlib import resources

    table = json.loads(resources.files("surgsim_envs.tissue.data").joinpath("task_accuracy_table.json").read_text())
    ref = table["references"][TASK]["forces_N"]
    return ref[f"0/over/{depth_mm}mm"] / ref[f"0/mirror/{depth_mm}mm"]


def test_default_model_stiffer_inclusion_raises_the_force_above_it():
    """The reported case (5x inclusion, r 7 mm, 11 mm deep, 8 mm press over it) against the same press
    with contrast 1: the converged reference reads 1.35x at 7 mm (its lump against its mirror site).
    The default must feel at least half of that rise and not over-read it by more than the task's
    tolerance (the plain spring network read 0.66x: its surface node over the stiff column snapped
    sideways off the probe, docs/models/mass_spring.md)."""
    ratio, ref = contrast_ratio(DEFAULT_MODEL), reference_contrast()
    assert 1.0 + 0.5 * (ref - 1.0) <= ratio <= ref * 1.1, (
        f"{DEFAULT_MODEL}: 5x inclusion reads {ratio:.3f}x the homogeneous force above it; the reference {ref:.3f}x")


def test_default_model_frictionless_force_does_not_depend_on_the_path():
    straight, slid = path_difference(DEFAULT_MODEL)
    assert abs(slid - straight) <= 0.02 * straight, (
        f"{DEFAULT_MODEL}: straight down {straight:.4f} N, slid in at depth {slid:.4f} N")


def test_default_model_dent_follows_the_probe():
    check_dent_follows_probe(DEFAULT_MODEL)


@pytest.mark.parametrize("task", [TASK, "SurgSim/PalpationPress-v0"])
def test_palpation_tasks_refuse_a_surface_only_model_by_name(task):
    """``diffusion`` is surface-only: its interior carries nothing, so an inclusion below the surface
    cannot stiffen it and the probe sinks through the surface it presses (the slow test below measures
    both). The palpation tasks refuse it, naming the model, the missing capability and what serves."""
    with pytest.raises(CapabilityError, match=rf"tissue model 'diffusion' cannot serve {task}: it lacks the "
                                              r"capability 'subsurface_stiffness' \(the interior carries load.*"
                                              rf"models that serve {task}: \[.*'mass_spring'.*'fem'.*\]"):
        gym.make(task, model="diffusion")


# ----------------------------------------------------------------------------------------------
# -m slow: every model the task accepts
MODELS = _accepted_models()


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
def test_every_model_contact_is_unilateral(model):
    check_unilateral(model)


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("site", [(0.02, 0.0), (-0.02, 0.0)], ids=["over", "mirror"])
def test_every_model_force_rises_with_depth(model, site):
    check_depth_monotone(model, site)


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("site", [(0.02, 0.0), (-0.02, 0.0)], ids=["over", "mirror"])
@pytest.mark.parametrize("depth", [0.004, 0.008])
def test_every_model_dent_follows_the_probe(model, site, depth):
    check_dent_follows_probe(model, site, depth)


@pytest.mark.slow
def test_the_surface_only_model_fails_what_the_palpation_tasks_refuse_it_for(monkeypatch):
    """The refusal's reason, measured: built in Palpation-v0's scene anyway (the capability check
    lifted), ``diffusion`` lets the probe sink through the surface over the reported inclusion and
    feels the 5x lump less than a third as much as ``fem`` does (fem about 2.1x, diffusion about 1.1x)."""
    from surgsim_envs.envs.palpation import PalpationEnv

    monkeypatch.setattr(PalpationEnv, "REQUIRES", ("forces",))
    with pytest.raises(AssertionError, match="sinks .* mm through the surface"):
        check_dent_follows_probe("diffusion")
    ratio, ref = contrast_ratio("diffusion"), contrast_ratio("fem")
    assert ratio - 1.0 < (ref - 1.0) / 3.0, f"diffusion reads {ratio:.3f}x over the 5x lump where fem reads {ref:.3f}x"


#: contrast cases: the reported one, a weak and a strong inclusion, a shallow press, a site off the lattice
CONTRAST_CASES = [((0.02, 0.0), 0.008, 5.0), ((0.02, 0.0), 0.008, 2.0), ((0.02, 0.0), 0.006, 10.0),
                  ((0.02, 0.0), 0.004, 5.0), ((0.017, 0.004), 0.008, 5.0)]


#: F(C) / F(1) of CONTRAST_CASES in the converged reference's scene (graded fem_static, fine spacing
#: 2 mm, physics step 0.25 ms, elastic liver with its friction): ``python
#: scripts/contrast_reference_ratios.py``. The explicit ``fem`` at 10 mm, once the comparison here,
#: reads the reported case 1.63x
REFERENCE_RATIOS = {
    ((0.02, 0.0), 0.008, 5.0): 1.218,
    ((0.02, 0.0), 0.008, 2.0): 1.095,
    ((0.02, 0.0), 0.006, 10.0): 1.447,
    ((0.02, 0.0), 0.004, 5.0): 1.398,
    ((0.017, 0.004), 0.008, 5.0): 1.180,
}
ELASTIC = {"preset": "liver", "relax_fraction": 0.0}


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
def test_every_model_stiffer_inclusion_never_lowers_and_raises_where_the_reference_does(model):
    """Each case, the liver elastic as in the reference: never below the contrast-1 press, and where
    the reference feels the inclusion (a rise over 10 %), a rise of at least a third of the reference's."""
    for case in CONTRAST_CASES:
        ratio = contrast_ratio(model, *case, material=ELASTIC)
        ref = REFERENCE_RATIOS[case]
        assert ratio >= 1.0 - NEVER_LOWER_SLACK, f"{model}: {case} lowers the force above the inclusion: {ratio:.3f}x"
        if ref > 1.1:
            assert ratio - 1.0 >= (ref - 1.0) / 3.0, f"{model}: {case} reads {ratio:.3f}x where the reference reads {ref:.3f}x"


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
def test_every_model_frictionless_force_does_not_depend_on_the_path(model):
    straight, slid = path_difference(model)
    assert abs(slid - straight) <= 0.02 * straight, f"{model}: straight down {straight:.4f} N, slid in {slid:.4f} N"


def press_task_samples(model: str) -> list:
    """PalpationPress-v0's own stiffness samples (N/m) of one press over the reported inclusion, contrast 5 and 1."""
    env = gym.make("SurgSim/PalpationPress-v0", model=model)
    x, y = INCLUSION["inclusion_position"]
    half = env.unwrapped.config.map_half_width
    readings = []
    for contrast in (5.0, 1.0):
        _reset(env, contrast)
        env.step(np.array([x / half, y / half, -1.0], dtype=np.float32))
        readings.append(float(env.unwrapped.samples_k[-1]))
    env.close()
    return readings


def test_palpation_press_shares_the_scene_and_its_inclusion_raises_the_press_force():
    """PalpationPress-v0 builds Palpation-v0's scene: its own press (6 mm, held, averaged) over the
    reported inclusion reads more than the same press with contrast 1."""
    stiff, plain = press_task_samples(DEFAULT_MODEL)
    ref = reference_contrast()
    assert stiff > (1.0 + 0.5 * (ref - 1.0)) * plain, (
        f"PalpationPress-v0 stiffness samples {stiff:.2f}, {plain:.2f} N/m (contrast 5, 1; the reference {ref:.3f}x)")


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
def test_palpation_press_inclusion_raises_the_press_force(model):
    stiff, plain = press_task_samples(model)
    assert stiff >= 1.2 * plain, f"{model}: PalpationPress-v0 samples {stiff:.2f}, {plain:.2f} N/m (contrast 5, 1)"


# ----------------------------------------------------------------------------------------------
# forces converge under refinement (the task-accuracy harness's reference)
def graded_press_forces(fines, depths, material, xy=(-0.02, 0.0)) -> list:
    """The reference's press (bench/task_reference.py: quasi-static FEM, contact stiffness per area,
    samples at half the spacing) at ``xy`` beside the reported lump, to each of ``depths`` (m), on a
    lattice graded about the site to each fine spacing of ``fines`` (m)."""
    from surgsim_envs.bench import task_accuracy as ta
    from surgsim_envs.bench import task_reference as tr

    inc = ta.PALPATION_FULL.inclusions[0]
    env = ta.make_task_env(TASK, tr.REFERENCE_MODEL, tr.COARSE_SPACING, material=material)
    out = []
    try:
        for fine in fines:
            tr.graded_scene(env, xy, fine, max(depths))
            env.reset(seed=0, options=inc.options())
            out.append(tr.descent_forces(env, xy, depths))
    finally:
        env.close()
    return out


def relative_changes(series) -> list:
    return [abs(b - a) / abs(b) for a, b in zip(series, series[1:])]


@pytest.mark.slow
def test_reference_forces_converge_under_refinement():
    """Frictionless, 5 mm beside the reported lump: refining the graded lattice's fine spacing 1.41 -> 1 ->
    0.71 mm changes the force less each time, at an observed order Richardson can use (measured 0.2692,
    0.2622, 0.2596 N: changes 2.7 %, 1.0 %, order 2.8; about 5 minutes, most of it at 0.71 mm)."""
    from surgsim_envs.bench import task_reference as tr

    fines = (0.002 / np.sqrt(2), 0.001, 0.001 / np.sqrt(2))
    f = [row[0] for row in graded_press_forces(fines, (0.005,), FRICTIONLESS_ELASTIC)]
    changes = relative_changes(f)
    assert changes[1] < changes[0], f"{f} N at {fines} m"
    _, order = tr.richardson(fines, f)
    assert tr.MIN_ORDER <= order <= tr.MAX_ORDER, f"observed order {order:.2f} from {f} N"


@pytest.mark.slow
def test_quasi_static_fem_stiffer_inclusion_raises_the_force_at_5_mm():
    """``fem_static`` (the cheapest FEM in the task, 1.2 ms per env step at 5 mm) reads more over the 5x lump
    than with contrast 1 (measured 1.17x; about 8 s with its factorisation, so under -m slow; the default
    run's representative is the default model's contrast test at 10 mm)."""
    ratio = contrast_ratio("fem_static", depth=0.007, material={"preset": "liver", "relax_fraction": 0.0},
                           resolution=0.005)
    assert ratio > 1.05, f"fem_static at 5 mm: a 5x lump reads {ratio:.3f}x the contrast-1 force"


@pytest.mark.slow
@pytest.mark.parametrize("model", MODELS)
def test_every_model_stiffer_inclusion_never_lowers_the_force_at_5_mm(model):
    """The harness's finest model spacing (5 mm), its elastic material, a 7 mm press over the 5x lump:
    never below the contrast-1 press (the graded reference reads 1.34x the mirror site there)."""
    ratio = contrast_ratio(model, depth=0.007, material={"preset": "liver", "relax_fraction": 0.0}, resolution=0.005)
    assert ratio >= 1.0 - NEVER_LOWER_SLACK, f"{model} at 5 mm: a 5x lump reads {ratio:.3f}x the contrast-1 force"


def _signed_tet_volumes(tissue, positions) -> np.ndarray:
    """(T,) m^3, signed volume of each tet at ``positions`` (negative: the tet is inverted)."""
    a, b, c, d = (positions[tissue.volume.tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def test_mass_spring_at_5_mm_stiffer_inclusion_raises_the_force_and_inverts_no_tet():
    """The fast representative of the 5 mm invariant (a 5 x 5 cm slab, 605 nodes, the same inclusion
    under (0.01, 0)): the lump makes the task step implicitly, so the model gets its material's Poisson
    ratio in the volume term, and a 7 mm press (deeper than the 5 mm lattice) pushes the surface node
    into the stiff layer below without inverting a tet. With the capped term it inverted them (signed
    volume -0.6 of rest) and read 0.97x the contrast-1 force; now it reads more (measured 1.32x)."""
    env = gym.make(TASK, model="mass_spring", material={"preset": "liver", "relax_fraction": 0.0}, resolution=0.005,
                   slab_size=(0.05, 0.05, 0.02), xy_limit=0.02, map_half_width=0.02, inclusion_xy=(-0.015, 0.015))
    site, forces = (0.01, 0.0), []
    for contrast in (5.0, 1.0):
        env.reset(seed=SEED, options={**INCLUSION, "inclusion_position": site, "stiffness_contrast": (contrast, contrast)})
        forces.append(press_force(env, site, 0.007, hold=0.2))
        t = env.unwrapped.sim.tissue()
        ratio = _signed_tet_volumes(t, t.positions) / _signed_tet_volumes(t, t.rest_positions)
        assert ratio.min() > 0.0, f"contrast {contrast}: a 7 mm press inverts a tet (volume ratio {ratio.min():.3f})"
    env.close()
    assert forces[0] >= 1.05 * forces[1], f"mass_spring at 5 mm: a 5x lump reads {forces[0]:.4f} N, contrast 1 {forces[1]:.4f} N"


def test_palpation_gives_mass_spring_the_full_volume_term_whenever_it_steps_implicitly():
    """The capped volume term only keeps the explicit step: the 10 mm task (explicit) keeps it;
    an implicit step asked for, or the switch the task makes on the 5 mm lattice, gets the material's nu."""
    cases = [({"spacing": 0.01}, "symplectic", "capped"),
             ({"integrator": "implicit", "spacing": 0.01}, "implicit", "auto"),
             ({"resolution": 0.005}, "auto", "auto")]
    for kw, integrator, term in cases:
        env = gym.make(TASK, model="mass_spring", **kw)
        t = env.unwrapped.sim.tissue()
        assert (t.integrator, t.volume_stiffness) == (integrator, term), kw
        env.close()
