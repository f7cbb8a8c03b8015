"""The README picture, docs/img/readme_palpation.png: Palpation-v0's probe pressing the liver slab (a
rendered frame, the tissue coloured by displacement with its colour bar) beside the force the probe feels (N) against time. ``python scripts/readme_figure.py``."""
import os
os.environ.setdefault("MUJOCO_GL", "egl")
import gymnasium as gym
import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import surgsim_envs  # noqa: F401

env = gym.make("SurgSim/Palpation-v0", render_mode="rgb_array")
obs, info = env.reset(seed=0)
forces = []
frame = None
for i in range(60):
    a = np.array([0.0, 0.0, -1.0, -1.0], dtype=np.float32) if i < 40 else np.array([0.0, 0.0, 0.0, -1.0], dtype=np.float32)
    obs, r, term, trunc, info = env.step(a)
    f = float(np.linalg.norm(env.unwrapped.sim.tool_force("probe")))
    forces.append(f)
    if i == 45:
        frame = env.render()
print(f"peak probe force {max(forces):.3f} N; wrote docs/img/readme_palpation.png")
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 3.6), gridspec_kw={"width_ratios": [1.4, 1]})
ax0.imshow(frame); ax0.axis("off"); ax0.set_title("SurgSim/Palpation-v0: probe pressing a liver slab")
# the slab is coloured by node displacement, 0-4 mm, viridis (the scene's render_field)
sm = plt.cm.ScalarMappable(cmap="viridis", norm=matplotlib.colors.Normalize(0.0, 4.0))
fig.colorbar(sm, ax=ax0, fraction=0.046, pad=0.02, label="tissue displacement (mm)")
t = np.arange(1, len(forces) + 1) * 0.01
ax1.plot(t, forces, color="tab:red"); ax1.axvline(0.46, color="0.5", ls=":", label="frame shown"); ax1.legend(loc="upper left")
ax1.set_xlabel("time (s)"); ax1.set_ylabel("probe force (N)"); ax1.set_title("force the probe feels")
fig.tight_layout(); fig.savefig("docs/img/readme_palpation.png", dpi=100)
