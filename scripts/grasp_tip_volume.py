"""The grasp scene's organ lattice at each spacing: its node count, its volume and the volume of its
tets within 10 and 20 mm of its tip (the +x end the grasper closes on): how well the lattice holds
the organ's outline where the jaws grasp, apart from the FEM's convergence.

    python scripts/grasp_tip_volume.py --spacings 0.00389,0.00275,0.0019445,0.001375
"""

from __future__ import annotations

import argparse
import copy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--organ", default="spleen")
    parser.add_argument("--spacings", default="0.011,0.00778,0.0055,0.00389,0.00275,0.0019445",
                        help="lattice spacings, m")
    args = parser.parse_args()
    from surgsim_envs.geometry.volume import tet_signed_volumes
    from surgsim_envs.scene.builder import grasp_config, placed_volume

    tissue = grasp_config(organ=args.organ, model="fem_static").tissues[0]
    for h in (float(s) for s in args.spacings.split(",")):
        t = copy.deepcopy(tissue)
        t.spacing = t.resolution = h
        vol = placed_volume(t)
        x = vol.nodes
        tip = float(x[:, 0].max())
        centroid_x = x[vol.tets][:, :, 0].mean(axis=1)
        v = tet_signed_volumes(x, vol.tets)
        near = [float(v[centroid_x > tip - d].sum()) * 1e9 for d in (0.010, 0.020)]
        print(f"{h * 1e3:.4g} mm: {len(x):,} nodes, volume {v.sum() * 1e6:.2f} cm^3, tip at x {tip * 1e3:.2f} mm, "
              f"within 10 / 20 mm of the tip {near[0]:,.0f} / {near[1]:,.0f} mm^3", flush=True)


if __name__ == "__main__":
    main()
