"""Tool-tissue contact: penalty normal force with one-sided damping, Coulomb friction with stick state.

Contact law for a candidate tissue node ``i`` at ``x`` (velocity ``v``) and a tool geom ``g``
(signed distance ``phi(x)``, outward unit normal ``n``, geom velocity ``[w, u]`` at its origin ``p``):

    depth   = max(-phi(x), 0)                             penetration, m
    v_rel   = v - (u + w x (x - p))                       node velocity relative to the geom surface
    v_n     = v_rel . n                                   < 0 while approaching / compressing
    f_n     = k_n depth + c_n max(-v_n, 0)                normal force magnitude, N (always >= 0)
    f_t     = stick/slip spring: sticks while |f_t| <= mu_s f_n (static), slides at mu f_n (kinetic),
              see :mod:`surgsim_envs.contact.friction` (mu_s = mu unless ``tool_static_friction``)
    F_i    += f_n n + f_t                                 force ON the tissue node
    F_tool -= f_n n + f_t,  tau_tool -= (x - c_tool) x (f_n n + f_t)

The damping acts only while the node approaches the surface, so the contact never pulls (no
adhesion): a separating node feels at most the elastic ``k_n depth``, and nothing once it is out.
Reaction torques are taken with the force applied at the node position, so tissue plus tools
conserve linear *and* angular momentum exactly.

Implicit damping (``ContactParams.implicit_damping``, for quasi-static tissue models, whose
velocities are finite differences (x^{n+1} - x^n) / dt): the damping of an approaching point is
not applied from the old velocity. The point's explicit normal force keeps only the tool part,
``k_n depth + c_n max(v_s . n, 0)`` (v_s the geom surface velocity), and its reported stiffness
gains ``c_n / dt``; the tissue's linearised solve ``f - k (x^{n+1} - x^n)`` then applies
``-c_n (v^{n+1} - v_s) . n`` at the new velocity: backward-Euler damping, stable for any c_n / dt
(explicit damping on a quasi-static model diverges once c_n / dt exceeds about half a node's
stiffness). The tissue contract takes one isotropic stiffness per node, so on approaching points
c_n / dt also resists tangential motion for that step; at rest (v = 0) nothing changes.

Optional surface samples (``surface=...``, :mod:`surgsim_envs.contact.surface_points`): points
embedded in the surface triangles are contact points too, with the same law at their interpolated
position/velocity; each sample force goes to its triangle's nodes by its barycentric weights (and
the reaction is applied at the sample), and every contact point then uses k_n, c_n, k_t divided by
n^2 (n edge subdivisions) so the stiffness per surface area is unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from surgsim_envs.contact.contact_set import contact_set_changes
from surgsim_envs.contact.friction import stick_slip
from surgsim_envs.contact.integrated_readings import integrated_readings_kernel
from surgsim_envs.contact.report import ContactReport
from surgsim_envs.contact.plane_law import POTENTIAL_MARGIN, build_plane_law
from surgsim_envs.contact_law.plane import ROW, PlaneContactLaw
from surgsim_envs.contact.shapes import (BOX, CAPSULE, CYLINDER, N_KINDS, ROUNDED_BOX, bounding_radius, local_outside,
                                         world_sdf)
from surgsim_envs.contact.surface_points import check_surface, contact_point, subdivisions_for_spacing, surface_samples
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: default explicit-stability ratio k_n dt^2 / m used by :func:`auto_stiffness`
AUTO_STIFFNESS_RATIO = 0.1


def auto_stiffness(masses, dt: float, ratio: float = AUTO_STIFFNESS_RATIO) -> float:
    """Penalty stiffness k_n (N/m) that keeps explicit contact integration stable.

    A node of mass m on a penalty spring k_n is a harmonic oscillator; symplectic Euler is stable
    for k_n dt^2 / m < 4 and accurate only well below that. This returns
    ``k_n = ratio * min(masses) / dt^2`` so that ``k_n dt^2 / m <= ratio`` (default 0.1, i.e. 40x
    below the stability limit, leaving room for the tissue's own springs acting on the same node).

    masses: (N,) node masses in kg (use the candidate nodes' masses); dt: time step in s;
    ratio: target k_n dt^2 / m_min in (0, 4).
    """
    m = np.asarray(masses, dtype=np.float64).reshape(-1)
    if len(m) == 0 or not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise ConfigError("auto stiffness needs positive finite node masses in kg (e.g. tissue.masses)")
    validate.positive(dt, "dt", unit="s", fix="the time step of the contact, e.g. 1e-3")
    validate.real(ratio, "ratio k_n dt^2/m", lo=0.0, hi=4.0, lo_open=True, hi_open=True,
                  fix="(0, 4) keeps the explicit step stable; use ~0.1")
    return float(ratio * m.min() / (dt * dt))


@dataclass
class ContactParams:
    """Contact law parameters (per node: they do not scale with mesh resolution).

    stiffness: k_n, N/m per node, normal penalty spring; or "auto" (needs ``node_masses`` in
        :class:`ContactModel`): chosen per call from the smallest candidate node mass and dt by
        :func:`auto_stiffness` so explicit contact is stable.
    damping: c_n, N s/m per node, normal damping, acting only while the node approaches the
        surface (never pulls, so never adhesive).
    tangential_stiffness: k_t, N/m per node, stick spring of the Coulomb friction; None = k_n.
    implicit_damping: False (default): the damping force uses the node's current velocity. True:
        the damping of an approaching point is reported as stiffness c_n / dt for the tissue's
        implicit solve (module docstring); for quasi-static models (capability ``quasi_static``),
        whose velocities are finite differences. Needs a tissue step that uses the stiffness.
    """

    stiffness: float | str = 200.0
    damping: float = 0.5
    tangential_stiffness: float | None = None
    implicit_damping: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.stiffness, str):
            if self.stiffness != "auto":
                raise ConfigError(f"stiffness must be a number in N/m or 'auto', got {self.stiffness!r}")
        else:
            validate.positive(self.stiffness, "stiffness", unit="N/m", fix="typical 50-2000 per node, or 'auto'")
        validate.non_negative(self.damping, "damping", unit="N s/m", fix="0 = no contact damping")
        if self.tangential_stiffness is not None:
            validate.positive(self.tangential_stiffness, "tangential_stiffness", unit="N/m",
                              fix="or None (= stiffness)")
        if not isinstance(self.implicit_damping, (bool, np.bool_)):
            raise ConfigError(f"implicit_damping must be True or False, got {self.implicit_damping!r}")


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)


@dataclass
class ContactResult:
    """Output of :meth:`ContactModel.compute` (arrays owned by the model, overwritten next call).

    forces: (N,3) N, contact force ON each tissue node (zeros off contact).
    stiffness: (N,) N/m, isotropic contact stiffness per node (sum over its contacts of
        max(k_n, k_t) while sticking, k_n while slipping, plus c_n / dt on approaching points with
        ``implicit_damping``) for implicit tissue integrators.
    tool_force: (T,3) N, total force ON each tool (minus the sum of its forces on the tissue).
    tool_torque: (T,3) N m, torque ON each tool about ``tool_com``.
    report: per-tool summary.
    geom_normal_force: (G,) N, sum of normal force magnitudes per geom.
    geom_tangential_force: (G,) N, magnitude of the summed friction force per geom.
    """

    forces: np.ndarray
    stiffness: np.ndarray
    tool_force: np.ndarray
    tool_torque: np.ndarray
    report: ContactReport
    geom_normal_force: np.ndarray = field(default_factory=lambda: np.zeros(0))
    geom_tangential_force: np.ndarray = field(default_factory=lambda: np.zeros(0))


# Status codes returned by the kernel (negative = bad input at a geom index).
_OK, _BAD_KIND, _BAD_TOOL, _BAD_SIZE = 0, 1, 2, 3
#: what may cap a sliding contact's friction force (:meth:`ContactModel.set_friction_cap`)
FRICTION_CAPS = ("penalty", "integrated", "solved")
#: ``pair[..., 5]`` of a model whose friction is capped by the penalty: never written, never read
CAP_PENALTY = -2.0
#: how a quasi-static tissue step takes the contact (:meth:`ContactModel.set_contact_law`)
CONTACT_LAWS = ("linearised", "plane")


@njit(cache=True, inline="always")
def _local_extents(kind, s0, s1, s2):
    """Half extents (m) along the local axes of a shape of size (s0, s1, s2) (module ``shapes``)."""
    if kind == BOX or kind == ROUNDED_BOX:
        return s0, s1, s2
    if kind == CAPSULE:
        return s0, s0, s1 + s0
    if kind == CYLINDER:
        return s0, s0, s1
    return s0, s0, s0


@njit(cache=True, inline="always")
def geom_box_half_width(kind, size, gmat, g, k, radius):
    """Half width (m) along world axis ``k`` of a box about geom ``g``'s centre that contains the whole
    shape: its local extents rotated (``sum_j |R_kj| e_j``, R = ``gmat[g]`` row-major), padded by 1e-9
    relative + 1e-12 m for rounding, and never wider than its bounding sphere ``radius``."""
    e0, e1, e2 = _local_extents(kind, size[g, 0], size[g, 1], size[g, 2])
    h = abs(gmat[g, 3 * k]) * e0 + abs(gmat[g, 3 * k + 1]) * e1 + abs(gmat[g, 3 * k + 2]) * e2
    return min(h * (1.0 + 1e-9) + 1e-12, radius)


@njit(cache=True, inline="always")
def _row_lists(C, S):
    """Layout of the kernel's ``rows`` buffer for C candidate nodes and S surface samples: [0] the
    number of node rows written, [1] the number of points left in contact; the node rows from index
    ``w0`` (at most C + 3S: a point's node, or a sample's 3 nodes, once per point in contact), the
    points from ``a0`` (at most C + S). Returns (w0, a0)."""
    return 2, 2 + C + 3 * S


@njit(cache=True)
def contact_rows_start(C, S):
    """Index in the kernel's ``rows`` buffer where the list of the points in contact starts
    (:func:`_row_lists`' ``a0``) for C candidate nodes and S surface samples."""
    return _row_lists(C, S)[1]


def _row_buffer(C: int, S: int) -> np.ndarray:
    """A zeroed ``rows`` buffer of :func:`_contact_kernel` (empty lists)."""
    return np.zeros(2 + (C + 3 * S) + (C + S), dtype=np.int64)


@njit(cache=True, nogil=True)
def _contact_kernel(positions, velocities, cand, s_nodes, s_w, touched, kind, tool, size, gpos, gmat, gvel, tool_com,
                    mu, mu_s, k_n, c_n, c_imp, k_t, anchor_local, anchor_on,
                    forces, stiffness, node_tool_k, tool_force, tool_torque, geom_fn, geom_ft, geom_ftv,
                    tool_fn, tool_ft, tool_ftv, contacts, slipping, penetration, last_contact, last_slip,
                    err, radius, vec3, rows, pair):
    """Contact points p < C are the candidate nodes ``cand[p]``; points p >= C are the surface
    samples ``s = p - C`` at ``sum_j s_w[s, j] x[s_nodes[s, j]]`` whose forces go back to the nodes
    with the same weights. ``touched`` lists every node that can receive a force (all others stay
    zero; the kernel zeroes only the touched rows it wrote last call, listed in ``rows``).
    mu, mu_s (T,) kinetic and static friction per tool; c_imp: 0 (damping from the velocity) or
    c_n / dt (implicit damping: reported as stiffness, module docstring). ``anchor_on[c, g]`` is
    the contact state (friction.NO_CONTACT / STICKING / SLIDING). Work buffers (the model's own, so
    the kernel allocates nothing): ``radius`` (G,) the geoms' bounding radii, ``vec3`` (7 + G, 3) rows
    for the bounding box (lo, hi), the 3-vectors of the signed distance and friction calls, and each
    geom's box half widths (:func:`geom_box_half_width`); ``rows`` (int64, 2 + (C + 3S) + (C + S), layout
    :func:`_row_lists`) the node rows this kernel wrote and the points whose contact state it left
    set, so that the next call zeroes only those: every other touched row and every other contact
    state is already zero (NO_CONTACT), so the outputs are those of zeroing every touched row and
    writing every rejected point's states (the arrays start zero; ``ContactModel.reset`` zeroes them).
    ``pair`` (C + S, G, 6): for each point and geom in contact (``anchor_on[c, g] != 0``) the pair's
    contact stiffness (N/m), unit normal and normal force (N), read by
    :func:`~surgsim_envs.contact.integrated_readings.integrated_readings_kernel` (other entries
    stale), and the normal force the pair integrated over the last step (N; -1: none yet), which that
    kernel writes and which caps the pair's friction here (:data:`CAP_PENALTY`: the model caps
    friction by the penalty; nothing is written or read)."""
    G = kind.shape[0]
    T = tool_force.shape[0]
    # validate geoms and precompute bounding radii
    for g in range(G):
        if kind[g] < 0 or kind[g] >= N_KINDS:
            err[0] = 1
            err[1] = g
            return
        if tool[g] < 0 or tool[g] >= T:
            err[0] = 2
            err[1] = g
            return
        r = bounding_radius(kind[g], size[g, 0], size[g, 1], size[g, 2])
        if not (r > 0.0) or not (size[g, 0] > 0.0):
            err[0] = 3
            err[1] = g
            return
        radius[g] = r
    # axis-aligned box around all geoms: a cheap first rejection per point. Each geom's box is that
    # of its local extents (e0, e1, e2) rotated, half width sum_j |R_kj| e_j along world axis k
    # (R = gmat, row-major), padded by 1e-9 relative + 1e-12 m (rounding): it contains the whole
    # shape, so a point outside it is outside every geom (no contact, as the full tests would find)
    blo = vec3[0]
    bhi = vec3[1]
    for k in range(3):
        blo[k] = np.inf
        bhi[k] = -np.inf
    for g in range(G):
        for k in range(3):
            h = geom_box_half_width(kind[g], size, gmat, g, k, radius[g])
            vec3[7 + g, k] = h
            lo = gpos[g, k] - h
            hi = gpos[g, k] + h
            if lo < blo[k]:
                blo[k] = lo
            if hi > bhi[k]:
                bhi[k] = hi
    for t in range(T):
        for k in range(3):
            tool_force[t, k] = 0.0
            tool_torque[t, k] = 0.0
            tool_ftv[t, k] = 0.0
        tool_fn[t] = 0.0
        contacts[t] = 0
        slipping[t] = 0
        penetration[t] = 0.0
        last_contact[t] = -1
        last_slip[t] = -1
    for g in range(G):
        geom_fn[g] = 0.0
        for k in range(3):
            geom_ftv[g, k] = 0.0
    C = cand.shape[0]
    P = C + s_nodes.shape[0]
    w0, a0 = _row_lists(C, s_nodes.shape[0])
    # the node rows written last call back to zero (every other touched row is zero: never written)
    for q in range(w0, w0 + rows[0]):
        i = rows[q]
        forces[i, 0] = 0.0
        forces[i, 1] = 0.0
        forces[i, 2] = 0.0
        stiffness[i] = 0.0
        for t in range(T):
            node_tool_k[i, t] = 0.0
    rows[0] = 0
    # contact states: a point outside the box gets NO_CONTACT on every geom; only the points in
    # contact after the last call can hold another state, so only theirs are written here (the loop
    # below skips the box-rejected points; it writes every state of the others)
    for q in range(a0, a0 + rows[1]):
        c = rows[q]
        x0, x1, x2, i, a, b, e, wa, wb, we = contact_point(c, C, cand, s_nodes, s_w, positions)
        if (x0 < blo[0] or x0 > bhi[0] or x1 < blo[1] or x1 > bhi[1] or x2 < blo[2] or x2 > bhi[2]):
            for g in range(G):
                anchor_on[c, g] = 0
    rows[1] = 0
    nl = vec3[2]
    cl = vec3[3]
    nrm = vec3[4]
    cpt = vec3[5]
    ft = vec3[6]
    for c in range(P):
        x0, x1, x2, i, a, b, e, wa, wb, we = contact_point(c, C, cand, s_nodes, s_w, positions)
        fx = 0.0
        fy = 0.0
        fz = 0.0
        kk = 0.0
        if (x0 < blo[0] or x0 > bhi[0] or x1 < blo[1] or x1 > bhi[1] or x2 < blo[2] or x2 > bhi[2]):
            continue          # its states are NO_CONTACT already (see above)
        hit = False
        for g in range(G):
            dx = x0 - gpos[g, 0]
            dy = x1 - gpos[g, 1]
            dz = x2 - gpos[g, 2]
            rg = radius[g]
            # outside the geom's own box (contains the shape) or its bounding sphere: no contact
            if abs(dx) > vec3[7 + g, 0] or abs(dy) > vec3[7 + g, 1] or abs(dz) > vec3[7 + g, 2] \
                    or dx * dx + dy * dy + dz * dz >= rg * rg:
                anchor_on[c, g] = 0
                continue
            # cheap exact inside test in the geom frame before the full signed distance
            qx = gmat[g, 0] * dx + gmat[g, 3] * dy + gmat[g, 6] * dz
            qy = gmat[g, 1] * dx + gmat[g, 4] * dy + gmat[g, 7] * dz
            qz = gmat[g, 2] * dx + gmat[g, 5] * dy + gmat[g, 8] * dz
            if local_outside(kind[g], size[g, 0], size[g, 1], size[g, 2], qx, qy, qz):
                anchor_on[c, g] = 0
                continue
            phi = world_sdf(kind[g], size, gpos, gmat, g, x0, x1, x2, nl, cl, nrm, cpt)
            if phi >= 0.0:
                anchor_on[c, g] = 0
                continue
            depth = -phi
            if c < C:
                v0 = velocities[i, 0]
                v1 = velocities[i, 1]
                v2 = velocities[i, 2]
            else:
                v0 = wa * velocities[a, 0] + wb * velocities[b, 0] + we * velocities[e, 0]
                v1 = wa * velocities[a, 1] + wb * velocities[b, 1] + we * velocities[e, 1]
                v2 = wa * velocities[a, 2] + wb * velocities[b, 2] + we * velocities[e, 2]
            # relative normal velocity: v - (u + w x (x - p))
            vsx = gvel[g, 3] + gvel[g, 1] * dz - gvel[g, 2] * dy
            vsy = gvel[g, 4] + gvel[g, 2] * dx - gvel[g, 0] * dz
            vsz = gvel[g, 5] + gvel[g, 0] * dy - gvel[g, 1] * dx
            vn = (v0 - vsx) * nrm[0] + (v1 - vsy) * nrm[1] + (v2 - vsz) * nrm[2]
            f_n = k_n * depth
            k_damp = 0.0
            if vn < 0.0:
                if c_imp > 0.0:    # implicit: the tool part here, c_n / dt into the stiffness
                    vsn = vsx * nrm[0] + vsy * nrm[1] + vsz * nrm[2]
                    if vsn > 0.0:
                        f_n += c_n * vsn
                    k_damp = c_imp
                else:
                    f_n -= c_n * vn
            t = tool[g]
            # friction cap: mu times the normal force, but not more than the pair integrated over the
            # last step (pair[..., 5], kept by integrated_readings_kernel for steps that integrate
            # the penalty linearised): a quasi-static step starts where the tool has moved on, so
            # its penalty here carries the tool's travel, which its solve relaxes away
            if anchor_on[c, g] == 0 and pair[c, g, 5] != CAP_PENALTY:
                pair[c, g, 5] = -1.0          # a new contact: nothing integrated yet
            f_cap = f_n
            if pair[c, g, 5] >= 0.0 and pair[c, g, 5] < f_n:
                f_cap = pair[c, g, 5]
            slip = stick_slip(x0, x1, x2, nrm, f_cap, mu[t], mu_s[t], k_t, gpos, gmat, g, anchor_local, c,
                              anchor_on[c, g], ft)
            if not hit:       # listed before its rows and state are written (counts kept current)
                hit = True
                rows[a0 + rows[1]] = c
                rows[1] += 1
                q = w0 + rows[0]
                if c < C:
                    rows[q] = i
                    rows[0] += 1
                else:
                    rows[q] = a
                    rows[q + 1] = b
                    rows[q + 2] = e
                    rows[0] += 3
            anchor_on[c, g] = 2 if slip else 1
            gx = f_n * nrm[0] + ft[0]
            gy = f_n * nrm[1] + ft[1]
            gz = f_n * nrm[2] + ft[2]
            fx += gx
            fy += gy
            fz += gz
            kg = (k_n if (slip or k_n > k_t) else k_t) + k_damp
            kk += kg
            pair[c, g, 0] = kg
            pair[c, g, 1] = nrm[0]
            pair[c, g, 2] = nrm[1]
            pair[c, g, 3] = nrm[2]
            pair[c, g, 4] = f_n
            if c < C:
                node_tool_k[i, t] += kg
            else:
                node_tool_k[a, t] += wa * kg
                node_tool_k[b, t] += wb * kg
                node_tool_k[e, t] += we * kg
            # reactions on the tool (applied at the contact point)
            tool_force[t, 0] -= gx
            tool_force[t, 1] -= gy
            tool_force[t, 2] -= gz
            rx = x0 - tool_com[t, 0]
            ry = x1 - tool_com[t, 1]
            rz = x2 - tool_com[t, 2]
            tool_torque[t, 0] -= ry * gz - rz * gy
            tool_torque[t, 1] -= rz * gx - rx * gz
            tool_torque[t, 2] -= rx * gy - ry * gx
            # bookkeeping
            geom_fn[g] += f_n
            geom_ftv[g, 0] += ft[0]
            geom_ftv[g, 1] += ft[1]
            geom_ftv[g, 2] += ft[2]
            tool_fn[t] += f_n
            tool_ftv[t, 0] += ft[0]
            tool_ftv[t, 1] += ft[1]
            tool_ftv[t, 2] += ft[2]
            if last_contact[t] != c:
                last_contact[t] = c
                contacts[t] += 1
            if slip and last_slip[t] != c:
                last_slip[t] = c
                slipping[t] += 1
            if depth > penetration[t]:
                penetration[t] = depth
        if kk == 0.0:
            continue
        if c < C:
            forces[i, 0] += fx
            forces[i, 1] += fy
            forces[i, 2] += fz
            stiffness[i] += kk
        else:
            forces[a, 0] += wa * fx
            forces[a, 1] += wa * fy
            forces[a, 2] += wa * fz
            stiffness[a] += wa * kk
            forces[b, 0] += wb * fx
            forces[b, 1] += wb * fy
            forces[b, 2] += wb * fz
            stiffness[b] += wb * kk
            forces[e, 0] += we * fx
            forces[e, 1] += we * fy
            forces[e, 2] += we * fz
            stiffness[e] += we * kk
    for g in range(G):
        geom_ft[g] = math.sqrt(geom_ftv[g, 0] ** 2 + geom_ftv[g, 1] ** 2 + geom_ftv[g, 2] ** 2)
    for t in range(T):
        tool_ft[t] = math.sqrt(tool_ftv[t, 0] ** 2 + tool_ftv[t, 1] ** 2 + tool_ftv[t, 2] ** 2)
    err[0] = 0


@njit(cache=True, nogil=True)
def attribute_increment_kernel(touched, integrated, forces, stiffness, node_tool_k, positions, tool_com,
                               tool_force, tool_torque):
    """Give each tool the reaction of its share (node_tool_k / stiffness) of the increment
    ``integrated - forces`` the tissue added to the contact force of every touched node."""
    T = tool_force.shape[0]
    for j in range(touched.shape[0]):
        i = touched[j]
        k = stiffness[i]
        if k <= 0.0:
            continue
        dx = integrated[i, 0] - forces[i, 0]
        dy = integrated[i, 1] - forces[i, 1]
        dz = integrated[i, 2] - forces[i, 2]
        if dx == 0.0 and dy == 0.0 and dz == 0.0:
            continue
        for t in range(T):
            w = node_tool_k[i, t] / k
            if w == 0.0:
                continue
            gx = w * dx
            gy = w * dy
            gz = w * dz
            tool_force[t, 0] -= gx
            tool_force[t, 1] -= gy
            tool_force[t, 2] -= gz
            rx = positions[i, 0] - tool_com[t, 0]
            ry = positions[i, 1] - tool_com[t, 1]
            rz = positions[i, 2] - tool_com[t, 2]
            tool_torque[t, 0] -= ry * gz - rz * gy
            tool_torque[t, 1] -= rz * gx - rx * gz
            tool_torque[t, 2] -= rx * gy - ry * gx


@njit(cache=True, nogil=True)
def contact_kernel_prepared(positions, velocities, gpos, gmat, gvel, tool_com, state):
    """:meth:`ContactModel.compute_prepared` from compiled code: ``state`` is
    :meth:`ContactModel.kernel_state`. Returns the kernel's status (0 = OK; else call
    ``ContactModel.raise_kernel_error``). Same kernel, same result, and the positions and tool
    centres are kept for :meth:`ContactModel.attribute_increment` as compute_prepared keeps them: the
    positions only of the node rows this call wrote (the rows with a contact stiffness > 0, the only
    ones :func:`attribute_increment_kernel` reads: every other row's stiffness is zero)."""
    (cand, s_nodes, s_w, touched, kind, tool, size, mu, k_n, c_n, k_t, anchor_local, anchor_on,
     forces, stiffness, node_tool_k, tool_force, tool_torque, geom_fn, geom_ft, geom_ftv, tool_fn, tool_ft, tool_ftv,
     contacts, slipping, penetration, last0, last1, err, com_copy, pos_copy, mu_s, c_imp, radius, vec3,
     rows, pair) = state
    _contact_kernel(positions, velocities, cand, s_nodes, s_w, touched, kind, tool, size, gpos, gmat, gvel,
                    tool_com, mu, mu_s, k_n, c_n, c_imp, k_t, anchor_local, anchor_on, forces, stiffness, node_tool_k,
                    tool_force, tool_torque, geom_fn, geom_ft, geom_ftv, tool_fn, tool_ft, tool_ftv, contacts,
                    slipping, penetration, last0, last1, err, radius, vec3, rows, pair)
    if err[0] != 0:
        return err[0]
    for t in range(tool_com.shape[0]):
        for j in range(3):
            com_copy[t, j] = tool_com[t, j]
    w0 = _row_lists(cand.shape[0], s_nodes.shape[0])[0]
    for q in range(w0, w0 + rows[0]):
        i = rows[q]
        for j in range(3):
            pos_copy[i, j] = positions[i, j]
    return 0


def _array(value, shape, dtype, name, unit):
    arr = np.ascontiguousarray(value, dtype=dtype)
    if arr.shape != shape:
        raise ConfigError(f"{name} must have shape {shape} ({unit}), got {np.shape(value)}")
    return arr


class ContactModel:
    """Penalty contact between tissue nodes and tool shapes, with Coulomb stick/slip friction.

    n_nodes: number of tissue nodes N.
    candidate_nodes: (C,) unique indices of the nodes that may touch tools (usually surface nodes).
    tool_friction: (T,) Coulomb coefficient mu >= 0 per tool (also fixes the number of tools T);
        the kinetic one when ``tool_static_friction`` is given.
    tool_static_friction: (T,) static coefficient mu_s >= mu per tool, or None (= tool_friction: one
        coefficient). A sticking contact breaks away at mu_s f_n and slides at mu f_n
        (:mod:`surgsim_envs.contact.friction`). Both arrays are kept and may be rewritten in place
        (``tool_friction[:] = mu``); the kernel never uses a static cap below the kinetic one.
    params: :class:`ContactParams`.
    node_masses: (N,) kg, needed only for ``stiffness="auto"``.
    surface: (F,3) surface triangles (node indices, e.g. ``tissue.surface``) to add embedded
        contact points on (see :mod:`surgsim_envs.contact.surface_points`); None = nodes only.
    surface_subdivisions: n, edge subdivisions of every surface triangle (1 = nodes only, 2..8);
        or give ``sample_spacing`` (m, e.g. the tool tip radius) with ``rest_positions`` (N,3) m and
        n = ceil(mean edge / sample_spacing) is chosen. With samples every contact point (node or
        sample) uses k_n / n^2, c_n / n^2 and k_t / n^2, so the stiffness per unit surface area (and
        the force on a broad indenter) is the same as with nodes only; a tool smaller than the
        lattice spacing now meets the surface between the nodes.

    Call :meth:`compute` once per physics step (between ``mj_step1`` and ``mj_step2``). It keeps
    the friction anchors between calls; :meth:`reset` clears them. The returned arrays are reused
    on every call (no allocation in the loop): copy what you want to keep.
    """

    def __init__(self, n_nodes: int, candidate_nodes, tool_friction, params: ContactParams | None = None,
                 node_masses=None, *, surface=None, surface_subdivisions: int | None = None,
                 sample_spacing: float | None = None, rest_positions=None, tool_static_friction=None):
        validate.integer(n_nodes, "n_nodes", lo=1, fix="the tissue's node count (tissue.n_nodes)")
        self.n_nodes = int(n_nodes)
        cand = np.asarray(candidate_nodes)
        if cand.dtype == bool:
            if cand.shape != (self.n_nodes,):
                raise ConfigError(f"candidate_nodes mask must have shape ({self.n_nodes},), got {cand.shape}")
            cand = np.flatnonzero(cand)
        cand = np.ascontiguousarray(cand.reshape(-1), dtype=np.int64)
        if len(cand) and (cand.min() < 0 or cand.max() >= self.n_nodes):
            raise ConfigError(f"candidate_nodes must lie in [0, {self.n_nodes}), got [{cand.min()}, {cand.max()}]")
        if len(np.unique(cand)) != len(cand):
            raise ConfigError("candidate_nodes contains duplicates; pass np.unique(candidate_nodes)")
        self.candidate_nodes = cand
        mu = np.ascontiguousarray(np.asarray(tool_friction, dtype=np.float64).reshape(-1))
        if len(mu) == 0 or not np.all(np.isfinite(mu)) or np.any(mu < 0):
            raise ConfigError(f"tool_friction must be one Coulomb coefficient >= 0 per tool, got {mu.tolist()}")
        self.tool_friction = mu
        if tool_static_friction is None:
            mu_s = mu.copy()
        else:
            mu_s = np.ascontiguousarray(np.asarray(tool_static_friction, dtype=np.float64).reshape(-1))
            if mu_s.shape != mu.shape or not np.all(np.isfinite(mu_s)) or np.any(mu_s < mu):
                raise ConfigError(f"tool_static_friction must be one static coefficient per tool, each >= the kinetic "
                                  f"tool_friction {mu.tolist()}; got {np.asarray(tool_static_friction).tolist()} "
                                  "(None = the same as tool_friction)")
        #: (T,) static friction coefficient per tool (mu_s >= tool_friction; equal by default)
        self.tool_static_friction = mu_s
        #: what caps a sliding contact's friction (:data:`FRICTION_CAPS`, :meth:`set_friction_cap`)
        self.friction_cap = "penalty"
        #: how a quasi-static tissue step takes the contact (:data:`CONTACT_LAWS`, :meth:`set_contact_law`)
        self.contact_law = "linearised"
        self._law = PlaneContactLaw(np.zeros(0, dtype=np.int64), np.zeros((0, ROW)))
        self._gpos_last = self._gmat_last = None      # the geom poses of the last compute
        self.params = params if params is not None else ContactParams()
        if not isinstance(self.params, ContactParams):
            raise ConfigError(f"params must be a ContactParams, got {type(self.params).__name__}")
        self.node_masses = None
        if node_masses is not None:
            self.node_masses = _array(np.asarray(node_masses, dtype=np.float64).reshape(-1), (self.n_nodes,),
                                      np.float64, "node_masses", "kg")
            # only nodes that can touch a tool need mass (surface-only models leave interior nodes massless)
            weighed = self.node_masses[cand] if len(cand) else self.node_masses
            if np.any(weighed <= 0):
                raise ConfigError("node_masses must be > 0 kg at every candidate (contact) node")
        if self.params.stiffness == "auto" and self.node_masses is None:
            raise ConfigError("stiffness='auto' needs node_masses (kg, e.g. tissue.masses) in ContactModel(...)")
        self._auto_dt = None
        self._k_n = None if self.params.stiffness == "auto" else float(self.params.stiffness)

        self._setup_samples(surface, surface_subdivisions, sample_spacing, rest_positions)

        T = len(mu)
        self.report = ContactReport.zeros(T)
        self.result = ContactResult(np.zeros((self.n_nodes, 3)), np.zeros(self.n_nodes), np.zeros((T, 3)),
                                    np.zeros((T, 3)), self.report)
        self._tool_ftv = np.zeros((T, 3))
        #: (N, T) N/m, each tool's part of every node's contact stiffness at the last compute()
        self.node_tool_stiffness = np.zeros((self.n_nodes, T))
        self._com = np.zeros((T, 3))
        self._pos = np.zeros((self.n_nodes, 3))
        self._last = np.zeros((2, T), dtype=np.int64)
        self._err = np.zeros(2, dtype=np.int64)
        self._vec3 = np.zeros((7, 3))          # kernel work rows (bounding box, 3-vectors)
        self._n_geoms = -1
        self._prepared = None
        self._geom_tool = np.zeros(0, dtype=np.int64)     # the last compute's tool index per geom
        #: bumped by every :meth:`prepare` (and when the geom count changes): the arrays of
        #: :meth:`kernel_state` may then be new objects
        self.prepared_version = 0
        self._alloc_geoms(0)

    def _setup_samples(self, surface, subdivisions, spacing, rest_positions) -> None:
        n = 1
        if surface is None:
            if subdivisions not in (None, 1) or spacing is not None:
                raise ConfigError("surface_subdivisions / sample_spacing need the surface triangles: "
                                  "pass surface=tissue.surface")
        else:
            surface = check_surface(surface, self.n_nodes)
            if subdivisions is not None and spacing is not None:
                raise ConfigError("give either surface_subdivisions (int) or sample_spacing (m), not both")
            if spacing is not None:
                if rest_positions is None:
                    raise ConfigError("sample_spacing needs rest_positions (N,3) m to measure the surface edges")
                x = _array(rest_positions, (self.n_nodes, 3), np.float64, "rest_positions", "m")
                n = subdivisions_for_spacing(x, surface, spacing)
            elif subdivisions is not None:
                n = subdivisions
            surface_samples(surface, n)  # validates n
        self.surface_subdivisions = int(n)
        self.sample_nodes, self.sample_weights = (surface_samples(surface, n) if n > 1 else
                                                  (np.zeros((0, 3), np.int64), np.zeros((0, 3))))
        #: factor applied to k_n, c_n and k_t of every contact point (1 / n^2)
        self.point_scale = 1.0 / (n * n)
        self._touched = np.unique(np.concatenate([self.candidate_nodes, self.sample_nodes.reshape(-1)]))
        #: kernel work: the node rows written and the points left in contact by the last call (_row_lists)
        self._rows = _row_buffer(len(self.candidate_nodes), len(self.sample_nodes))

    @property
    def n_samples(self) -> int:
        """Number of embedded surface samples S (contact points besides the candidate nodes)."""
        return len(self.sample_nodes)

    @property
    def n_points(self) -> int:
        """Number of contact points: candidate nodes plus surface samples."""
        return len(self.candidate_nodes) + len(self.sample_nodes)

    def sample_positions(self, positions) -> np.ndarray:
        """(S,3) m, world positions of the surface samples for node ``positions`` (N,3)."""
        x = _array(positions, (self.n_nodes, 3), np.float64, "positions", "m")
        return np.einsum("sj,sjk->sk", self.sample_weights, x[self.sample_nodes])

    @property
    def n_tools(self) -> int:
        return len(self.tool_friction)

    def stiffness_for(self, dt: float) -> float:
        """The normal penalty stiffness k_n (N/m) used at time step ``dt`` (s)."""
        if self.params.stiffness != "auto":
            return float(self.params.stiffness)
        if self._auto_dt != dt:
            self._k_n = auto_stiffness(self.node_masses[self.candidate_nodes] if len(self.candidate_nodes)
                                       else self.node_masses, dt)
            self._auto_dt = dt
        return self._k_n

    def _alloc_geoms(self, G: int) -> None:
        C = self.n_points
        self._n_geoms = G
        self._prepared = None   # prepare() again: the geom count changed
        self.prepared_version += 1
        self._anchor_local = np.zeros((C, G, 3))
        self._anchor_on = np.zeros((C, G), dtype=np.uint8)
        # per point and geom in contact: stiffness, normal, normal force (kernel), integrated normal force
        self._pair = np.zeros((C, G, 6))
        self._pair[:, :, 5] = CAP_PENALTY if self.friction_cap == "penalty" else -1.0
        self.result.geom_normal_force = np.zeros(G)
        self.result.geom_tangential_force = np.zeros(G)
        self._geom_ftv = np.zeros((G, 3))
        self._radius = np.zeros(G)             # kernel work: bounding radius per geom
        self._vec3 = np.zeros((7 + G, 3))      # kernel work rows: bounding box, 3-vectors, per-geom box half widths

    def reset(self) -> None:
        """Forget all stick anchors (every contact starts fresh) and zero the outputs."""
        self._anchor_on[:] = 0
        self._anchor_local[:] = 0.0
        self.node_tool_stiffness[:] = 0.0
        self._rows[:2] = 0            # nothing written, nothing in contact
        r = self.result
        for arr in (r.forces, r.stiffness, r.tool_force, r.tool_torque, r.geom_normal_force,
                    r.geom_tangential_force, self.report.normal_force, self.report.tangential_force,
                    self.report.contacts, self.report.slipping, self.report.penetration):
            arr[...] = 0

    def friction_state(self) -> tuple[np.ndarray, np.ndarray]:
        """A copy of the stick anchors and contact states (what a contact call reads and updates), for
        :meth:`restore_friction_state`: a quasi-static step solved again starts from the same friction
        state as its first solve (``scene/step/quasi_static.py``)."""
        return self._anchor_local.copy(), self._anchor_on.copy()

    def restore_friction_state(self, state: tuple[np.ndarray, np.ndarray]) -> None:
        """Back to the anchors and contact states of :meth:`friction_state`, in place."""
        np.copyto(self._anchor_local, state[0])
        np.copyto(self._anchor_on, state[1])

    @property
    def in_contact(self) -> np.ndarray:
        """(C, G) bool: candidate node c is in contact with geom g after the last call."""
        return self._anchor_on[:len(self.candidate_nodes)].astype(bool)

    @property
    def points_in_contact(self) -> np.ndarray:
        """(C + S, G) bool: contact point p (candidate nodes, then surface samples) touches geom g."""
        return self._anchor_on.astype(bool)

    def compute(self, positions, velocities, shape_kind, shape_tool, shape_size, shape_pos, shape_mat,
                shape_vel, tool_com, dt) -> ContactResult:
        """Contact forces for the current tissue state and tool poses (see module docstring).

        positions, velocities: (N,3) tissue nodes, m and m/s.
        shape_kind (G,) int codes (SPHERE, CAPSULE, BOX, CYLINDER, ROUNDED_BOX); shape_tool (G,) int tool index;
        shape_size (G,3) m (MuJoCo geom_size); shape_pos (G,3) m (d.geom_xpos);
        shape_mat (G,9) row-major rotations (d.geom_xmat); shape_vel (G,6) [angular rad/s, linear m/s]
        world velocity of each geom frame origin (zeros allowed); tool_com (T,3) m, torque reference
        point per tool; dt s, time step (used by "auto" stiffness).
        """
        N, T = self.n_nodes, self.n_tools
        pos = _array(positions, (N, 3), np.float64, "positions", "m")
        vel = _array(velocities, (N, 3), np.float64, "velocities", "m/s")
        consts = self._constants(shape_kind, shape_tool, shape_size, dt)
        G = len(consts[0])
        gpos = _array(shape_pos, (G, 3), np.float64, "shape_pos", "m")
        gmat = _array(shape_mat, (G, 9), np.float64, "shape_mat", "row-major rotation")
        gvel = _array(shape_vel, (G, 6), np.float64, "shape_vel", "[rad/s, m/s]")
        com = _array(tool_com, (T, 3), np.float64, "tool_com", "m")
        return self._run(pos, vel, gpos, gmat, gvel, com, consts)

    def _constants(self, shape_kind, shape_tool, shape_size, dt) -> tuple:
        """Checked per-scene constants: (kind (G,), tool (G,), size (G,3) m, k_n, c_n, c_n/dt if
        implicit, k_t, each per contact point); re-sizes the per-geom buffers to G."""
        kind = np.ascontiguousarray(shape_kind, dtype=np.int64).reshape(-1)
        G = len(kind)
        tool = _array(shape_tool, (G,), np.int64, "shape_tool", "tool index per geom")
        size = _array(shape_size, (G, 3), np.float64, "shape_size", "m")
        if not (_is_number(dt) and dt > 0):          # once per step: the check inline, the message shared
            validate.positive(dt, "dt", unit="s", fix="the time step of the contact, e.g. 1e-3")
        if G != self._n_geoms:
            self._alloc_geoms(G)
        k_n = self.stiffness_for(dt)
        k_t = self.params.tangential_stiffness or k_n
        scale = self.point_scale
        return (kind, tool, size, float(k_n) * scale, float(self.params.damping) * scale,
                self._implicit_damping(dt) * scale, float(k_t) * scale)

    def _run(self, pos, vel, gpos, gmat, gvel, com, consts) -> ContactResult:
        """The contact kernel on checked arrays and constants; raises on a bad shape."""
        kind, tool, size, k_n, c_n, c_imp, k_t = consts
        r, rep, err = self.result, self.report, self._err
        _contact_kernel(pos, vel, self.candidate_nodes, self.sample_nodes, self.sample_weights, self._touched,
                        kind, tool, size, gpos, gmat, gvel, com, self.tool_friction, self.tool_static_friction,
                        k_n, c_n, c_imp, k_t,
                        self._anchor_local, self._anchor_on, r.forces, r.stiffness, self.node_tool_stiffness,
                        r.tool_force,
                        r.tool_torque, r.geom_normal_force, r.geom_tangential_force, self._geom_ftv,
                        rep.normal_force, rep.tangential_force, self._tool_ftv, rep.contacts, rep.slipping,
                        rep.penetration, self._last[0], self._last[1], err, self._radius, self._vec3, self._rows,
                        self._pair)
        if err[0] != _OK:
            self._raise_kernel_error(kind, tool, size)
        self._geom_tool = tool
        self._gpos_last, self._gmat_last = gpos, gmat
        np.copyto(self._com, com)
        np.copyto(self._pos, pos)
        return r

    def _implicit_damping(self, dt: float) -> float:
        """c_n / dt (N/m per node) when the damping is implicit (``ContactParams.implicit_damping``), else 0."""
        return float(self.params.damping) / dt if self.params.implicit_damping else 0.0

    def _raise_kernel_error(self, kind, tool, size) -> None:
        err, T = self._err, self.n_tools
        g = int(err[1])
        if err[0] == _BAD_KIND:
            raise ConfigError(f"shape_kind[{g}] = {kind[g]} is not a shape code; use 0..{N_KINDS - 1} "
                              "(SPHERE, CAPSULE, BOX, CYLINDER, ROUNDED_BOX)")
        if err[0] == _BAD_TOOL:
            raise ConfigError(f"shape_tool[{g}] = {tool[g]} is not a tool index in [0, {T})")
        raise ConfigError(f"shape_size[{g}] = {size[g].tolist()} m is invalid for shape kind {kind[g]}; "
                          "sizes must be positive (MuJoCo geom_size convention)")

    def prepare(self, shape_kind, shape_tool, shape_size, dt) -> None:
        """Validate and keep the per-scene constants for :meth:`compute_prepared`: the geom shape
        codes (G,), tool index per geom (G,), sizes (G,3) m and the time step dt (s), which fixes
        the penalty stiffness. The arrays are kept by reference (the caller's own buffers)."""
        self._prepared = self._constants(shape_kind, shape_tool, shape_size, dt)
        self.prepared_version += 1

    def raise_kernel_error(self) -> None:
        """Raise the ConfigError for the error code the prepared kernel left (a compiled caller that
        ran :func:`contact_kernel_prepared` itself and got a non-zero status)."""
        kind, tool, size = self._prepared[:3]
        self._raise_kernel_error(kind, tool, size)

    def compute_prepared(self, positions, velocities, shape_pos, shape_mat, shape_vel, tool_com) -> ContactResult:
        """:meth:`compute` for the scene's hot loop, after :meth:`prepare`: the same kernel and the
        same result, without the per-call argument checks. ``positions``/``velocities`` (N,3),
        ``shape_pos`` (G,3), ``shape_mat`` (G,9), ``shape_vel`` (G,6), ``tool_com`` (T,3) must be
        C-contiguous float64 arrays of those shapes (the simulation's own buffers); use
        :meth:`compute` for anything user-supplied."""
        if self._prepared is None:
            raise ConfigError("compute_prepared() needs prepare(shape_kind, shape_tool, shape_size, dt) first "
                              "(and again after compute() with a different number of geoms)")
        return self._run(positions, velocities, shape_pos, shape_mat, shape_vel, tool_com, self._prepared)

    def contact_set_changes(self, positions, shape_pos, shape_mat) -> int:
        """After :meth:`prepare`: the number of contact points whose state at ``positions`` (N,3) m,
        inside a geom or not, differs from the contact the last compute left, with the geoms at
        ``shape_pos`` (G,3) m and ``shape_mat`` (G,9) (C-contiguous float64, the simulation's
        buffers). Writes no contact state (:mod:`surgsim_envs.contact.contact_set`)."""
        kind, _, size = self._prepared[:3]
        return int(contact_set_changes(positions, self.candidate_nodes, self.sample_nodes, self.sample_weights, kind,
                                       size, shape_pos, shape_mat, self._anchor_on, self._vec3))

    def kernel_state(self) -> tuple:
        """The arguments of the contact kernel after :meth:`prepare`, for a compiled caller that
        runs :func:`contact_kernel_prepared` itself (the scene's compiled substeps): a tuple of the
        model's own arrays and the prepared constants, in :func:`contact_kernel_prepared` order.
        Valid until the next :meth:`prepare` (or a compute() with another geom count). The static
        friction, the implicit damping (c_n / dt) and the kernel's work buffers are the last five
        entries, so that compiled callers that index the earlier entries (forces = [13], stiffness =
        [14], ...) keep their indices."""
        if self._prepared is None:
            raise ConfigError("kernel_state() needs prepare(shape_kind, shape_tool, shape_size, dt) first")
        kind, tool, size, k_n, c_n, c_imp, k_t = self._prepared
        r, rep = self.result, self.report
        return (self.candidate_nodes, self.sample_nodes, self.sample_weights, self._touched, kind, tool, size,
                self.tool_friction, k_n, c_n, k_t, self._anchor_local, self._anchor_on, r.forces, r.stiffness,
                self.node_tool_stiffness, r.tool_force, r.tool_torque, r.geom_normal_force,
                r.geom_tangential_force, self._geom_ftv, rep.normal_force, rep.tangential_force, self._tool_ftv,
                rep.contacts, rep.slipping, rep.penetration, self._last[0], self._last[1], self._err,
                self._com, self._pos, self.tool_static_friction, c_imp, self._radius, self._vec3, self._rows,
                self._pair)

    def attribute_increment_prepared(self, integrated_forces) -> None:
        """:meth:`attribute_increment` without the argument check (``integrated_forces`` a
        C-contiguous float64 (N,3) array, e.g. the tissue's ``integrated_external_forces``)."""
        r = self.result
        attribute_increment_kernel(self._touched, integrated_forces, r.forces, r.stiffness, self.node_tool_stiffness,
                             self._pos, self._com, r.tool_force, r.tool_torque)
        self._integrated_readings(integrated_forces)

    def _integrated_readings(self, integrated_forces) -> None:
        """The per-geom and per-tool readings moved onto the integrated force
        (:mod:`surgsim_envs.contact.integrated_readings`)."""
        r, rep = self.result, self.report
        integrated_readings_kernel(self.candidate_nodes, self.sample_nodes, self.sample_weights, self._rows,
                                   _row_lists(len(self.candidate_nodes), len(self.sample_nodes))[1], self._anchor_on,
                                   self._pair, self._geom_tool, integrated_forces, r.forces, r.stiffness,
                                   r.geom_normal_force, r.geom_tangential_force, self._geom_ftv, rep.normal_force,
                                   rep.tangential_force, self._tool_ftv)

    def set_friction_cap(self, cap: str) -> None:
        """What caps a sliding contact's friction force (:data:`FRICTION_CAPS`): ``"penalty"`` (the
        default) mu times the normal penalty where the contact is computed; ``"integrated"`` no more
        than mu times the normal force the pair integrated over the last step, for tissue steps that
        integrate the penalty linearised (quasi-static, implicit). A quasi-static step computes its
        contact where it starts, after the tool moved on, so there the penalty carries the tool's
        travel over the step, which the solve relaxes away: with ``"penalty"`` the integrated
        friction then exceeds Coulomb's bound (docs/contact.md, "Quasi-static steps"). ``"solved"``:
        as ``"integrated"``, and a quasi-static step is solved again (up to
        ``MAX_CONTACT_SET_SOLVES``) until every pair's integrated normal force changes by under
        ``FRICTION_CAP_TOLERANCE`` of the largest, so that the cap is the step's own normal force.
        Explicit steps integrate the penalty itself: the caps are the same for them."""
        cap = validate.choice(cap, "ContactModel.set_friction_cap: cap", FRICTION_CAPS,
                              fix="'penalty' (default), 'integrated' or 'solved'")
        if cap != "penalty" and self.contact_law == "plane":
            raise ConfigError(f"ContactModel.set_friction_cap({cap!r}): the plane law solves the friction cap with "
                              "the step; set_contact_law('linearised') first to cap a linearised step")
        self.friction_cap = cap
        self._pair[:, :, 5] = CAP_PENALTY if self.friction_cap == "penalty" else -1.0

    def set_contact_law(self, law: str) -> None:
        """How a quasi-static tissue step takes this contact (:data:`CONTACT_LAWS`): ``"linearised"``
        (the default) the force at the step's start linearised with one isotropic stiffness per node
        (``result.stiffness``); ``"plane"`` each contact pair's penalty and Coulomb friction solved
        with the step on the pair's tangent plane (:meth:`plane_law`,
        :mod:`surgsim_envs.contact_law.plane`), for tissue models with the capability
        ``plane_contact_law``. Nodes only (no surface samples), friction capped by the penalty."""
        law = validate.choice(law, "ContactModel.set_contact_law: law", CONTACT_LAWS,
                              fix="'linearised' (default) or 'plane'")
        if law == "plane":
            if self.n_samples:
                raise ConfigError("ContactModel.set_contact_law('plane') takes contact at the nodes only; this model "
                                  f"has {self.n_samples} surface samples (build it with surface=None)")
            if self.friction_cap != "penalty":
                raise ConfigError("ContactModel.set_contact_law('plane') solves the friction cap with the step; "
                                  f"set_friction_cap('penalty') first (now {self.friction_cap!r})")
            if len(self._law.nodes) < self.n_points * max(self._n_geoms, 1):
                P = self.n_points * max(self._n_geoms, 1)
                self._law = PlaneContactLaw(np.zeros(P, dtype=np.int64), np.zeros((P, ROW)))
        self.contact_law = law

    @property
    def solves_plane_law(self) -> bool:
        """Whether a quasi-static step solves this contact's plane law (``set_contact_law("plane")``)."""
        return self.contact_law == "plane"

    def plane_law(self, friction_before) -> PlaneContactLaw:
        """The plane law of the pairs in contact after the last compute, linearised where it ran,
        with the stick anchors of ``friction_before`` (:meth:`friction_state` from before that
        compute). After :meth:`prepare` and ``set_contact_law("plane")``."""
        kind, tool, size, k_n, c_n, c_imp, k_t = self._prepared
        P = len(self._anchor_on) * self._anchor_on.shape[1]
        if len(self._law.nodes) < P:
            self._law = PlaneContactLaw(np.zeros(P, dtype=np.int64), np.zeros((P, ROW)))
        count = build_plane_law(self.candidate_nodes, self._rows,
                                _row_lists(len(self.candidate_nodes), len(self.sample_nodes))[1], self._anchor_on,
                                self._pair, friction_before[1], friction_before[0], self._pos, self._gpos_last,
                                self._gmat_last, self._geom_tool, k_n, k_t, self.tool_friction,
                                self.tool_static_friction, self._law.nodes, self._law.data, kind, size,
                                POTENTIAL_MARGIN, self._vec3)
        if count < 0:
            raise ConfigError("ContactModel.plane_law: a surface sample is in contact; the plane law takes the "
                              "nodes only")
        self._law.count = int(count)
        return self._law

    @property
    def solves_friction_cap(self) -> bool:
        """Whether a quasi-static step is solved again until each pair's friction cap is its own
        integrated normal force (``set_friction_cap("solved")``; scene/step/quasi_static.py)."""
        return self.friction_cap == "solved"

    def update_pair_normals(self, integrated_forces) -> float:
        """Keep each contact pair's integrated normal force after a solve that integrated
        ``integrated_forces`` (the tissue's ``integrated_external_forces``), for the next contact
        call's friction cap, and return the largest change of one pair's value over the largest
        value. Nothing else (forces, readings, tool reactions) changes."""
        before = self._pair[:, :, 5].copy()
        G, T = len(self._radius), len(self.tool_friction)
        integrated_readings_kernel(self.candidate_nodes, self.sample_nodes, self.sample_weights, self._rows,
                                   _row_lists(len(self.candidate_nodes), len(self.sample_nodes))[1], self._anchor_on,
                                   self._pair, self._geom_tool, integrated_forces, self.result.forces,
                                   self.result.stiffness, np.zeros(G), np.zeros(G), np.zeros((G, 3)), np.zeros(T),
                                   np.zeros(T), np.zeros((T, 3)))     # the sums into scratch: readings unchanged
        on = self._anchor_on != 0
        after = np.maximum(self._pair[:, :, 5][on], 0.0)       # -1: none yet
        top = float(after.max()) if after.size else 0.0
        return float(np.max(np.abs(after - np.maximum(before[on], 0.0)))) / top if top > 0.0 else 0.0

    def attribute_increment(self, integrated_forces) -> None:
        """After the tissue step: add to ``result.tool_force`` / ``tool_torque`` the reaction of
        the increment ``integrated_forces - result.forces`` (N,3) N that an implicit integrator
        added to the contact force (the tissue's ``integrated_external_forces``), split among the
        tools by their part of each node's contact stiffness. Then tools receive the reaction of
        exactly the force the tissue integrated, and total momentum is conserved for every
        integrator (torques taken at the node positions of the last :meth:`compute`). The readings
        (``geom_normal_force``, ``geom_tangential_force``, the report's ``normal_force`` and
        ``tangential_force``) move onto the integrated force as well
        (:mod:`surgsim_envs.contact.integrated_readings`)."""
        f = _array(integrated_forces, (self.n_nodes, 3), np.float64, "integrated_forces", "N")
        r = self.result
        attribute_increment_kernel(self._touched, f, r.forces, r.stiffness, self.node_tool_stiffness, self._pos,
                             self._com, r.tool_force, r.tool_torque)
        self._integrated_readings(f)
