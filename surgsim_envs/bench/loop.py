"""``surgsim bench loop``: the full physics step against MuJoCo's own 3-D flex.

Same protocol for every row: a 4.5 cm cube of liver-like tissue with 10 x 10 x 10 = 1,000 nodes,
bottom face fixed, gravity off; a probe with an 8 mm spherical tip (position actuator, kp 2e4 N/m)
starts 1 mm above the top face, presses to 4 mm below it at 50 mm/s, then holds for 50 ms.

Rows (JSON ``{"name", "nodes", "us_per_step", "penetration_mm", ...}``):

* ``mass_spring`` - our full step: MuJoCo tool step + contact + 1,000-node mass-spring tissue
  (symplectic, dt 0.5 ms; its explicit stable step on this mesh is below 1 ms);
* ``mass_spring_implicit`` - the same with the implicit (backward Euler) integrator at dt 1 ms;
* ``mujoco_flex_full`` - MuJoCo ``<flexcomp type="grid" dim="3">`` with built-in elasticity and
  full vertex dofs (2,700 free dofs), dt 1 ms, ``integrator="discrete"`` (MuJoCo 4.0 no longer
  integrates flex elasticity implicitly under implicit/implicitfast);
* ``mujoco_flex_trilinear`` - the same flex with ``dof="trilinear"`` (8 control nodes, 12 free dofs).

``us_per_step`` is the median wall time of one complete physics step (including Python around
it); ``penetration_mm`` is the deepest tissue node / flex vertex inside the probe tip at the end
of the hold (how far the tip has sunk into the surface it should be pushing).
"""

from __future__ import annotations

import json
import time

import numpy as np

from surgsim_envs.errors import ConfigError

SIZE = 0.045          # m, cube edge
COUNT = 10            # nodes per edge
TIP = 0.008           # m, probe tip radius
YOUNG, POISSON, DENSITY = 4000.0, 0.45, 1060.0
PRESS_DEPTH, APPROACH, PRESS_SPEED, HOLD = 0.004, 0.001, 0.05, 0.05


def add_arguments(parser) -> None:
    parser.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    parser.add_argument("--skip-full", action="store_true",
                        help="skip mujoco_flex_full (its 3,000-dof step takes seconds per 100 steps)")


def _probe_target(t: float, top: float) -> float:
    """Tip-centre height (m) at time t (s) of the press protocol."""
    start = top + TIP + APPROACH
    return max(start - PRESS_SPEED * t, top + TIP - PRESS_DEPTH)


def _duration() -> float:
    return (APPROACH + PRESS_DEPTH) / PRESS_SPEED + HOLD


def run_ours(integrator: str, dt: float) -> dict:
    """Our full step on the 1,000-node cube; returns the JSON row."""
    from surgsim_envs.scene import ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene

    half = SIZE / 2.0
    tissue = TissueConfig(name="cube", organ="block", model="mass_spring",
                          material={"preset": "liver", "young": YOUNG, "poisson": POISSON, "density": DENSITY},
                          spacing=SIZE / (COUNT - 1), anchors=("bottom",), position=(0.0, 0.0, half),
                          volume_options={"size": (SIZE, SIZE, SIZE)}, options={"integrator": integrator})
    top = SIZE
    probe = ProbeConfig(name="probe", tip_radius=TIP, position=(0.0, 0.0, top + TIP + APPROACH), speed=float("inf"))
    cfg = SceneConfig(name="bench_loop", tissues=[tissue], tools=[probe], dt=dt, gravity=(0.0, 0.0, 0.0),
                      floor=False, cameras=[])
    sim = Simulation(build_scene(cfg))
    n = sim.tissue().n_nodes
    for _ in range(20):  # warm-up (numba dispatch, caches); then start again
        sim.physics_step()
    sim.reset()
    steps = int(round(_duration() / dt))
    times = np.empty(steps)
    for i in range(steps):
        sim.set_tool_target("probe", [0.0, 0.0, _probe_target(sim.time, top)])
        t0 = time.perf_counter()
        sim.physics_step()
        times[i] = time.perf_counter() - t0
    rep = sim.contact_report()["probe"]
    name = "mass_spring" if integrator == "symplectic" else f"mass_spring_{integrator}"
    return {"name": name, "nodes": n, "us_per_step": float(np.median(times) * 1e6),
            "penetration_mm": rep["penetration"] * 1e3, "force_N": rep["normal_force"], "dt_ms": dt * 1e3,
            "indentation_mm": (top + TIP - sim.tool_position("probe")[2]) * 1e3}


def _flex_xml(dof: str, dt: float) -> str:
    from surgsim_envs.bench.mujoco_flex import flexcomp_xml

    mass = DENSITY * SIZE ** 3
    spacing = SIZE / (COUNT - 1)
    top = SIZE
    flex = flexcomp_xml("cube", young=YOUNG, poisson=POISSON, mass=mass, dof=dof, damping=0.005, radius=0.0005,
                        solref=0.002, condim=3, count=(COUNT, COUNT, COUNT), spacing=(spacing,) * 3,
                        pos=(0, 0, SIZE / 2))
    return f"""<mujoco><option timestep="{dt}" integrator="discrete" gravity="0 0 0"/>
<worldbody>
{flex}
<body name="probe" pos="0 0 {top + TIP + APPROACH}">
  <joint name="pz" type="slide" axis="0 0 1" range="-0.2 0.2"/>
  <geom name="tip" type="sphere" size="{TIP}" mass="0.05"/>
</body>
</worldbody>
<actuator><position name="press" joint="pz" kp="20000" dampratio="1"/></actuator></mujoco>"""


def run_mujoco_flex(dof: str, dt: float = 1e-3) -> dict:
    """MuJoCo's own 3-D flex (``dof`` "full" or "trilinear") pressed by the same probe."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(_flex_xml(dof, dt))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    top = float(d.flexvert_xpos[:, 2].max())
    home = top + TIP + APPROACH
    pid = m.body("probe").id
    steps = int(round(_duration() / dt))
    times = np.empty(steps)
    for i in range(steps):
        d.ctrl[0] = _probe_target(d.time, top) - home
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        times[i] = time.perf_counter() - t0
    if not np.all(np.isfinite(d.qpos)):
        pen = float("nan")
    else:
        c = d.xpos[pid]
        pen = float(max(0.0, (TIP + m.flex_radius[0] - np.linalg.norm(d.flexvert_xpos - c, axis=1)).max()))
    return {"name": f"mujoco_flex_{dof}", "nodes": int(m.nflexvert), "us_per_step": float(np.median(times) * 1e6),
            "penetration_mm": pen * 1e3, "force_N": float(-d.actuator_force[0]), "dt_ms": dt * 1e3,
            "indentation_mm": (top + TIP - d.xpos[pid][2]) * 1e3, "dofs": int(m.nv)}


def bench(skip_full: bool = False, progress: bool = True) -> list[dict]:
    import sys

    from tqdm import tqdm

    cases = [("ours symplectic", lambda: run_ours("symplectic", 5e-4)), ("ours implicit", lambda: run_ours("implicit", 1e-3))]
    if not skip_full:
        cases.append(("MuJoCo flex full", lambda: run_mujoco_flex("full")))
    cases.append(("MuJoCo flex trilinear", lambda: run_mujoco_flex("trilinear")))
    rows = []
    with tqdm(cases, desc="bench loop", unit="case", file=sys.stderr, disable=not progress) as bar:
        for label, case in bar:
            bar.set_postfix_str(label)
            rows.append(case())
    return rows


def run(args) -> int:
    rows = bench(skip_full=args.skip_full)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'name':24s} {'nodes':>6s} {'dt ms':>6s} {'us/step':>10s} {'indent mm':>10s} {'force N':>8s} {'penetration mm':>15s}")
    for r in rows:
        print(f"{r['name']:24s} {r['nodes']:6d} {r['dt_ms']:6.2f} {r['us_per_step']:10.1f} {r['indentation_mm']:10.2f} "
              f"{r['force_N']:8.3f} {r['penetration_mm']:15.2f}")
    return 0
