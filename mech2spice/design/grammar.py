"""The block grammar of `mech2spice design`: structures, each a function of named parameters.

Every structure keeps one slow DOF (the insulator I), so the batched all-roots steady-state scan applies.
Parameters are dimensionless and bounded (detunings relative to m omega^2, log10 of Qs, gammas,
stiffnesses and forces); masses, omega, F_R and u_R stay the classic block's.  docs/design.md.

  classic      the paper's block: channel C (source + output), insulator I, per input a spring- and a
               dashpot-linked gate oscillator (6 DOFs)
  buffer       classic + a light low-Q buffer oscillator B spring-coupled to C; B is the output (7 DOFs)
  two_stage    a second channel stage C2 (output, its own mass) spring-coupled to C (source), both detuned
               by I (7)
  spring_only  one spring-linked gate oscillator per input, no dashpot (waveguide-like coupling) (4)
  sym_pair     classic + a reference channel R, spring-coupled to C (driven through it: one source per
               block) and detuned by I with the opposite sign: a common-mode shift of C and R partly
               cancels at the output (7)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..physics.blocks import Attach, BlockSpec, Dof
from ..physics.params import DEFAULT, GateParams, block_params

P0 = DEFAULT
W2 = P0.omega ** 2

# name -> (low, high); d* detuning (k = m w^2 (1 + d)), l* log10
CORE = {"d_c": (-0.15, 0.15), "lq_c": (0.7, 2.6), "d_g": (-0.3, 0.3), "lq_g": (0.7, 2.6),
        "lk_i": (-1.5, 1.5), "lq_i": (-0.5, 1.0), "lgam_ig": (0.0, 3.5), "lgam_ic": (1.0, 4.5),
        "lf_c": (-1.0, 2.0)}
EXTRA = {
    "classic": {},
    "spring_only": {"lm_g": (-1.7, 0.0)},
    "buffer": {"d_b": (-0.3, 0.3), "lq_b": (0.0, 1.5), "lk_cb": (-1.0, 3.5), "lm_b": (-3.0, 0.0)},
    "two_stage": {"d_c2": (-0.15, 0.15), "lq_c2": (0.0, 2.6), "lk_12": (-1.0, 3.5), "lgam_ic2": (-1.0, 4.5),
                  "lm_c2": (-3.0, 1.0)},
    "sym_pair": {"d_r": (-0.15, 0.15), "lgam_ir": (-1.0, 4.5), "lk_cr": (-2.0, 3.5)},
}
# Where each structure's search starts: the default gate embedded in it (a light follower as the buffer or
# second stage, k = |Z| so its amplitude equals the channel's; a barely coupled reference channel).
SEED_EXTRA = {
    # one gate per input with half the mass, stiffness and damping and half gamma: twice the amplitude, the
    # same pull on the insulator and the same relative detuning as the classic pair
    "classic": {}, "spring_only": {"lm_g": math.log10(P0.m_g / 2), "lgam_ig": math.log10(P0.gamma_ig / 2)},
    "buffer": {"d_b": 0.0, "lq_b": 0.3, "lm_b": -3.0, "lk_cb": math.log10(1e-3 * W2 / 10 ** 0.3)},
    "two_stage": {"d_c2": 0.0, "lq_c2": 0.3, "lm_c2": -3.0, "lk_12": math.log10(1e-3 * W2 / 10 ** 0.3),
                  "lgam_ic2": -1.0},
    "sym_pair": {"d_r": 0.0, "lgam_ir": -1.0, "lk_cr": -2.0},
}
STRUCTURES = tuple(EXTRA)


@dataclass(frozen=True)
class Structure:
    """One grammar entry: its name, parameter names and bounds."""
    name: str

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """Parameter name -> (low, high)."""
        return {**CORE, **EXTRA[self.name]}

    def params(self, x) -> GateParams:
        """The GateParams (with its block) for parameter vector x (in `bounds` order)."""
        v = dict(zip(self.bounds, np.asarray(x, float)))
        return block_params({"block": build(self.name, v).to_dict(), "name": self.name}, self.name)


def _k(m: float, d: float) -> float:
    return m * W2 * (1 + d)


def build(name: str, v: dict) -> BlockSpec:
    """The BlockSpec of structure `name` at parameter values v (see CORE, EXTRA)."""
    e = 10.0 ** np.array([v[k] for k in ("lq_c", "lq_g", "lk_i", "lq_i", "lgam_ig", "lgam_ic", "lf_c")])
    q_c, q_g, k_i, q_i, g_ig, g_ic, f_c = map(float, e)
    C = Dof("C", P0.m_c, _k(P0.m_c, v["d_c"]), q_c)
    I = Dof("I", P0.m_i, k_i, q_i, slow=True)
    kinds = ("s",) if name == "spring_only" else ("s", "d")
    m_g = 10.0 ** v["lm_g"] if "lm_g" in v else P0.m_g
    gates = [Dof(f"G{pin}{kind}", m_g, _k(m_g, v["d_g"]), q_g) for pin in (1, 2) for kind in kinds]
    links = {"s": "spring", "d": "dashpot"}
    inputs = tuple(tuple(Attach(f"G{pin}{k}", links[k]) for k in kinds) for pin in (1, 2))
    dofs, springs = [C, I, *gates], []
    quads = [("C", "I", -g_ic), *((g.name, "I", g_ig) for g in gates)]
    output = "C"
    if name == "buffer":
        m_b = 10.0 ** v["lm_b"]
        dofs.append(Dof("B", m_b, _k(m_b, v["d_b"]), 10.0 ** v["lq_b"]))
        springs.append(("C", "B", 10.0 ** v["lk_cb"]))
        output = "B"
    elif name == "two_stage":
        m_2 = 10.0 ** v["lm_c2"]
        dofs.append(Dof("C2", m_2, _k(m_2, v["d_c2"]), 10.0 ** v["lq_c2"]))
        springs.append(("C", "C2", 10.0 ** v["lk_12"]))
        quads.append(("C2", "I", -10.0 ** v["lgam_ic2"]))
        output = "C2"
    elif name == "sym_pair":
        dofs.append(Dof("R", P0.m_c, _k(P0.m_c, v["d_r"]), q_c))
        springs.append(("C", "R", 10.0 ** v["lk_cr"]))
        quads.append(("R", "I", 10.0 ** v["lgam_ir"]))
    return BlockSpec(name, tuple(dofs), tuple(springs), (), tuple(quads), "C", f_c, output, inputs)


def x_default(name: str) -> np.ndarray:
    """The search's starting point: the default gate's parameters, embedded in structure `name`."""
    v = {"d_c": P0.k_c / (P0.m_c * W2) - 1, "lq_c": math.log10(P0.q_c), "d_g": P0.k_g / (P0.m_g * W2) - 1,
         "lq_g": math.log10(P0.q_g), "lk_i": math.log10(P0.k_i), "lq_i": math.log10(P0.q_i),
         "lgam_ig": math.log10(P0.gamma_ig), "lgam_ic": math.log10(P0.gamma_ic), "lf_c": math.log10(P0.f_c),
         **SEED_EXTRA[name]}
    return np.array([v[k] for k in Structure(name).bounds])
