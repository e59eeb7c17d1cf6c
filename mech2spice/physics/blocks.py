"""Block structures as data: which oscillators one NOR gate has and how they are wired.

A `BlockSpec` names the block-internal DOFs (mass, total stiffness, Q, slow flag), the springs,
dashpots and signed quadratic gammas between them, which DOF the source drives (and at what force),
which DOF is the output, and how each logical input attaches: a list of (DOF, link) per input, link
"spring" (k = F_R/u_R) or "dashpot" (c = F_R/(u_R omega)).  An upstream output joins the input by
those links; an external input drives each attached DOF with what such a link would carry, level x F_R
at phase 0 (spring) or pi/2 (dashpot).

`classic(p)` is the paper's block (physics/nor.py builds every block from a spec; for the classic one
the model is identical to the hand-written builder's).  A block file (JSON, `--params FILE`) holds
the spec under "block" plus the gate-level fields f_r, u_r, omega: docs/design.md.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..errors import Mech2SpiceError

LINKS = ("spring", "dashpot")
DOF_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,39}")   # model names are gate.DOF: no dots, spaces or newlines


@dataclass(frozen=True)
class Dof:
    """One block-internal oscillator: total stiffness k (as in a network), quality factor q."""
    name: str
    m: float
    k: float
    q: float
    slow: bool = False

    @property
    def c(self) -> float:
        """Total damping m sqrt(k/m) / Q (the formula GateParams.damping uses)."""
        return self.m * math.sqrt(self.k / self.m) / self.q


@dataclass(frozen=True)
class Attach:
    """One link of a logical input: the block DOF it reaches, by a spring or a dashpot."""
    dof: str
    link: str = "spring"


@dataclass(frozen=True)
class BlockSpec:
    """A NOR block's structure and element values (see the module docstring)."""
    name: str
    dofs: tuple[Dof, ...]
    springs: tuple[tuple[str, str, float], ...]
    dashpots: tuple[tuple[str, str, float], ...]
    quads: tuple[tuple[str, str, float], ...]     # (fast, slow, signed gamma)
    source: str
    source_force: float
    output: str
    inputs: tuple[tuple[Attach, ...], ...]

    def dof(self, name: str) -> Dof:
        """The DOF called `name`."""
        return {d.name: d for d in self.dofs}[name]

    @property
    def slow_dofs(self) -> list[str]:
        """Names of the slow (insulator) DOFs."""
        return [d.name for d in self.dofs if d.slow]

    @property
    def n_dofs(self) -> int:
        """Degrees of freedom per gate (the paper's seventh requirement counts them)."""
        return len(self.dofs)

    def validate(self) -> None:
        """Raise Mech2SpiceError (one line) unless the structure is a buildable NOR block."""
        names = [d.name for d in self.dofs]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise Mech2SpiceError(f"block '{self.name}': duplicate DOF name(s) {', '.join(sorted(dup))}")
        for d in self.dofs:
            for key in ("m", "k", "q"):
                v = getattr(d, key)
                if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                    raise Mech2SpiceError(f"block '{self.name}': DOF {d.name}: {key} = {v!r} must be a positive number")
        slow = {d.name: d.slow for d in self.dofs}

        def known(n: str, where: str) -> None:
            if n not in slow:
                raise Mech2SpiceError(f"block '{self.name}': {where} names unknown DOF '{n}' "
                                      f"(DOFs: {', '.join(names)})")
        for kind, links in (("spring", self.springs), ("dashpot", self.dashpots)):
            for a, b, v in links:
                known(a, kind), known(b, kind)
                if a == b or slow[a] or slow[b] or not (math.isfinite(v) and v > 0):
                    raise Mech2SpiceError(f"block '{self.name}': {kind} {a}-{b} = {v!r} must join two different "
                                          "oscillating DOFs with a positive value")
        for f, s, g in self.quads:
            known(f, "quad"), known(s, "quad")
            if slow[f] or not slow[s] or not math.isfinite(g):
                raise Mech2SpiceError(f"block '{self.name}': quad {f}-{s} must join an oscillating DOF to a slow "
                                      "one with a finite gamma")
        for role, n in (("source", self.source), ("output", self.output)):
            if not n:
                raise Mech2SpiceError(f"block '{self.name}': missing {role} DOF")
            known(n, role)
            if slow[n]:
                raise Mech2SpiceError(f"block '{self.name}': the {role} DOF '{n}' must oscillate, not be slow")
        if not (math.isfinite(self.source_force) and self.source_force >= 0):
            raise Mech2SpiceError(f"block '{self.name}': source force {self.source_force!r} must be >= 0")
        if len(self.inputs) != 2 or not all(self.inputs):
            raise Mech2SpiceError(f"block '{self.name}': a NOR block needs 2 inputs with at least one link each")
        for pin, links in enumerate(self.inputs, 1):
            for a in links:
                known(a.dof, f"input {pin}")
                if a.link not in LINKS or slow[a.dof]:
                    raise Mech2SpiceError(f"block '{self.name}': input {pin} link to {a.dof}: link must be one of "
                                          f"{'/'.join(LINKS)} on an oscillating DOF")
        if [a.link for a in self.inputs[0]] != [a.link for a in self.inputs[1]]:
            raise Mech2SpiceError(f"block '{self.name}': both inputs must have the same links (kinds, in the same "
                                  "order): NOR is symmetric and wiring does not say which pin")
        if not self.slow_dofs:
            raise Mech2SpiceError(f"block '{self.name}': no slow (insulator) DOF: nothing makes the block nonlinear")

    # --- JSON ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The JSON form `from_dict` reads."""
        return {"name": self.name,
                "dofs": {d.name: {"m": d.m, "k": d.k, "q": d.q, **({"slow": True} if d.slow else {})}
                         for d in self.dofs},
                "springs": [list(s) for s in self.springs], "dashpots": [list(s) for s in self.dashpots],
                "quads": [list(q) for q in self.quads],
                "source": {"dof": self.source, "force": self.source_force}, "output": self.output,
                "inputs": [[{"dof": a.dof, "link": a.link} for a in pin] for pin in self.inputs]}

    @classmethod
    def from_dict(cls, data, where: str = "block") -> "BlockSpec":
        """Parse and validate the JSON form; every mistake is one Mech2SpiceError line."""
        from ..inputs import is_name, is_number, type_name, MAX_NAME
        if not isinstance(data, dict):
            raise Mech2SpiceError(f"{where}: must be a JSON object, not {type_name(data)}")
        allowed = {"name", "dofs", "springs", "dashpots", "quads", "source", "output", "inputs"}
        unknown = set(data) - allowed
        if unknown:
            raise Mech2SpiceError(f"{where}: unknown key(s) {', '.join(sorted(unknown))} (known: {', '.join(sorted(allowed))})")
        for key in ("dofs", "source", "output", "inputs"):
            if key not in data:
                raise Mech2SpiceError(f"{where}: missing '{key}'")
        dofs_in = data["dofs"]
        if not isinstance(dofs_in, dict) or not dofs_in:
            raise Mech2SpiceError(f"{where}: 'dofs' must be an object of DOF name -> {{m, k, q[, slow]}}")
        dofs = []
        for name, d in dofs_in.items():
            if not DOF_NAME.fullmatch(name):
                raise Mech2SpiceError(f"{where}: DOF name {ascii(name)[:60]} must be a letter, then letters, digits "
                                      "or _ (at most 40)")
            if not isinstance(d, dict) or set(d) - {"m", "k", "q", "slow"} or not {"m", "k", "q"} <= set(d):
                raise Mech2SpiceError(f"{where}: DOF {name} must be an object with m, k, q (and optional slow)")
            if not all(is_number(d[x]) for x in ("m", "k", "q")):
                raise Mech2SpiceError(f"{where}: DOF {name}: m, k, q must be finite numbers")
            if not isinstance(d.get("slow", False), bool):
                raise Mech2SpiceError(f"{where}: DOF {name}: slow must be true or false, not {type_name(d['slow'])}")
            dofs.append(Dof(name, float(d["m"]), float(d["k"]), float(d["q"]), d.get("slow", False)))

        def triples(key: str) -> tuple:
            rows = data.get(key, [])
            ok = isinstance(rows, list) and all(isinstance(r, list) and len(r) == 3 and isinstance(r[0], str)
                                                and isinstance(r[1], str) and is_number(r[2]) for r in rows)
            if not ok:
                raise Mech2SpiceError(f"{where}: '{key}' must be a list of [DOF, DOF, number]")
            return tuple((a, b, float(v)) for a, b, v in rows)

        src = data["source"]
        if not (isinstance(src, dict) and set(src) == {"dof", "force"} and isinstance(src["dof"], str)
                and is_number(src["force"])):
            raise Mech2SpiceError(f"{where}: 'source' must be {{\"dof\": NAME, \"force\": NUMBER}}")
        if not isinstance(data["output"], str):
            raise Mech2SpiceError(f"{where}: 'output' must be a DOF name")
        ins = data["inputs"]
        if not (isinstance(ins, list) and all(isinstance(p, list) and all(isinstance(a, dict) and isinstance(a.get("dof"), str)
                                                                           for a in p) for p in ins)):
            raise Mech2SpiceError(f"{where}: 'inputs' must be a list (one per input) of lists of "
                                  "{\"dof\": NAME, \"link\": spring|dashpot}")
        inputs = []
        for p in ins:
            links = []
            for a in p:
                if set(a) - {"dof", "link"}:
                    raise Mech2SpiceError(f"{where}: input link {a} may only have dof and link")
                links.append(Attach(a["dof"], a.get("link", "spring")))
            inputs.append(tuple(links))
        name = data.get("name", "block")
        if not is_name(name):
            raise Mech2SpiceError(f"{where}: 'name' must be a string of at most {MAX_NAME} printable characters")
        spec = cls(name, tuple(dofs), triples("springs"), triples("dashpots"),
                   triples("quads"), src["dof"], float(src["force"]), data["output"], tuple(inputs))
        spec.validate()
        return spec


def classic(p) -> BlockSpec:
    """The paper's block (Fig. 3c) from a GateParams' fields: channel C (source, output), insulator I,
    and per input a spring-linked and a dashpot-linked gate oscillator."""
    gates = [Dof(f"G{pin}{kind}", p.m_g, p.k_g, p.q_g) for pin in (1, 2) for kind in ("s", "d")]
    return BlockSpec(
        "classic",
        (Dof("C", p.m_c, p.k_c, p.q_c), Dof("I", p.m_i, p.k_i, p.q_i, slow=True), *gates),
        (), (), (("C", "I", -p.gamma_ic), *((g.name, "I", p.gamma_ig) for g in gates)),
        "C", p.f_c, "C",
        tuple((Attach(f"G{pin}s", "spring"), Attach(f"G{pin}d", "dashpot")) for pin in (1, 2)))
