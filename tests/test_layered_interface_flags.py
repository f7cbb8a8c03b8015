"""A lattice node lying exactly on an interface is an interface point, like a node snapped onto it.

On the abdominal wall (29 mm, skin 2 mm) at a 2.5 mm spacing a lattice level lies exactly on the
skin/fat interface (z = 27 mm, no snap needed). Its nodes must take the interface's material (the fat
below it), as they do when the interface sits a fraction of a micrometre off the level and they snap
onto it; otherwise the skin's in-plane springs get a second level and the skin reads 3.75 mm thick.
"""
import numpy as np
import pytest

from surgsim_envs.contact.unilateral_probe import UnilateralProbe
from surgsim_envs.geometry.anatomy import abdominal_wall_layers
from surgsim_envs.geometry.layers import layered_volume
from surgsim_envs.tissue import make

H = 0.0025
SIZE = (0.02, 0.02)


def _wall(shift: float = 0.0):
    """The wall with the skin/fat interface ``shift`` m below 27 mm (the skin thicker, the fat thinner:
    the other surfaces and the lattice stay where they are)."""
    return layered_volume(abdominal_wall_layers(size=SIZE, skin=0.002 + shift, fat=0.015 - shift), H)


def _press(vol, depth: float = 0.002) -> float:
    model = make("layered", vol, fixed=vol.face_nodes(4))
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    probe = UnilateralProbe(model, top, 0.005)
    z_top = float(vol.nodes[top, 2].max())
    probe.press(np.array([0.0, 0.0, z_top + 0.005 - depth]), model.static_solve)
    return float(probe.force()[2])


def test_nodes_on_the_interface_take_the_material_below_it():
    vol = _wall()
    level = np.abs(vol.nodes[:, 2] - 0.027) < 1e-9
    assert level.sum() >= 25, "the 2.5 mm lattice should have a level at the skin/fat interface (27 mm)"
    names = np.array(vol.material_names)[vol.node_material[level]]
    assert set(names) == {"fat"}, f"nodes on the skin/fat interface flagged {sorted(set(names))}"
    skin = vol.material_names.index("skin")
    horizontal = (vol.spring_material[level][:, :4] == skin) & (vol.neighbours[level][:, :4] >= 0)
    assert not horizontal.any(), f"{int(horizontal.sum())} in-plane springs on the interface level carry the skin"


def test_the_press_does_not_jump_when_the_interface_moves_off_the_level():
    # the interface 0.1 um above the lattice level: the interior nodes snap onto it (a 0.1 um snap),
    # the side-face nodes (they snap onto the boundary only) lie below it; the press must read what
    # it reads with the interface exactly on the level (before, the level's interior nodes were skin
    # and the press read 16 % more)
    on = _press(_wall())
    off = _press(_wall(-1e-7))
    assert on > 0.0
    assert off == pytest.approx(on, rel=1e-3)
