"""Reproduce Lin et al. 2008's Figs. 2.14-2.16 with the layered model; writes docs/img/layered_*.png and
prints the numbers as JSON. Usage: PYTHONPATH=. python scripts/layered_figures.py [spacing_m]"""

import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from surgsim_envs.bench import layers_experiments as E  # noqa: E402

h = float(sys.argv[1]) if len(sys.argv) > 1 else 0.004
out = {}
model, top = E.wall_model(h)
# Fig. 2.14: deformation profile
res = E.layer_deformation(model, top, 0.004)
x = res.pop("positions")
out["fig2_14"] = res
X = model.rest_positions
sec = np.abs(X[:, 1]) < 0.5 * h
fig, ax = plt.subplots(1, 2, figsize=(11, 4))
colors = {"skin": "#d9a066", "fat": "#f2e394", "fascia": "#555555", "muscle": "#b23a3a", "peritoneum": "#6a8dbf"}
for k, name in enumerate(model.volume.material_names):
    s = sec & (model.volume.node_material == k)
    ax[0].scatter(x[s, 0] * 1e3, x[s, 2] * 1e3, s=6, c=colors.get(name, "k"), label=name)
ax[0].set_xlim(-30, 30)
ax[0].set_xlabel("x (mm)"); ax[0].set_ylabel("z (mm)"); ax[0].set_title("Fig. 2.14: section y = 0, probe 4 mm deep")
ax[0].legend(fontsize=7, markerscale=2)
ax[1].barh(range(len(res["material"])), np.asarray(res["displacement"]) * 1e3, color=[colors.get(m, "k") for m in res["material"]])
ax[1].set_yticks(range(len(res["material"]))); ax[1].set_yticklabels(res["material"]); ax[1].invert_yaxis()
ax[1].set_xlabel("mean downward displacement under the probe (mm)")
ax[1].set_title(f"upper layers deform more; interpenetrations: {res['interpenetrations']}")
fig.tight_layout(); fig.savefig("docs/img/layered_fig2_14.png", dpi=110)
# Fig. 2.15: shallow vs deep path
xs = np.linspace(-0.045, 0.045, 10)
sh = E.path_forces(model, top, 0.003, xs)
dp = E.path_forces(model, top, 0.012, xs)
out["fig2_15"] = {"shallow": sh, "deep": dp}
fig, ax = plt.subplots(figsize=(6.5, 4))
ax.plot(xs * 1e3, sh["force"], "o-", label="shallow path, 3 mm (fat only)")
ax.plot(xs * 1e3, dp["force"], "s-", label="deep path, 12 mm (muscle engaged)")
ax2 = ax.twinx()
fat = 0.015 * (1 + 0.4 * np.clip(2 * xs / 0.12, -1, 1))
ax2.plot(xs * 1e3, fat * 1e3, "k:", label="fat thickness"); ax2.set_ylabel("fat thickness (mm)")
ax.set_xlabel("probe position x (mm)"); ax.set_ylabel("probe force (N)")
ax.set_title("Fig. 2.15: abdominal wall, two probe paths"); ax.legend(loc="upper right", fontsize=8)
fig.tight_layout(); fig.savefig("docs/img/layered_fig2_15.png", dpi=110)
# Fig. 2.16: towards the bone
lm, lt = E.leg_model(0.003)
depths = np.linspace(0.002, 0.0175, 12)  # 23 mm soft tissue, 20 % of it stays: deeper is infeasible
bp = E.bone_press(lm, lt, depths)
out["fig2_16"] = bp
fig, ax = plt.subplots(figsize=(6.5, 4))
ax.plot(np.asarray(bp["depth"]) * 1e3, bp["force"], "o-")
ax.axvline(bp["soft_thickness"] * 0.8 * 1e3, color="gray", ls=":", label="80 % of the soft tissue over the femur")
ax.set_xlabel("probe depth (mm)"); ax.set_ylabel("probe force (N)"); ax.legend(fontsize=8)
ax.set_title("Fig. 2.16: pushing towards the femur (rigid)")
fig.tight_layout(); fig.savefig("docs/img/layered_fig2_16.png", dpi=110)
print(json.dumps(out, indent=1, default=float))
