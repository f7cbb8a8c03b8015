"""The task's presses (nodule at (2, 1) cm, mirror site, 2.5/3.5/4.5 mm) with the layered model's
paper springs and with stiffness="elastic" (the snapped cells' elasticity) on the same lattice.
Usage: PYTHONPATH=. python scripts/layered_skin_elastic.py SPACING_MM ..."""
import sys
import numpy as np
from surgsim_envs.contact.unilateral_probe import UnilateralProbe
from surgsim_envs.geometry.anatomy import abdominal_wall_volume
from surgsim_envs.tissue import make

depths = (0.0025, 0.0035, 0.0045)
sites = {"over": (0.02, 0.01), "mirror": (-0.02, -0.01)}
out = {}
for h in [float(s) * 1e-3 for s in sys.argv[1:]]:
    vol = abdominal_wall_volume(h, size=(0.08, 0.06))
    for form in ("paper", "elastic"):
        t = make("layered", vol, fixed=vol.face_nodes(4), stiffness=form)
        top = np.flatnonzero(vol.neighbours[:, 5] < 0)
        zt = float(vol.nodes[top, 2].max())
        probe = UnilateralProbe(t, top, 0.005)
        c = t.element_centroids()
        fz = c[vol.labels == vol.layer_names.index("fat"), 2]
        z = float(np.clip(np.median(fz), fz.min() + 0.004, fz.max()))
        mask = np.linalg.norm(c - (0.02, 0.01, z), axis=1) < 0.008
        row = {}
        for name, xy in sites.items():
            for d in depths:
                probe.move_to((1e3, 1e3, 1e3)); t.reset()
                t.scale_material("young", 1.0); t.scale_material("young", 30.0, mask=mask)
                probe.press(np.array([xy[0], xy[1], zt + 0.005 - d]), t.static_solve)
                row[f"0/{name}/{d * 1e3:g}mm"] = round(float(probe.force()[2]), 4)
        out[f"{form} {h * 1e3:g} mm"] = row
        print(form, h, row, flush=True)
