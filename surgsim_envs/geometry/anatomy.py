"""Procedural layered anatomy for the ``layered`` model (Lin et al. 2008): abdominal wall, thigh section.

Every value is SI (m, Pa, kg/m^3) and carries its source. Where the literature gives a TENSILE
modulus for a membrane (fascia, peritoneum: tens of MPa, measured along the sheet) we use a
smaller effective value: the layered model's springs couple displacements across the membrane
(eq. 2.8), and a membrane's resistance to a transverse push is far below its in-plane tensile
stiffness; the choice is documented in docs/models/layered.md.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.layers import Interface, LayerSet, LayeredVolume, layered_volume
from surgsim_envs.materials import PRESETS, Material

#: materials of the layered anatomy that are not presets (skin, fat, muscle come from PRESETS)
ANATOMY_MATERIALS: dict[str, Material] = {
    "fascia": Material(
        young=200_000.0, poisson=0.45, density=1100.0, damping=5.0, nonlinear=0.0, friction=0.5, name="fascia",
        source="anterior rectus sheath: tensile E ~ 20-40 MPa along the sheet (Kirilova et al. 2011, Med Eng Phys; "
               "Hollinsky & Sandberg 2007, Clin Biomech); 200 kPa is our effective transverse value (choice, "
               "docs/models/layered.md)"),
    "peritoneum": Material(
        young=50_000.0, poisson=0.45, density=1050.0, damping=5.0, nonlinear=0.0, friction=0.3, name="peritoneum",
        source="transversalis fascia + preperitoneal fat + peritoneum lumped as one 2 mm layer; "
               "effective E 50 kPa between fat and fascia (choice, docs/models/layered.md)"),
    "bone": Material(
        young=1.7e10, poisson=0.3, density=1900.0, damping=5.0, nonlinear=0.0, friction=0.3, name="bone",
        source="cortical bone E ~ 17 GPa (Reilly & Burstein 1975); held rigid by the layered model"),
}

#: anterior abdominal wall at the umbilical level, adult, from outside in (m)
ABDOMINAL_WALL_THICKNESS = {
    "skin": 0.002,        # dermis + epidermis ~1.5-2.5 mm: Laurent et al. 2007 (Vaccine, 20-MHz ultrasound)
    "fat": 0.015,         # subcutaneous fat 10-30 mm: Stoerchle et al. 2018 (Sci Rep, standardized ultrasound)
    "muscle": 0.010,      # rectus abdominis ~10 mm: Rankin, Stokes & Newham 2006 (Muscle Nerve, ultrasound)
    "peritoneum": 0.002,  # transversalis fascia + preperitoneal fat + peritoneum, lumped (choice)
}
#: moduli (Pa) of the abdominal wall layers; the presets carry their own sources
ABDOMINAL_WALL_MATERIALS = {"skin": "skin", "fat": "fat", "fascia": "fascia", "muscle": "muscle",
                            "peritoneum": "peritoneum"}

#: a thigh/leg section: outer radius, skin, fat (m), femur radius and its offset below the axis (m)
THIGH = {"radius": 0.05, "length": 0.10, "skin": 0.0015, "fat": 0.010, "bone_radius": 0.013,
         "bone_offset": 0.008}
# sources: thigh subcutaneous fat 5-20 mm (Stoerchle et al. 2018); femoral shaft diameter ~25-30 mm
# (e.g. Ruff & Hayes 1983, Am J Phys Anthropol); skin ~1.5 mm (Laurent et al. 2007)


def _materials() -> dict:
    return {**{k: v for k, v in PRESETS.items()}, **ANATOMY_MATERIALS}


def abdominal_wall_layers(size=(0.12, 0.12), skin: float | None = None, fat: float | None = None,
                          muscle: float | None = None, peritoneum: float | None = None,
                          fat_variation: float = 0.0) -> LayerSet:
    """LayerSet of an anterior abdominal wall patch (``size`` x, y in m), outer skin surface at the
    top (z = total thickness), peritoneum at z = 0.

    Thicknesses (m) default to :data:`ABDOMINAL_WALL_THICKNESS`. ``fat_variation`` (fraction in
    [0, 0.8)) makes the fat thicker towards +x and thinner towards -x (linearly, +-fraction), so that
    the muscle's depth varies across the patch. The fat/muscle interface carries the fascia (its own
    spring layer); the other interfaces' points take the material below them.
    """
    t = dict(ABDOMINAL_WALL_THICKNESS)
    for key, val in (("skin", skin), ("fat", fat), ("muscle", muscle), ("peritoneum", peritoneum)):
        if val is not None:
            t[key] = val
    for key, val in t.items():
        if not (isinstance(val, (int, float)) and 0.0 < val < 0.2):
            raise ConfigError(f"abdominal wall: {key} thickness must be in (0, 0.2) m, got {val!r} "
                              "(a zero-thickness layer is not a layer)")
    if not (0.0 <= fat_variation < 0.8):
        raise ConfigError(f"abdominal wall: fat_variation must be in [0, 0.8), got {fat_variation!r}")
    sx, sy = (float(v) for v in size)
    if not (0.01 < sx < 1.0 and 0.01 < sy < 1.0):
        raise ConfigError(f"abdominal wall: size must be two lengths in (0.01, 1) m, got {size!r}")
    import trimesh

    total = sum(t.values())
    # the fat may be up to (1 + fat_variation) thick: the box holds the thickest column
    top = total + fat_variation * t["fat"]
    box = trimesh.creation.box(extents=(sx, sy, top))
    box.apply_translation((0.0, 0.0, top / 2.0))
    bot_muscle = t["peritoneum"]
    top_muscle = bot_muscle + t["muscle"]
    fat0, var = t["fat"], float(fat_variation)

    def skin_fat(x, y):
        return np.full(np.broadcast(x, y).shape, top - t["skin"])

    def fat_muscle(x, y):
        return top - t["skin"] - fat0 * (1.0 + var * np.clip(2.0 * np.asarray(x) / sx, -1.0, 1.0)) + 0.0 * y

    def muscle_peritoneum(x, y):
        return np.full(np.broadcast(x, y).shape, bot_muscle)

    if var == 0.0:
        def fat_muscle(x, y):  # noqa: F811 - the flat case keeps the muscle top exactly planar
            return np.full(np.broadcast(x, y).shape, top_muscle)
    interfaces = [
        Interface("skin/fat", "fat", skin_fat),
        Interface("fat/muscle (anterior rectus sheath)", "muscle", fat_muscle, interface_material="fascia"),
        Interface("muscle/peritoneum", "peritoneum", muscle_peritoneum),
    ]
    return LayerSet(box, "skin", interfaces, name="abdominal_wall", materials=ANATOMY_MATERIALS)


def thigh_layers(radius: float | None = None, length: float | None = None, skin: float | None = None,
                 fat: float | None = None, bone_radius: float | None = None,
                 bone_offset: float | None = None, sections: int = 48) -> LayerSet:
    """LayerSet of a thigh/leg section: a cylinder along x (``radius``, ``length`` m) of skin, fat,
    muscle and a rigid femur (``bone_radius``, centred ``bone_offset`` m below the axis). The inner
    cylinders are shortened by their depth at each end, so the section is closed by skin and fat."""
    import trimesh

    p = dict(THIGH)
    for key, val in (("radius", radius), ("length", length), ("skin", skin), ("fat", fat),
                     ("bone_radius", bone_radius), ("bone_offset", bone_offset)):
        if val is not None:
            p[key] = float(val)
    r_fat = p["radius"] - p["skin"]
    r_mus = r_fat - p["fat"]
    if not (p["bone_radius"] + abs(p["bone_offset"]) < r_mus):
        raise ConfigError(f"thigh: bone (radius {p['bone_radius']} m, offset {p['bone_offset']} m) must lie inside "
                          f"the muscle (radius {r_mus:.4f} m)")

    def cyl(r, length, dz=0.0):
        m = trimesh.creation.cylinder(radius=r, height=length, sections=sections)
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (0, 1, 0)))
        m.apply_translation((0.0, 0.0, dz))
        return m

    L = p["length"]
    boundary = cyl(p["radius"], L)
    interfaces = [
        Interface("skin/fat", "fat", cyl(r_fat, L - 2 * p["skin"])),
        Interface("fat/muscle (fascia lata)", "muscle", cyl(r_mus, L - 2 * (p["skin"] + p["fat"])),
                  interface_material="fascia"),
        Interface("muscle/bone (periosteum)", "bone", cyl(p["bone_radius"], L - 2 * (p["skin"] + p["fat"]) - 0.01,
                                                          -p["bone_offset"])),
    ]
    return LayerSet(boundary, "skin", interfaces, name="thigh", materials=ANATOMY_MATERIALS, rigid=("bone",))


def abdominal_wall_volume(spacing: float = 0.003, **kwargs) -> LayeredVolume:
    """:func:`layered_volume` of :func:`abdominal_wall_layers` (``spacing`` m = d_threshold)."""
    return layered_volume(abdominal_wall_layers(**kwargs), spacing)


def thigh_volume(spacing: float = 0.004, **kwargs) -> LayeredVolume:
    """:func:`layered_volume` of :func:`thigh_layers` (``spacing`` m = d_threshold)."""
    return layered_volume(thigh_layers(**kwargs), spacing)


__all__ = ["ANATOMY_MATERIALS", "ABDOMINAL_WALL_THICKNESS", "THIGH", "abdominal_wall_layers", "thigh_layers",
           "abdominal_wall_volume", "thigh_volume"]
