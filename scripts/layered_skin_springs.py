"""How LayeredPalpation-v0's 2 mm skin sits on the layered lattice, and what its in-plane springs
(a membrane for a vertical press) contribute to a press beside the nodule.

For each lattice spacing: the column of nodes under the mirror site (-2, -1) cm (material, the
tension per unit width of its in-plane springs and the skin thickness that stands for, the
vertical spring's modulus), the dent's profile along x at a 3.5 mm press, and the press force at
2.5 / 3.5 / 4.5 mm (the task's wall, nodule at (2, 1) cm, unilateral probe, direct solve) for
the paper's springs and three variants: the skin's in-plane springs standing for exactly 2 mm of
skin, the skin's in-plane springs at the fat's modulus (no membrane), the fascia at the muscle's.
Results: docs/models/layered.md ("Why the task reads 3-8 x the reference beside the nodule").
Usage: PYTHONPATH=. python scripts/layered_skin_springs.py [spacings_mm ...] [--out FILE.json]"""
import sys, json
import numpy as np
from surgsim_envs.contact.unilateral_probe import UnilateralProbe
from surgsim_envs.geometry.anatomy import abdominal_wall_volume
from surgsim_envs.tissue import make
from surgsim_envs.tissue.layered import laplace_modulus

args = [a for a in sys.argv[1:] if a != "--out"]
out_path = sys.argv[sys.argv.index("--out") + 1] if "--out" in sys.argv else None
if out_path:
    args.remove(out_path)
spacings = [float(s) * 1e-3 for s in args] or [0.01, 0.005, 0.0025, 0.002]
depths = (0.0025, 0.0035, 0.0045)
site = (-0.02, -0.01)
out = {}
for h in spacings:
    vol = abdominal_wall_volume(h, size=(0.08, 0.06))
    t = make("layered", vol, fixed=vol.face_nodes(4))
    names = vol.material_names
    gl = {m: float(laplace_modulus(vol.material_table[m].young, vol.material_table[m].poisson)) for m in names}
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    zt = float(vol.nodes[top, 2].max())
    probe = UnilateralProbe(t, top, 0.005)   # one probe per model (a second one would not own the held nodes)
    # the column under the site
    col = np.flatnonzero(np.hypot(vol.nodes[:, 0] - site[0], vol.nodes[:, 1] - site[1]) < 1e-6)
    col = col[np.argsort(-vol.nodes[col, 2])]
    rep = []
    for i in col[:4]:
        kx = t.kk_build[i, 0]; Lx = t.rest_lengths[i, 0]
        kz = t.kk_build[i, 4]; Lz = t.rest_lengths[i, 4]; j = vol.neighbours[i, 4]
        rep.append({"z_mm": round(vol.nodes[i, 2] * 1e3, 3), "material": names[vol.node_material[i]],
                    # in-plane: tension per unit width K L / h (N/m) and the skin thickness it stands for
                    "x_tension_N_per_m": round(kx * Lx / h, 3), "as_skin_mm": round(kx * Lx / h / gl["skin"] * 1e3, 3),
                    "z_spring_to_mm": round(vol.nodes[j, 2] * 1e3, 3) if j >= 0 else None,
                    "z_G_eff_Pa": round(kz * Lz / vol.spring_area[i, 4], 1) if j >= 0 else None})
    c = t.element_centroids()
    fz = c[vol.labels == vol.layer_names.index("fat"), 2]
    z = float(np.clip(np.median(fz), fz.min() + 0.004, fz.max()))
    mask = np.linalg.norm(c - (0.02, 0.01, z), axis=1) < 0.008
    skin = names.index("skin")
    hor = np.zeros_like(t.kk_build, dtype=bool); hor[:, :4] = True
    skin_h = hor & (vol.spring_material == skin) & (vol.neighbours >= 0)
    base_k = t.kk_build.copy()
    variants = {
        "paper": base_k,
        # (a) the skin's in-plane springs standing for exactly 2 mm of skin (K L / h = G_skin * 2 mm)
        "skin_inplane_2mm": np.where(skin_h, base_k * 0.002 / np.maximum(base_k * t.rest_lengths / h / gl["skin"], 1e-12), base_k),
        # (c) no membrane: the skin's in-plane springs at the fat's modulus (vertical ones unchanged)
        "skin_inplane_fat": np.where(skin_h, base_k * gl["fat"] / gl["skin"], base_k),
        # the fascia's springs (an interface material, absent from the reference) at the muscle's modulus
        "fascia_as_muscle": np.where(vol.spring_material == names.index("fascia"), base_k * gl["muscle"] / gl["fascia"], base_k),
    }
    res = {"nodes": int(vol.n_nodes) if hasattr(vol, "n_nodes") else len(vol.nodes), "column": rep}
    for name, kk in variants.items():
        t.kk_build = np.ascontiguousarray(kk)
        f = []
        for d in depths:
            probe.move_to((1e3, 1e3, 1e3)); t.reset()
            t.scale_material("young", 1.0); t.scale_material("young", 30.0, mask=mask)
            probe.press(np.array([site[0], site[1], zt + 0.005 - d]), t.static_solve)
            f.append(round(float(probe.force()[2]), 4))
            if name == "paper" and d == 0.0035:   # the dent's lateral extent along x
                p = t.positions; u = p[top, 2] - vol.nodes[top, 2]
                onl = np.abs(vol.nodes[top, 1] - site[1]) < 1e-6
                xs = vol.nodes[top[onl], 0] - site[0]; uu = u[onl]
                prof = {}
                for r in (0.0, 0.01, 0.02, 0.03):
                    k = np.argmin(np.abs(xs - r)); prof[f"{xs[k] * 1e3:.0f}mm"] = round(float(uu[k] / uu[np.argmin(np.abs(xs))]), 3)
                res["dent_profile_w_over_w0"] = prof
        res[name] = f
    t.kk_build = base_k
    out[f"{h * 1e3:g} mm"] = res
    print(h, json.dumps(res), flush=True)
if out_path:
    json.dump(out, open(out_path, "w"), indent=1)
