"""Estimate (c): the transverse stiffness of a 2 mm skin on 15 mm of fat over a rigid bed, carried
as a membrane (what scalar springs give: tension T = G_L t) or as a plate (what elasticity gives:
bending D = E t^3 / 12 (1 - nu^2)). The fat is the scalar model's Laplace layer in both (surface
impedance G_L k coth(k H)); a uniform pressure on a disc of radius a; stiffness = F / mean w under
the disc (Hankel transform). Usage: python scripts/layered_skin_plate_membrane.py"""
import numpy as np
from scipy.integrate import quad
from scipy.special import j1

E_s, nu_s, E_f, nu_f, H = 100e3, 0.45, 1e3, 0.49, 0.015
GL = lambda E, nu: E / (2 * (1 - nu ** 2))
Gs, Gf = GL(E_s, nu_s), GL(E_f, nu_f)


def stiffness(a, T=0.0, D=0.0):
    # w_mean = int_0^inf k P(k) / Z(k) * 2 J1(ka) / (ka) dk with P(k) = (F / pi a^2) a J1(ka) / k, F = 1
    def f(k):
        Z = Gf * k / np.tanh(k * H) + T * k ** 2 + D * k ** 4
        P = a * j1(k * a) / k / (np.pi * a * a)
        return k * P / Z * 2 * j1(k * a) / (k * a)
    w = sum(quad(f, lo, hi, limit=400)[0] for lo, hi in ((1e-6, 1 / a), (1 / a, 50 / a), (50 / a, 2000 / a)))
    return 1.0 / w


t = 0.002
D = E_s * t ** 3 / (12 * (1 - nu_s ** 2))
print(f"G_L skin {Gs:.0f} Pa, fat {Gf:.0f} Pa; membrane T = G_L t = {Gs * t:.1f} N/m; plate D = {D:.3g} N m")
print(f"spreading length: membrane sqrt(T H / G_f) = {np.sqrt(Gs * t * H / Gf) * 1e3:.0f} mm, "
      f"plate (D H / G_f)^(1/4) = {(D * H / Gf) ** 0.25 * 1e3:.1f} mm")
for a in (0.003, 0.004, 0.005):
    k0 = stiffness(a)
    row = {"fat only": k0, "plate 2 mm": stiffness(a, D=D)}
    for tm in (0.001, 0.002, 0.0025, 0.005):
        row[f"membrane {tm * 1e3:g} mm"] = stiffness(a, T=Gs * tm)
    print(f"a = {a * 1e3:g} mm: " + ", ".join(f"{k} {v:.3g} N/m ({v / row['plate 2 mm']:.2f} x plate)" for k, v in row.items()))
