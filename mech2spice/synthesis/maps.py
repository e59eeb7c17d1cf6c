"""Techmap files for what Yosys leaves unmapped and a NOR network can compute.

`$pow` with an exponent that is not a constant: Yosys's own techmap fails it (`_90_pow` sets
`_TECHMAP_FAIL_`), so `a ** b` was refused as "no NOR-gate mapping".  Every script that reads a design's
source as its meaning (synthesis, the proof) runs `MAP_POW` after `flatten`, with the file written into its
folder (`write_maps`), so both sides of the proof read `**` the same way; co-simulation against Icarus checks
that reading (tests/test_rtl_constructs.py).
"""
from __future__ import annotations

from pathlib import Path

POW_MAP_FILE = "m2s_pow.v"
MAP_POW = f"techmap -autoproc -map {POW_MAP_FILE}"

# Square and multiply modulo 2^Y_WIDTH; a negative exponent by Verilog's table (IEEE 1364-2005 table 5-6) as
# Yosys's constant folder (const_pow) reads it: the base's value follows A_SIGNED, so an unsigned base whose
# bits are all 1 is not -1 (Icarus reads it as -1 there; docs/rtl.md).
POW_MAP = """\
(* techmap_celltype = "$pow" *)
module m2s_pow (A, B, Y);
  parameter A_SIGNED = 0;
  parameter B_SIGNED = 0;
  parameter A_WIDTH = 1;
  parameter B_WIDTH = 1;
  parameter Y_WIDTH = 1;
  input [A_WIDTH-1:0] A;
  input [B_WIDTH-1:0] B;
  output [Y_WIDTH-1:0] Y;

  // A as a Y_WIDTH-bit number: only the low Y_WIDTH bits of the result are kept, (a mod 2^n)^b = a^b mod 2^n
  wire [Y_WIDTH-1:0] a;
  generate
    if (A_WIDTH >= Y_WIDTH) begin : cut
      assign a = A[Y_WIDTH-1:0];
    end else begin : extend
      assign a = {{(Y_WIDTH - A_WIDTH){A_SIGNED ? A[A_WIDTH-1] : 1'b0}}, A};
    end
  endgenerate
  wire [Y_WIDTH-1:0] base [0:B_WIDTH];      // a^(2^i)
  wire [Y_WIDTH-1:0] prod [0:B_WIDTH];      // a^(the exponent's bits below i)
  assign base[0] = a;
  assign prod[0] = 1;
  genvar i;
  generate
    for (i = 0; i < B_WIDTH; i = i + 1) begin : step
      assign base[i + 1] = base[i] * base[i];
      assign prod[i + 1] = B[i] ? prod[i] * base[i] : prod[i];
    end
  endgenerate
  // a negative exponent: 1 for a base of 1, +-1 for -1 (by the exponent's parity), else 0 (also for a base
  // of 0, where the source's value is x)
  wire negative = B_SIGNED && B[B_WIDTH-1];
  wire one = A == 1 && !(A_SIGNED && A_WIDTH == 1);
  wire minus_one = A_SIGNED && &A;
  wire [Y_WIDTH-1:0] small = one ? 1 : minus_one ? (B[0] ? {Y_WIDTH{1'b1}} : 1) : 0;
  assign Y = negative ? small : prod[B_WIDTH];
endmodule
"""


def write_maps(folder) -> None:
    """Write the map files the scripts name into `folder` (Yosys reads them by relative name)."""
    (Path(folder) / POW_MAP_FILE).write_text(POW_MAP)
