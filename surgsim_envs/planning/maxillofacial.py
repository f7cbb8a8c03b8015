"""A maxillofacial-like planning case (Vandewalle et al. 2003, section 3), synthetic: no patient data ships.

A soft-tissue layer (``thickness`` m, default 15 mm) over an ``width`` x ``height`` patch of
bone, curved like a cheek (the layer follows ``z = -x^2 / (2 curvature_radius)``). Its bottom
face is the bone contact. A bone segment (the lower part on one side: x > ``segment_x``,
y < ``segment_y``) is moved by a distraction device with two degrees of freedom, as in the
paper's patients: a unidirectional translation (``translation`` m along ``direction``) and an
angular rotation (``rotation_deg`` about the axis ``rotation_axis`` through the segment's
corner). The rest of the bone contact is fixed, and so are the layer's far borders (the paper:
"the soft tissue above the eyes and behind the ears ... supposed to have a fixed position"):
the faces y = +height/2 and x = +-width/2. The skin is the top face. Between the moved segment
and the fixed bone the bone displacement blends to zero over a band ``transition`` m wide
(smoothstep; the stretched regenerate of distraction osteogenesis), so the prescribed field is
resolved by every mesh finer than the band (a jump across one element would make the
prediction depend on the element size).

Units: m, Pa. E does not change the prediction (only alpha E matters, see growth.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.box import box_volume
from surgsim_envs.geometry.volume import Volume


@dataclass
class DistractionCase:
    """Geometry and distraction of the case (defaults: a 80 x 60 mm patch, 15 mm layer, 8 mm + 8 deg)."""

    width: float = 0.08
    height: float = 0.06
    thickness: float = 0.015
    curvature_radius: float = 0.09
    segment_x: float = 0.0
    segment_y: float = 0.0
    translation: float = 0.008
    direction: tuple = (0.25, -1.0, 0.35)
    rotation_deg: float = 8.0
    rotation_axis: tuple = (0.0, 0.0, 1.0)
    transition: float = 0.012
    young: float = 3000.0
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        for name in ("width", "height", "thickness", "curvature_radius"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"{name} must be > 0 m, got {v!r}")
        if np.linalg.norm(self.direction) == 0 or np.linalg.norm(self.rotation_axis) == 0:
            raise ConfigError("direction and rotation_axis must be non-zero vectors")

    # ------------------------------------------------------------------------------------------
    def volume(self, spacing: float) -> Volume:
        """The tissue layer meshed with about ``spacing`` m between nodes (structured tets, curved)."""
        vol = box_volume((self.width, self.height, self.thickness), spacing=spacing,
                         center=(0.0, 0.0, self.thickness / 2), name="maxillofacial_layer")
        nodes = vol.nodes.copy()
        nodes[:, 2] -= nodes[:, 0] ** 2 / (2.0 * self.curvature_radius)   # a shear map: volumes kept
        return Volume(nodes, vol.tets, name=vol.name)

    def _flat(self, vol: Volume) -> np.ndarray:
        """Rest nodes mapped back to the flat layer (z = height above the bone)."""
        x = vol.nodes.copy()
        x[:, 2] += x[:, 0] ** 2 / (2.0 * self.curvature_radius)
        return x

    def regions(self, vol: Volume) -> dict:
        """Boolean node masks: "bone" (bottom), "segment" (moved bone), "border" (fixed far faces), "skin" (top)."""
        x = self._flat(vol)
        tol = 1e-9 + 1e-6 * self.thickness
        bone = x[:, 2] <= tol
        skin = x[:, 2] >= self.thickness - tol
        segment = bone & (x[:, 0] > self.segment_x + tol) & (x[:, 1] < self.segment_y - tol)
        border = (x[:, 1] >= self.height / 2 - tol) | (np.abs(x[:, 0]) >= self.width / 2 - tol)
        if not segment.any():
            raise ConfigError("the bone segment holds no node: move segment_x/segment_y inside the patch")
        return {"bone": bone, "segment": segment, "border": border, "skin": skin}

    def bone_displacement(self, points: np.ndarray) -> np.ndarray:
        """(P,3) m displacement of bone points by the distraction: rotation about the segment corner,
        then the translation."""
        axis = np.asarray(self.rotation_axis, float) / np.linalg.norm(self.rotation_axis)
        th = np.deg2rad(self.rotation_deg)
        kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        rot = np.eye(3) + np.sin(th) * kx + (1 - np.cos(th)) * kx @ kx
        corner = np.array([self.segment_x, self.segment_y, -self.segment_x ** 2 / (2 * self.curvature_radius)])
        d = np.asarray(self.direction, float) / np.linalg.norm(self.direction)
        p = np.asarray(points, float)
        return (p - corner) @ rot.T + corner + self.translation * d - p

    def bone_weight(self, points: np.ndarray) -> np.ndarray:
        """(P,) in [0, 1]: how much of the segment's motion a bone point follows (1 on the segment,
        smoothstep to 0 over ``transition`` m outside it)."""
        p = np.asarray(points, float)
        tw = max(self.transition, 1e-12)

        def smooth(t):
            t = np.clip(t, 0.0, 1.0)
            return t * t * (3.0 - 2.0 * t)

        return smooth((p[:, 0] - self.segment_x) / tw + 1.0) * smooth((self.segment_y - p[:, 1]) / tw + 1.0)

    def dirichlet(self, vol: Volume):
        """``(fixed (N,) bool, displacement (N,3) m)``: the bone contact and the borders are fixed; the
        bone moves with the segment weighted by :meth:`bone_weight`, the borders stay."""
        r = self.regions(vol)
        fixed = r["bone"] | r["border"]
        disp = np.zeros((vol.n_nodes, 3))
        moving = r["bone"] & ~r["border"]
        w = self.bone_weight(vol.nodes[moving])
        disp[moving] = w[:, None] * self.bone_displacement(vol.nodes[moving])
        return fixed, disp

    def skin_faces(self, vol: Volume) -> np.ndarray:
        """(F,3) boundary triangles of the skin (top face), outward normals."""
        skin = self.regions(vol)["skin"]
        return vol.surface[np.all(skin[vol.surface], axis=1)]

    def model(self, spacing: float, poisson: float = 0.25, formulation: str = "standard"):
        """The paper's basic model on this case: linear FEM (not corotational) with the Dirichlet
        conditions set (targets = rest + bone displacement)."""
        from surgsim_envs.tissue import make

        vol = self.volume(spacing)
        m = make("fem", vol, {"young": self.young, "poisson": poisson, "density": 1000.0, "name": "facial_soft_tissue"},
                 formulation=formulation, corotational=False, integrator="implicit")
        fixed, disp = self.dirichlet(vol)
        m.set_fixed(fixed, vol.nodes[fixed] + disp[fixed])
        return m
