"""Per-tissue contact options of a scene: static friction ratio and implicit damping.

``ContactConfig.static_friction_ratio`` (mu_s / mu >= 1) gives every tool a static friction
coefficient above its kinetic one (:mod:`surgsim_envs.contact.friction`).
``ContactConfig.implicit_damping`` ("auto", True, False) decides per tissue whether the contact
damping enters the tissue's solve as the stiffness c_n / dt (``ContactParams.implicit_damping``):
"auto" turns it on for tissue models that declare the capabilities ``quasi_static`` (their
velocities are finite differences of equilibria, and explicit damping c_n / dt above about half a
node's stiffness makes the sequence of equilibria diverge; see docs/models/fem_static.md) and
``implicit_contact`` (their solve takes the reported stiffness, which now carries the damping).
"""

from __future__ import annotations

import dataclasses

from surgsim_envs.contact import ContactParams
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


def static_friction_ratio(contact_cfg) -> float:
    """mu_s / mu of a ContactConfig (or a task config with that field), checked (a number >= 1)."""
    r = getattr(contact_cfg, "static_friction_ratio", 1.0)
    return validate.real(r, f"{type(contact_cfg).__name__}.static_friction_ratio", lo=1.0, hi=100.0,
                         fix="a number >= 1 (static friction mu_s as a multiple of the kinetic mu; 1 = one "
                             "coefficient)")


def contact_params_for(params: ContactParams, contact_cfg, tissue) -> ContactParams:
    """``params`` with ``implicit_damping`` set for ``tissue`` from ``contact_cfg.implicit_damping``."""
    opt = getattr(contact_cfg, "implicit_damping", "auto")
    if isinstance(opt, str):
        if opt != "auto":
            raise ConfigError(f"ContactConfig.implicit_damping={opt!r}; use 'auto' (on for quasi-static tissue "
                              "models), True or False")
        caps = getattr(tissue, "capabilities", ())
        on = "quasi_static" in caps and "implicit_contact" in caps   # the solve must take the stiffness
    elif isinstance(opt, bool):
        on = opt
    else:
        raise ConfigError(f"ContactConfig.implicit_damping={opt!r}; use 'auto', True or False")
    return dataclasses.replace(params, implicit_damping=on) if on != params.implicit_damping else params
