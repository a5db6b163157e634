"""Reduction of the 20th-order parameters to the 8th-order model (section 4.1, eq. 4.2-4.8).

The idler pulleys lose their own degrees of freedom: belt sections in series become the three
effective springs (eq. 4.6-4.8); the corner pulleys opposite the motors lump into the motor
pulleys (eq. 4.2, 4.4: J_M1 = J_1 + J_3, B_M1 = B_1 + B_3, which is 2 J_p, 2 B_p for equal
pulleys); the four bridge pulleys, which turn only in y motion, lump into the cart as
J / r^2 and B / r^2 (eq. 4.3, 4.5) and, for Coulomb torques, tau_c / r.

Applied to Table 3.1 this reproduces Table 4.1 except b_cart, where the thesis prints 45.5517
N s/m and eq. 4.5 gives 23.2224 + 4 * 0.0021 / 0.0194^2 = 45.5415 N s/m (0.02 % lower); we keep
the formula's value.
"""

from __future__ import annotations

from hframe_id.errors import ParameterFileError
from hframe_id.parameters.files import ParameterSet


def series_stiffness(*stiffnesses: float) -> float:
    """Stiffness [N/m] of springs in series, eq. 2.12 / 4.6-4.8: 1 / sum(1 / k_i)."""
    return 1.0 / sum(1.0 / k for k in stiffnesses)


def reduce_to_hframe8(params: ParameterSet) -> ParameterSet:
    """hframe-20 parameter set -> hframe-8 parameter set (section 4.1)."""
    if params.variant != "hframe-20":
        raise ParameterFileError(
            f"{params.where()}: reduction needs an hframe-20 parameter set, got {params.variant}"
        )
    v = params.values
    r = v["r"]
    bridge_pulleys = (5, 6, 7, 8)
    reduced = {
        "r": r,
        "k_l": series_stiffness(v["k_1"], v["k_5"], v["k_7"]),
        "k_r": series_stiffness(v["k_2"], v["k_6"], v["k_8"]),
        "k_b": series_stiffness(v["k_3"], v["k_4"], v["k_9"]),
        "J_M1": v["J_1"] + v["J_3"],
        "J_M2": v["J_2"] + v["J_4"],
        "M_cart": v["M_cart"] + sum(v[f"J_{i}"] for i in bridge_pulleys) / r**2,
        "M_bridge": v["M_bridge"],
        "B_M1": v["B_1"] + v["B_3"],
        "B_M2": v["B_2"] + v["B_4"],
        "b_cart": v["b_cart"] + sum(v[f"B_{i}"] for i in bridge_pulleys) / r**2,
        "b_bridge": v["b_bridge"],
        "tau_cM1": v["tau_c1"] + v["tau_c3"],
        "tau_cM2": v["tau_c2"] + v["tau_c4"],
        "F_c_cart": v["F_c_cart"] + sum(v[f"tau_c{i}"] for i in bridge_pulleys) / r,
        "F_c_bridge": v["F_c_bridge"],
        "K_t": v["K_t"],
        "K_e": v["K_e"],
        "R": v["R"],
        "g_1": v["g_1"],
        "g_2": v["g_2"],
    }
    return ParameterSet(
        variant="hframe-8",
        values=reduced,
        title=f"{params.title} (reduced to the 8th-order model)",
        source=f"{params.source}, reduced by section 4.1 (eq. 4.2-4.8)",
        references=list(params.references),
        notes="Belt lengths (section 4.6) are not carried over by the reduction.",
    )
